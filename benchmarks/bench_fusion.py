"""Camera alone, IMU alone and both fused, on the same simulated logs (issue 16).

Two 40 s lane-change logs with a 20 Hz camera carrying the paper's noise and the sedan's
Pacejka truth; the nominal stiffness is 12 % off (front high, rear low). The IMU columns are
the simulator's exact ``ay``/``yaw_rate`` (``imu_noise = none``) or those plus white noise
of 0.1 m/s^2 and 0.002 rad/s (``imu_noise = 0.1``). Prints JSON: per sensor set, the stiffness
error [%] against the plant's, its two-sigma [%], and the curve error [%] at 0.1-0.7 deg.

Usage: ``python benchmarks/bench_fusion.py`` (a few minutes on 2 cores).
"""

from __future__ import annotations

import json

import numpy as np

from tire_learning_env.dynamics import BicyclePlant
from tire_learning_env.observer import ObserverConfig, estimate
from tire_learning_env.params import CameraParams, VehicleParams
from tire_learning_env.simulation import simulate
from tire_learning_env.tires import axle_tires

SLIPS_DEG = (0.1, 0.3, 0.5, 0.7)


def main() -> None:
    truth = VehicleParams()
    plant = BicyclePlant(truth, *axle_tires(truth))
    log = simulate("lane_changes", 40.0, vehicle=truth, camera=CameraParams.paper_noise(rate=20.0), seed=0, plant=plant)
    k_true = plant.true_cornering_stiffness()
    nominal = truth.replace(Cf=truth.Cf * 1.12, Cr=truth.Cr * 0.88)
    grid = np.radians(SLIPS_DEG)
    rng = np.random.default_rng(0)
    out: dict = {"slips_deg": list(SLIPS_DEG)}
    for imu_noise in ("none", "0.1"):
        s = dict(log.sensors)
        if imu_noise != "none":
            n = len(s["t"])
            s["ay"] = s["ay"] + rng.normal(0.0, 0.1, n)
            s["yaw_rate"] = s["yaw_rate"] + rng.normal(0.0, 0.002, n)
        rows = {}
        for sensors in ("camera", "imu", "both"):
            res = estimate(s, nominal, config=ObserverConfig(sensors=sensors))
            k = res.cornering_stiffness()
            sd = res.cornering_stiffness_std()
            rows[sensors] = {
                "stiffness_error_pct": [100.0 * (a / b - 1.0) for a, b in zip(k, k_true)],
                "two_sigma_pct": [200.0 * x / b for x, b in zip(sd, k_true)],
                "curve_error_pct": {
                    axle: (100.0 * (res.axle_force(grid, axle) / plant.true_axle_curve(grid, axle) - 1.0)).tolist()
                    for axle in ("front", "rear")
                },
                "runtime_s": res.runtime_s["total"],
            }
        out[f"imu_noise={imu_noise}"] = rows
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
