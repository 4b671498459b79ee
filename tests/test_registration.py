"""Every registered id (``registration.ENV_IDS``) passes both env checkers."""

import warnings

import gymnasium as gym
import pytest
from gymnasium.envs.registration import load_env_creator
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import tire_learning_env  # noqa: F401  (registers the ids)
from tire_learning_env.registration import ENV_IDS, register_envs

#: Warnings the checkers may emit for these envs; any other warning fails the test.
EXPECTED_WARNINGS = (
    # the steering action is in radians, not normalised to [-1, 1] (excitation envs normalise it)
    "symmetric and normalized Box action space",
    # one render mode ("rgb_array") only
    "Not able to test alternative render modes",
    # the excitation ids are wrappers: the checker runs on the wrapper, not on the base env
    "is different from the unwrapped version",
)


def _unexpected(caught) -> list[str]:
    return [str(w.message) for w in caught if not any(text in str(w.message) for text in EXPECTED_WARNINGS)]


def test_every_id_is_registered_with_its_entry_point():
    register_envs()  # idempotent
    for env_id, (entry_point, kwargs, steps) in ENV_IDS.items():
        spec = gym.spec(env_id)
        assert spec.entry_point == entry_point
        assert spec.kwargs == kwargs
        assert spec.max_episode_steps == steps


@pytest.mark.parametrize("render_mode", [None, "rgb_array"])
@pytest.mark.parametrize("env_id", list(ENV_IDS))
def test_gymnasium_env_checker(env_id, render_mode):
    """The checker runs on what the entry point returns (the wrapper itself for the excitation ids)."""
    entry_point, kwargs, _ = ENV_IDS[env_id]
    env = load_env_creator(entry_point)(**kwargs, render_mode=render_mode)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=render_mode is None)
    assert not _unexpected(caught)
    if render_mode == "rgb_array":
        env.reset(seed=0)
        frame = env.render()
        assert frame.ndim == 3 and frame.shape[2] == 3


@pytest.mark.parametrize("env_id", list(ENV_IDS))
def test_sb3_env_checker(env_id):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check_env(gym.make(env_id), warn=True)
    assert not _unexpected(caught)
