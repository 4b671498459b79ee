"""A lane camera ahead of the centre of gravity, with and without ``camera_x`` in the vehicle file, printed as JSON.

The drive: 45 s of repeated lane changes at 20 m/s. The package's sedan has a linear truth tire. The camera
runs at 20 Hz, with gaussian noise of 1 cm / 0.3 deg, 50 ms late. The vehicle file is +10 / -8 % off. The
logged ``e1`` is that of a point ``camera_x`` ahead of the CG, ``e1 + camera_x sin(e2) - kappa camera_x^2 / 2``
(:func:`camera_ahead_log`: the simulator's camera sits where the truth vehicle's ``camera_x`` puts it, and the
lane-keeping driver steers on what it shows).

Three cases:
- the camera at the CG;
- 1.5 m ahead, read as the CG's (``camera_x`` 0);
- 1.5 m ahead with ``camera_x`` 1.5.

Per case: the observer with defaults (stiffness error per axle, two-sigma band, verdict, the steering-delay
check's verdict), and beside it the joint UKF on the same log, told the camera noise (it has no noise
estimation) and the same ``camera_x``.

Run: ``python benchmarks/bench_camera_position.py [--out FILE]`` (about 30 s).
"""

from __future__ import annotations

import argparse
import math

from _bench_common import emit

import numpy as np  # noqa: E402

VX = 20.0
DURATION = 45.0
E1_NOISE, E2_NOISE = 0.01, math.radians(0.3)
FILE_ERROR = (1.10, 0.92)  # the vehicle file's stiffness against the truth, front / rear
CASES = (("camera at the CG", 0.0, 0.0), ("1.5 m ahead, camera_x 0", 1.5, 0.0), ("1.5 m ahead, camera_x 1.5", 1.5, 1.5))


def camera_ahead_log(camera_x: float, seed: int = 0):
    """``(sensors, truth_vehicle)``: the drive above with ``e1`` measured ``camera_x`` [m] ahead of the CG."""
    from tire_learning_env.params import CameraParams, VehicleParams
    from tire_learning_env.roads import LaneChangeRoad
    from tire_learning_env.simulation import simulate

    road = LaneChangeRoad.repeated(first=2 * VX, spacing=6 * VX, change_length=2.6 * VX, count=8)
    cam = CameraParams(rate=20.0, latency=0.05, noise="gaussian", e1_noise=E1_NOISE, e2_noise=E2_NOISE)
    log = simulate(road, DURATION, vehicle=VehicleParams(camera_x=camera_x), camera=cam, seed=seed,
                   speed_profile=lambda t: (VX, 0.0), tire_model="linear")  # fmt: skip
    return {k: np.array(v, dtype=float) for k, v in log.sensors.items()}, log.vehicle


def run_case(log_camera_x: float, file_camera_x: float) -> dict:
    from tire_learning_env.baselines.ukf import JointUKF
    from tire_learning_env.observer import ObserverConfig, estimate

    sensors, truth = camera_ahead_log(log_camera_x)
    file = truth.replace(Cf=truth.Cf * FILE_ERROR[0], Cr=truth.Cr * FILE_ERROR[1], camera_x=file_camera_x)
    kt = (truth.Cf, truth.Cr)
    res = estimate(sensors, file, config=ObserverConfig(sensors="camera"))
    k, s = res.cornering_stiffness(), res.cornering_stiffness_std()
    ukf = JointUKF(file, measurement_std=(E1_NOISE, E2_NOISE))
    ukf.run(sensors)
    ku = ukf.cornering_stiffness()
    return {
        "log_camera_x_m": log_camera_x, "file_camera_x_m": file_camera_x,
        "observer": {"stiffness_error_pct": [100.0 * (k[j] / kt[j] - 1.0) for j in range(2)],
                     "two_sigma_pct": [200.0 * s[j] / kt[j] for j in range(2)], "verdict": res.verdict,
                     "steering_delay_check": res.calibration["steering_delay"]["verdict"],
                     "latency_s": res.calibration["latency"].get("latency_s")},
        "ukf": {"stiffness_error_pct": [100.0 * (ku[j] / kt[j] - 1.0) for j in range(2)]},
    }  # fmt: skip


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None, help="also write the JSON here (atomically)")
    args = ap.parse_args(argv)
    out = {"benchmark": "camera_position", "cases": {name: run_case(x_log, x_file) for name, x_log, x_file in CASES}}
    emit(out, args.out)
    return out


if __name__ == "__main__":
    main()
