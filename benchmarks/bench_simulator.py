"""Speed of the truth simulator and environments (issue 2 targets), printed as JSON.

- ``study1_closed_loop_s``: the Study 1 closed loop (60 s at 1 kHz: truth plant +
  lane-keeping driver + camera) on one core. Target <= 0.5 s.
- ``env_physics_steps_per_s`` of ``TireLearning-Cornering-v0`` (1 kHz physics, 20 Hz
  policy) beside highway-env's ``lane-keeping-v0`` (its bicycle model stepped at 10 Hz,
  one physics step per env step), measured in the same run. Target ratio >= 30.

Run: ``python benchmarks/bench_simulator.py``
"""

from __future__ import annotations

import time

from _bench_common import emit, median_time, pin_to_one_core, time_env_steps

pin_to_one_core()

import gymnasium as gym  # noqa: E402
import highway_env  # noqa: E402,F401
import numpy as np  # noqa: E402

import tire_learning_env  # noqa: E402
from tire_learning_env.simulation import simulate  # noqa: E402


def env_physics_rate(env_id: str, seconds: float = 3.0, **kwargs) -> tuple[float, float]:
    """(physics steps/s, env steps/s) of stepping ``env_id`` for about ``seconds``."""
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    unwrapped = env.unwrapped
    if hasattr(unwrapped, "ticks_per_step"):
        per_step = unwrapped.ticks_per_step
    else:  # highway-env: simulation_frequency / policy_frequency physics steps per env step
        per_step = unwrapped.config["simulation_frequency"] // unwrapped.config["policy_frequency"]
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    n, elapsed = time_env_steps(env, action, seconds)
    return n * per_step / elapsed, n / elapsed


def main() -> None:
    study1 = median_time(lambda: simulate("study1", 60.0), repeats=7)
    ours, ours_env = env_physics_rate("TireLearning-Cornering-v0")
    theirs, theirs_env = env_physics_rate("lane-keeping-v0")
    emit(
        {
            "benchmark": "simulator",
            "study1_closed_loop_s": round(study1, 4),
            "study1_target_s": 0.5,
            "env_physics_steps_per_s": round(ours),
            "env_policy_steps_per_s": round(ours_env),
            "highway_lane_keeping_physics_steps_per_s": round(theirs),
            "highway_lane_keeping_env_steps_per_s": round(theirs_env),
            "physics_steps_ratio": round(ours / theirs, 1),
            "physics_steps_ratio_target": 30,
        }
    )


if __name__ == "__main__":
    main()
