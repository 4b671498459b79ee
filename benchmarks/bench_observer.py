"""Cost of the neuro-adaptive observer (issue 3 targets), printed as JSON, beside the joint UKF peer.

- ``study1_truth_plus_observer_s``: Study 1 (60 s at 1 kHz): truth simulation + one causal
  observer run, one core. Target <= 1 s. ``..._with_warm_start_s`` adds the SPEC §4
  second run.
- ``lmi_solve_s``: one cvxpy solve of the vertex LMIs (cache disabled) for the paper's basis
  and the default basis. Target <= 10 s on 2 cores.
- ``ukf_peer_s``: the joint UKF baseline on the same 60 s of sensor rows, same run.

Run: ``python benchmarks/bench_observer.py``
"""

from __future__ import annotations

import time

from _common import emit, median_time, pin_to_one_core

import tire_learning_env  # noqa: F401
from tire_learning_env.baselines.ukf import run_ukf_baseline
from tire_learning_env.observer import ObserverConfig, build_observer, estimate, make_basis, synthesize_gains
from tire_learning_env.params import CameraParams, VehicleParams
from tire_learning_env.simulation import simulate


def main() -> None:
    vehicle, camera = VehicleParams(), CameraParams()
    # LMI solves first, with both cores available
    solves = {}
    for name in ("paper", "two_sided"):
        t0 = time.perf_counter()
        g = synthesize_gains(vehicle, make_basis(name, vehicle), 1e-3, cache=False)
        solves[name] = {"wall_s": round(time.perf_counter() - t0, 3), "solver_s": round(g.solve_s, 3), "certified": g.certified}
    pin_to_one_core()
    observer = build_observer(vehicle, camera, ObserverConfig())

    def truth_plus_observer():
        log = simulate("study1", 60.0)
        observer.reset()
        observer.run(log.sensors)

    def truth_plus_estimate():
        log = simulate("study1", 60.0)
        estimate(log.sensors, vehicle, camera, ObserverConfig(), physics_dt=log.dt)

    log = simulate("study1", 60.0)
    emit(
        {
            "benchmark": "observer",
            "study1_truth_plus_observer_s": round(median_time(truth_plus_observer), 4),
            "study1_truth_plus_observer_with_warm_start_s": round(median_time(truth_plus_estimate), 4),
            "target_s": 1.0,
            "ukf_peer_s": round(median_time(lambda: run_ukf_baseline(log.sensors, vehicle, camera), repeats=3), 4),
            "lmi_solve_s": solves,
            "lmi_target_s": 10.0,
        }
    )


if __name__ == "__main__":
    main()
