"""IMU logs on the unified core: speed and accuracy on the real Revs log, beside the linear KF, as JSON.

- ``observer_online_pass_s`` / ``observer_offline_refinement_s`` / ``observer_gains_s``: the
  neuro-adaptive observer (``observer.estimate`` with ``sensors="imu"``) over the whole log
  (27,501 rows at 100 Hz, 275 s), on one core; gains loaded from the cache (re-certified)
  unless ``gains_cold_solve_s`` says otherwise.
- ``linear_kf_s``: the linear Kalman filter (``baselines.LinearKalmanFilter``) on the same rows.
- ``blend_s``: the IMM mode probabilities of the two and their mixture (``imu.blend``).
- ``observer_other_causal_law_s``: the causal pass again under the other learning law (the causal
  blend's third mode, ``imu.BlendParams.other_causal_law``).
- ``estimate_command_s``: the whole ``tire-learning estimate`` IMU branch
  (:func:`tire_learning_env.imu.estimate_imu_log`: cleaning, estimation, scores, figures, files).
- ``sideslip_rmse_deg``: whole log and halves, against the reference sensor, for the
  reported blend, the causal blend, the observer alone (causal and refined) and the KF.

With ``--noisy`` it runs instead on simulated hatchback logs (200 Hz, 14-32 m/s, tires 8-10 %
softer than the vehicle file) with 4.5 m/s^2 of band-limited (15-45 Hz) vibration on
``a_y``, three seeds, and prints the same sideslip figures.

Run: ``python benchmarks/bench_imu.py [--noisy] [LOG.csv VEHICLE.json]``
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from _bench_common import emit, pin_to_one_core

pin_to_one_core()

import numpy as np  # noqa: E402

from tire_learning_env.imu import clean_imu_log, estimate_imu, estimate_imu_log, simulate_imu_drive  # noqa: E402
from tire_learning_env.imu.scoring import reference_beta, sideslip_rmse_deg, split_masks  # noqa: E402
from tire_learning_env.io import read_log, read_vehicle  # noqa: E402
from tire_learning_env.params import TireParams, VehicleParams  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
HATCH = VehicleParams(m=1250.0, Iz=1900.0, lf=1.05, lr=1.55, Cf=5.0e4, Cr=4.5e4)


def _scores(res, beta_ref, t) -> dict:
    masks = split_masks(t)
    traces = {
        "reported_blend": res.blend.beta, "online_blend_causal": res.blend_online.beta,
        "observer_online_causal": res.online.beta, "observer_refined": res.trace.beta, "linear_kf": res.kalman.beta,
    }  # fmt: skip
    if res.online_other_law is not None:  # a mode of the causal blend: the causal pass under the other learning law
        traces["observer_online_other_law"] = res.online_other_law.beta
    return {k: {h: round(v, 4) for h, v in sideslip_rmse_deg(b, beta_ref, masks).items()} for k, b in traces.items()}


def noisy() -> None:
    from scipy.signal import butter, lfilter

    out = []
    for seed in (0, 1, 2):
        truth_vehicle = HATCH.replace(Cf=0.9 * HATCH.Cf, Cr=0.92 * HATCH.Cr)
        s, tr, _ = simulate_imu_drive(HATCH, duration=120.0, dt=0.005, true_vehicle=truth_vehicle, tire=TireParams(mu=0.9),
                                      speed_range=(14.0, 32.0), ay_max=6.0, noise_std=(0.0, 0.003), seed=seed)  # fmt: skip
        b, a = butter(2, [15 / 100, 45 / 100], btype="band")
        vib = lfilter(b, a, np.random.default_rng(100 + seed).normal(size=len(s["t"])))
        s["ay"] = s["ay"] + 4.5 * vib / np.std(vib)
        t0 = time.perf_counter()
        res = estimate_imu(s, HATCH)
        wall = time.perf_counter() - t0
        out.append({"seed": seed, "ay_noise_measured": round(res.noise["std"][0], 3), "wall_s": round(wall, 2),
                    "sideslip_rmse_deg": _scores(res, tr["true_beta"], s["t"])})  # fmt: skip
    emit({"benchmark": "imu_noisy_ay", "logs": out})


def main() -> None:
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    if "--noisy" in sys.argv:
        noisy()
        return
    log_path = Path(args[0]) if args else DATA / "revs_250lm_part1.csv"
    vehicle = read_vehicle(args[1] if len(args) > 1 else DATA / "revs_250lm_vehicle.json")
    t0 = time.perf_counter()
    cleaned, _ = clean_imu_log(read_log(log_path), vehicle)
    read_s = time.perf_counter() - t0
    rows = {k: cleaned.sensors[k] for k in ("t", "delta", "vx", "ax", "ay", "yaw_rate")}
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        estimate_imu(rows, vehicle, cache=tmp)
        cold = time.perf_counter() - t0
    estimate_imu(rows, vehicle)  # fills the default cache and compiles
    res = estimate_imu(rows, vehicle)
    rt = res.core.runtime_s
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        metrics = estimate_imu_log(read_log(log_path), vehicle, Path(tmp) / "out")
        command_s = time.perf_counter() - t0
    beta_ref = reference_beta(cleaned.truth, rows["vx"])
    emit(
        {
            "benchmark": "imu",
            "log": str(log_path),
            "rows": int(len(rows["t"])),
            "duration_s": float(rows["t"][-1] - rows["t"][0]),
            "observer_gains_s": round(rt["gains"], 3),
            "observer_online_pass_s": round(rt["online_pass"], 4),
            "observer_offline_refinement_s": round(rt.get("offline_refinement", 0.0), 4),
            "observer_other_causal_law_s": round(res.runtime_s.get("observer_other_causal_law", 0.0), 4),
            "causal_blend_mean_probability_by_mode": res.blend_online.summary()["mean_probability_by_mode"],
            "estimate_imu_cold_cache_s": round(cold, 3),
            "linear_kf_s": round(res.runtime_s["linear_kf"], 5),
            "blend_s": round(res.runtime_s["blend"], 5),
            "log_read_and_clean_s": round(read_s, 3),
            "estimate_command_s": round(command_s, 3),
            "sideslip_rmse_deg": None if beta_ref is None else _scores(res, beta_ref, rows["t"]),
            "ay_noise_measured": round(res.noise["std"][0], 4),
            "verdict": res.core.verdict,
            "stiffness_per_axle_N_per_rad": metrics["cornering_stiffness"]["final"]["per_axle_N_per_rad"],
            "stiffness_band_2sigma_per_axle_N_per_rad": metrics["cornering_stiffness"]["final"]["band_2sigma_per_axle_N_per_rad"],
            "lmi_certified": metrics["lmi"]["certified"],
        }
    )


if __name__ == "__main__":
    main()
