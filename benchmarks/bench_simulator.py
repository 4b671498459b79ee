"""Speed of the truth simulator and environments (issue 2 targets), printed as JSON.

- ``study1_closed_loop_s``: the Study 1 closed loop (60 s at 1 kHz: truth plant +
  lane-keeping driver + camera) on one core. Target <= 0.5 s.
- ``env_physics_steps_per_s`` of ``TireLearning-Cornering-v0`` (1 kHz physics, 20 Hz
  policy) beside highway-env's ``lane-keeping-v0`` (its bicycle model stepped at 10 Hz,
  one physics step per env step), measured in the same run. Target ratio >= 30.
- ``kernel_dispatch_cpu_us``: CPU time of one call of the compiled tick loop
  (``_kernels.advance_ticks``) that runs no tick, with the Cornering env's simulator's
  arguments built once: numba's per-call cost of boxing the arguments (issue 20 follow-up,
  ``results/kernel_call_overhead_issue20.json``).

Run: ``python benchmarks/bench_simulator.py``
"""

from __future__ import annotations

import statistics
import time

from _bench_common import emit, median_time, pin_to_one_core, time_env_steps

pin_to_one_core()

import gymnasium as gym  # noqa: E402
import highway_env  # noqa: E402,F401
import numpy as np  # noqa: E402

import tire_learning_env  # noqa: E402
from tire_learning_env import _kernels  # noqa: E402
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


def kernel_dispatch_cpu_us(calls: int = 20000, repeats: int = 15) -> float:
    """Median CPU time [us] of one ``advance_ticks`` call of zero ticks (the Cornering env's arguments)."""
    env = gym.make("TireLearning-Cornering-v0")
    env.reset(seed=0)
    sim = env.unwrapped.sim
    sim.camera.ensure_noise(1)
    out = np.empty((0, _kernels.N_LOG))
    table = sim.table
    args = (
        0, sim.dt, 0, sim.plant.state, 0.0, sim.plant.vehicle.vx, 0.0,
        *sim.plant.kernel_params(),
        _kernels.CURVATURE_TABLE, table.kappa, table.dkappa, table.ds, np.zeros(0),
        float("inf"), 0.0,
        *sim.camera.kernel_args(),
        *sim.driver.kernel_args(),
        0.0, float("nan"), 0.0,
        *_kernels.NO_LANE_CHANGE,
        out,
    )  # fmt: skip
    kernel = _kernels.advance_ticks
    for _ in range(calls // 4):
        kernel(*args)
    times = []
    for _ in range(repeats):
        t0 = time.process_time()
        for _ in range(calls):
            kernel(*args)
        times.append((time.process_time() - t0) / calls * 1e6)
    return statistics.median(times)


def main() -> None:
    study1 = median_time(lambda: simulate("study1", 60.0), repeats=7)
    ours, ours_env = env_physics_rate("TireLearning-Cornering-v0")
    theirs, theirs_env = env_physics_rate("lane-keeping-v0")
    dispatch = kernel_dispatch_cpu_us()
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
            "kernel_dispatch_cpu_us": round(dispatch, 2),
        }
    )


if __name__ == "__main__":
    main()
