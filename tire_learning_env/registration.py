"""Registration of the environment ids (idempotent)."""

from __future__ import annotations

import gymnasium as gym

__all__ = ["register_envs", "ENV_IDS"]

#: id -> (entry point, default kwargs, max episode steps at the default 20 Hz policy rate)
ENV_IDS: dict[str, tuple[str, dict, int]] = {
    "TireLearning-Cornering-v0": ("tire_learning_env.envs.lane_keeping:LaneKeepingEnv", {"road": "study1"}, 1200),
    "TireLearning-LaneChange-v0": ("tire_learning_env.envs.lane_keeping:LaneKeepingEnv", {"road": "lane_changes"}, 1200),
    "TireLearning-LaneKeeping-v0": ("tire_learning_env.envs.lane_keeping:LaneKeepingEnv", {}, 1200),
    # excitation task: steer to excite the slip range the observer still has to learn (wrappers/excitation.py)
    "TireLearning-Excitation-v0": ("tire_learning_env.wrappers.excitation:make_excitation_env", {}, 1200),
    "TireLearning-HighwayExcitation-v0": ("tire_learning_env.wrappers.excitation:make_highway_excitation_env", {}, 1200),
    # highway-env traffic scenes with the truth vehicle as the ego car (envs/highway.py, envs/highway_scenes.py)
    "TireLearning-Highway-v0": ("tire_learning_env.envs.highway_scenes:HighwayTrafficEnv", {}, 1200),
    "TireLearning-Racetrack-v0": ("tire_learning_env.envs.highway_scenes:RacetrackTrafficEnv", {}, 1200),
    # high-order truth vehicle (CommonRoad multi-body model), see tire_learning_env.high_order
    "TireLearning-HighOrderCornering-v0": ("tire_learning_env.envs.high_order:HighOrderLaneKeepingEnv", {"road": "study1"}, 1200),
    "TireLearning-HighOrderLaneChange-v0": ("tire_learning_env.envs.high_order:HighOrderLaneKeepingEnv", {"road": "lane_changes"}, 1200),
}


def register_envs() -> None:
    """Register every id of :data:`ENV_IDS` that is not registered yet."""
    for env_id, (entry_point, kwargs, steps) in ENV_IDS.items():
        if env_id in gym.registry:
            continue
        gym.register(id=env_id, entry_point=entry_point, kwargs=dict(kwargs), max_episode_steps=steps)
