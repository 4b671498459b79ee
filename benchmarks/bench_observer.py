"""Cost of the neuro-adaptive observer (issue 3 targets), printed as JSON, beside the joint UKF peer.

- ``study1_truth_plus_observer_s``: Study 1 (60 s at 1 kHz): truth simulation + one causal
  observer run (:meth:`~tire_learning_env.observer.NeuroAdaptiveObserver.run`, gains
  built once), one core. Target <= 1 s.
- ``study1_truth_plus_estimate_camera_given_s``: truth simulation + the whole
  :func:`~tire_learning_env.observer.estimate` with the camera's noise and latency given
  (gains from the cache, causal pass, offline refinement), as Study 1 runs it.
- ``study1_truth_plus_estimate_defaults_s``: the same with the defaults (noise and latency
  measured from the log as well). Both estimate timings are one run after a warm-up run
  (each takes tens of seconds).
- ``estimate_steps_s``: the wall time of each step of the defaults run
  (:attr:`~tire_learning_env.observer.EstimationResult.runtime_s`).
- ``lmi_solve_s``: one cvxpy solve of the vertex LMIs (cache disabled) for the camera
  observer with the paper's basis and the default basis, 1 kHz frames. Target <= 10 s on 2 cores.
- ``ukf_peer_s``: the joint UKF baseline on the same 60 s of sensor rows, same run.

Run: ``python benchmarks/bench_observer.py``
"""

from __future__ import annotations

import time

from _bench_common import emit, median_time, pin_to_one_core

import tire_learning_env  # noqa: F401
from tire_learning_env.baselines.ukf import run_ukf_baseline
from tire_learning_env.observer import ObserverConfig, build_observer, estimate
from tire_learning_env.params import CameraParams, VehicleParams
from tire_learning_env.simulation import simulate


def main() -> None:
    vehicle, camera = VehicleParams(), CameraParams()
    # LMI solves first, with both cores available
    solves = {}
    for name in ("paper", "two_sided"):
        t0 = time.perf_counter()
        g = build_observer(vehicle, camera, ObserverConfig.for_camera(camera, basis=name), cache=False).gains
        solves[name] = {"wall_s": round(time.perf_counter() - t0, 3), "solver_s": round(g.solve_s, 3), "certified": g.certified}
    pin_to_one_core()
    config = ObserverConfig.for_camera(camera)  # Study 1: the camera and the stiffness are known
    observer = build_observer(vehicle, camera, config)

    def truth_plus_observer():
        log = simulate("study1", 60.0)
        observer.reset()
        observer.run(log.sensors)

    def truth_plus_estimate(cam, cfg):
        log = simulate("study1", 60.0)
        return estimate(log.sensors, vehicle, cam, cfg, physics_dt=log.dt)

    log = simulate("study1", 60.0)
    steps = truth_plus_estimate(None, ObserverConfig()).runtime_s
    emit(
        {
            "benchmark": "observer",
            "study1_truth_plus_observer_s": round(median_time(truth_plus_observer), 4),
            "study1_truth_plus_estimate_camera_given_s": round(median_time(lambda: truth_plus_estimate(camera, config), repeats=1), 4),
            "study1_truth_plus_estimate_defaults_s": round(median_time(lambda: truth_plus_estimate(None, ObserverConfig()), repeats=1), 4),
            "estimate_steps_s": {k: round(float(v), 4) for k, v in steps.items()},
            "target_s": 1.0,
            "ukf_peer_s": round(median_time(lambda: run_ukf_baseline(log.sensors, vehicle, camera), repeats=3), 4),
            "lmi_solve_s": solves,
            "lmi_target_s": 10.0,
        }
    )


if __name__ == "__main__":
    main()
