"""Speed of the high-order truth plant and the joint-UKF baseline (issue 4), printed as JSON.

- ``high_order_60s_lane_changes_s`` / ``high_order_60s_study1_s``: 60 s simulated at 1 kHz
  with the multi-body plant (RK4, 34 states), lane camera and driver, on one core.
- ``commonroad_python_rhs_us`` and ``commonroad_python_60s_rhs_only_s``: the cost of one call
  of CommonRoad's own pure-Python ``vehicle_dynamics_mb`` and of the 240 000 calls an RK4
  run of 60 s at 1 kHz needs (why the model is ported to numba); null if not installed.
- ``ukf_60s_s``: the joint UKF (8 states, 17 sigma points, RK4 predict at 1 kHz, update
  per frame) on a 60 s lane-change sensor log.
- ``env_physics_steps_per_s``: ``TireLearning-HighOrderLaneChange-v0`` stepped with zero
  action (1 kHz physics, 20 Hz policy).

Run: ``python benchmarks/bench_high_order.py``
"""

from __future__ import annotations

import time

from _bench_common import emit, median_time, pin_to_one_core, time_env_steps

pin_to_one_core()

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import tire_learning_env  # noqa: E402,F401
from tire_learning_env.baselines import JointUKF  # noqa: E402
from tire_learning_env.high_order import simulate_high_order  # noqa: E402


def commonroad_rhs_us(calls: int = 3000) -> float | None:
    try:
        from vehiclemodels.init_mb import init_mb
        from vehiclemodels.parameters_vehicle2 import parameters_vehicle2
        from vehiclemodels.vehicle_dynamics_mb import vehicle_dynamics_mb
    except ImportError:
        return None
    p = parameters_vehicle2()
    x = init_mb([0, 0, 0, 30.0, 0, 0, 0], p)
    vehicle_dynamics_mb(list(x), [0.0, 0.0], p)
    t0 = time.perf_counter()
    for _ in range(calls):
        vehicle_dynamics_mb(list(x), [0.0, 0.0], p)
    return (time.perf_counter() - t0) / calls * 1e6


def env_rate(env_id: str, seconds: float = 3.0) -> float:
    env = gym.make(env_id)
    env.reset(seed=0)
    per_step = env.unwrapped.ticks_per_step
    action = np.zeros(1, dtype=np.float32)
    n, elapsed = time_env_steps(env, action, seconds)
    return n * per_step / elapsed


def main() -> None:
    lane = median_time(lambda: simulate_high_order("lane_changes", 60.0), repeats=3)
    study1 = median_time(lambda: simulate_high_order("study1", 60.0), repeats=3)
    log = simulate_high_order("lane_changes", 60.0)
    v = log.vehicle
    ukf = JointUKF(v.replace(Cf=1.13 * v.Cf, Cr=1.13 * v.Cr))
    ukf_time = median_time(lambda: ukf.run(log.sensors), repeats=3)
    cr_us = commonroad_rhs_us()
    emit(
        {
            "benchmark": "high_order",
            "high_order_60s_lane_changes_s": round(lane, 3),
            "high_order_60s_study1_s": round(study1, 3),
            "commonroad_python_rhs_us": None if cr_us is None else round(cr_us, 2),
            "commonroad_python_60s_rhs_only_s": None if cr_us is None else round(cr_us * 4 * 60000 * 1e-6, 2),
            "ukf_60s_s": round(ukf_time, 3),
            "env_physics_steps_per_s": round(env_rate("TireLearning-HighOrderLaneChange-v0")),
            "study_budget_s": 60.0,
        }
    )


if __name__ == "__main__":
    main()
