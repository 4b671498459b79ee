"""Speed of the highway-env traffic scenes (issue 5 target), printed as JSON.

Policy steps per second of ``TireLearning-Highway-v0`` with 20 traffic vehicles (1 kHz
truth ego physics, 10 Hz traffic, policy at 10 Hz and at 20 Hz) beside highway-env's own
``highway-fast-v0`` (20 vehicles, its defaults: 5 Hz traffic, 1 Hz policy, kinematic ego),
measured in the same run on one core. Target: ours not slower than ``highway-fast-v0``.

Only the time spent in ``env.step`` is counted (episodes end at different lengths: 30
steps for ``highway-fast-v0``, 1200 for ours); ``simulated_s_per_wall_s`` is the other
useful figure (simulated time per second of wall time), since one policy step covers 1 s
in ``highway-fast-v0`` and 0.05-0.1 s in ours. A run of ours with 5 Hz traffic (the
traffic rate of ``highway-fast-v0``) is reported too.

Run: ``python benchmarks/bench_highway.py``
"""

from __future__ import annotations

import time

from _bench_common import emit, pin_to_one_core

pin_to_one_core()

import gymnasium as gym  # noqa: E402
import highway_env  # noqa: E402,F401
import numpy as np  # noqa: E402

import tire_learning_env  # noqa: E402


def steps_per_second(env_id: str, seconds: float = 6.0, seed: int = 0, **kwargs) -> dict:
    """Policy steps per second of wall time spent in ``step`` (and simulated s per wall s)."""
    env = gym.make(env_id, **kwargs)
    unwrapped = env.unwrapped
    if hasattr(unwrapped, "policy_rate"):
        step_s = 1.0 / unwrapped.policy_rate
        action = np.zeros(env.action_space.shape, dtype=np.float32)
    else:  # highway-env: DiscreteMetaAction, 1 = IDLE
        step_s = 1.0 / unwrapped.config["policy_frequency"]
        action = 1
    env.reset(seed=seed)
    for _ in range(20):  # warm-up (numba compilation, caches)
        _, _, term, trunc, _ = env.step(action)
        if term or trunc:
            env.reset()
    env.reset(seed=seed + 1)
    n, busy, resets = 0, 0.0, 0
    while busy < seconds:
        t0 = time.perf_counter()
        _, _, term, trunc, _ = env.step(action)
        busy += time.perf_counter() - t0
        n += 1
        if term or trunc:
            env.reset()
            resets += 1
    env.close()
    return {
        "policy_steps_per_s": round(n / busy, 1),
        "simulated_s_per_wall_s": round(n * step_s / busy, 1),
        "policy_step_s": step_s,
        "episodes_ended": resets,
    }


def main() -> None:
    traffic = {"vehicles_count": 20}
    ours_10 = steps_per_second("TireLearning-Highway-v0", config=dict(traffic, policy_rate=10.0))
    ours_20 = steps_per_second("TireLearning-Highway-v0", config=dict(traffic, policy_rate=20.0))
    ours_10_t5 = steps_per_second(
        "TireLearning-Highway-v0", config=dict(traffic, policy_rate=10.0, traffic_frequency=5.0)
    )
    fast = steps_per_second("highway-fast-v0", config={"vehicles_count": 20})
    emit(
        {
            "benchmark": "highway",
            "traffic_vehicles": 20,
            "ours_policy_10hz_traffic_10hz": ours_10,
            "ours_policy_20hz_traffic_10hz": ours_20,
            "ours_policy_10hz_traffic_5hz": ours_10_t5,
            "highway_fast_v0": fast,
            "ratio_policy_steps_10hz": round(ours_10["policy_steps_per_s"] / fast["policy_steps_per_s"], 2),
            "ratio_policy_steps_20hz": round(ours_20["policy_steps_per_s"] / fast["policy_steps_per_s"], 2),
            "ratio_target": 1.0,
            "ego_physics_rate_hz": 1000,
        }
    )


if __name__ == "__main__":
    main()
