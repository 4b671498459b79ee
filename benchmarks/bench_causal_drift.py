"""The causal (on-line) pass' stiffness over time on drives where it is known to drift.

The offline estimate of :func:`tire_learning_env.observer.estimate` is the reported one; the
causal pass is what the :class:`~tire_learning_env.wrappers.EstimatorWrapper` and the
excitation task use. This prints, as JSON, the causal per-tire stiffness error [%] against
the truth at 10, 20, 40 and 60 s, and the offline one, on

- ``straight``: the excitation task's setting (30 Hz camera, 2 cm / 0.2 deg gaussian noise,
  truth tires x1.125 / x0.833 of the nominal), straight road, lane-keeping driver only;
- ``lane_changes``: 20 Hz camera with the paper's noise, nominal = truth.

Usage: ``python benchmarks/bench_causal_drift.py`` (about 2 minutes on 2 cores).
"""

from __future__ import annotations

import json
import time

import numpy as np

from tire_learning_env.dynamics import BicyclePlant
from tire_learning_env.observer import ObserverConfig, estimate
from tire_learning_env.params import CameraParams, VehicleParams
from tire_learning_env.simulation import simulate
from tire_learning_env.tires import axle_tires

CASES = {
    "straight": ("straight", (1.125, 0.833), CameraParams(rate=30.0, noise="gaussian", e1_noise=0.02, e2_noise=0.00349)),
    "lane_changes": ("lane_changes", (1.0, 1.0), CameraParams.paper_noise(rate=20.0)),
}


def run_case(road: str, truth_scale: tuple[float, float], camera: CameraParams, duration: float = 60.0) -> dict:
    nominal = VehicleParams()
    truth = nominal.replace(Cf=nominal.Cf * truth_scale[0], Cr=nominal.Cr * truth_scale[1])
    plant = BicyclePlant(truth, *axle_tires(truth))
    log = simulate(road, duration, vehicle=nominal, camera=camera, seed=0, plant=plant)
    k_true = plant.true_cornering_stiffness()
    t0 = time.perf_counter()
    res = estimate(log.sensors, nominal, config=ObserverConfig(sensors="camera", latency=0.0))
    tr = res.online
    causal = {}
    for t in (10.0, 20.0, 40.0, duration - 0.1):
        k = int(np.searchsorted(tr.t, t))
        ks = res.observer.cornering_stiffness(tr.weights[k])
        causal[f"{t:.0f}s"] = [100.0 * (a / b - 1.0) for a, b in zip(ks, k_true)]
    return {
        "causal_stiffness_error_pct": causal,
        "offline_stiffness_error_pct": [100.0 * (a / b - 1.0) for a, b in zip(res.cornering_stiffness(), k_true)],
        "offline_2sigma_pct": [200.0 * s / b for s, b in zip(res.cornering_stiffness_std(), k_true)],
        "causal_health_ok_fraction": tr.health_fraction["ok"],
        "runtime_s": time.perf_counter() - t0,
    }


def main() -> None:
    out = {name: run_case(*case) for name, case in CASES.items()}
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
