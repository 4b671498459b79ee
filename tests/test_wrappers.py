import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import tire_learning_env  # noqa: F401
from tire_learning_env.wrappers import ESTIMATE_OBSERVATION_NAMES, EstimatorWrapper

IDS = ["TireLearning-Cornering-v0", "TireLearning-LaneChange-v0", "TireLearning-LaneKeeping-v0", "TireLearning-HighOrderLaneChange-v0"]


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("append", [False, True])
def test_estimator_wrapper_passes_both_checkers(env_id, append):
    env = EstimatorWrapper(gym.make(env_id), append_to_observation=append)
    check_env(env, skip_render_check=True)
    sb3_check_env(env, warn=False)
    if append:
        assert env.observation_space.shape[0] == gym.make(env_id).observation_space.shape[0] + len(ESTIMATE_OBSERVATION_NAMES)


def test_wrapper_vectorised_and_scored():
    envs = gym.make_vec("TireLearning-LaneChange-v0", num_envs=2, vectorization_mode="sync", wrappers=[EstimatorWrapper])
    envs.reset(seed=[0, 1])
    for _ in range(5):
        _, _, _, _, info = envs.step(np.zeros((2, 1), dtype=np.float32))
    assert info["estimate"]["state"].shape == (2, 4)
    env = EstimatorWrapper(gym.make("TireLearning-LaneChange-v0"))
    env.reset(seed=0)
    for _ in range(400):
        env.step(np.zeros(1, dtype=np.float32))
    m = env.metrics()
    assert m["slip_rmse_deg"]["front"] < 0.01 and m["tire_curve_nrmse"]["rear"] < 0.02
    grid = np.radians(np.linspace(-1, 1, 5))
    assert np.all(np.diff(env.tire_curve(grid, "front")) > 0)


@pytest.mark.parametrize("env_id", ["TireLearning-Excitation-v0", "TireLearning-HighwayExcitation-v0"])
def test_estimator_wrapper_around_the_excitation_envs(env_id):
    """They drop the per-tick logs by default (issue 17: a KeyError 'sensor_log'); the wrapper
    asks for them and gets an estimate every step."""
    env = EstimatorWrapper(gym.make(env_id))
    env.reset(seed=0)
    for _ in range(3):
        _, _, _, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    assert np.all(np.isfinite(info["estimate"]["slip"]))
    assert info["estimate"]["state"].shape == (4,)
