"""Gymnasium environments (registered on ``import tire_learning_env``)."""

from .lane_keeping import OBSERVATION_NAMES, LaneKeepingEnv

__all__ = ["LaneKeepingEnv", "OBSERVATION_NAMES"]
