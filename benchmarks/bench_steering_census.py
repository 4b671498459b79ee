"""What the logged steering did between rows, drive by drive: the census behind the estimator's hold rule.

The estimator ramps the steering between rows when it is smooth at the row rate, or rough only by sensor
noise on a continuous wheel, and otherwise (camera logs with frames on fewer than 60 % of the rows) reports
the midpoint of the two holds (``observer.rows.steering_character``; `docs/results.md` "Logs of another generator").
This script lists, without running any estimator, each drive's ``roughness``, ``half_power_share``, share of
rows with a camera frame and the rule's verdict, for

- the generalisation benchmark's camera families and its highway-env family (``bench_generalization``'s
  draws, redraws included, ``--seed`` / ``--n``): a drive of the package's simulators, whose driver steps the
  road-wheel angle at each frame;
- the independent generator's random camera sweep (``benchmarks/independent_logs/camera_sweep/sweep.py``
  0-11);
- the same generator's sedan (60 s, seeds 0-7) with gaussian steering-sensor noise added, some quantised at
  0.007 deg as the real car's sensor is.

A change of the rule's thresholds shows here which drives it moves. Run:
``python benchmarks/bench_steering_census.py [--n 20] [--seed 15] [--highway 10] [--sweep 12] [--noisy-seeds 8]`` (about 2
minutes); JSON on stdout and written atomically to ``benchmarks/results/steering_census.json`` (``--out``).

``--estimate`` also runs the estimator, with default settings and a vehicle file 8 / 6 % off the generator's
true tire stiffness, on the noisy-steering logs of :data:`ESTIMATE_CASES` (the "Logs of another
generator" figures of `docs/results.md`), each twice: with the rule as it is, and with the sensor-noise test switched off
(``before``: the rule before it, which reports rough steering at the midpoint of the two holds). Per case the
stiffness error against the truth [%], the two-sigma band [% of the truth], whether the truth is inside it, the
verdict and the steering reported between rows (``ramp``, ``hold`` or ``midpoint``; about 2 minutes more;
``estimates`` in the JSON).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import _bench_common

import numpy as np  # noqa: E402

#: the steering-sensor noise (deg) and quantiser step (deg, 0: none) added to the generator's sedan
NOISY_VARIANTS = ((0.003, 0.0), (0.005, 0.0), (0.01, 0.007), (0.03, 0.0), (0.003, 0.007))
RESULTS = Path(__file__).resolve().parent / "results" / "steering_census.json"
#: the ``--estimate`` cases: (generator seed, steering-noise std [deg], quantiser step [deg, 0: none], sensors)
ESTIMATE_CASES = tuple((seed, 0.01, 0.007, "camera") for seed in (0, 1, 2, 3, 5, 6, 7)) + (
    (4, 0.005, 0.0, "camera"), (4, 0.01, 0.0, "camera"), (4, 0.03, 0.0, "camera"), (0, 0.005, 0.0, "camera"),
    (4, 0.01, 0.0, "both"), (0, 0.01, 0.0, "both"), (4, 0.01, 0.0, "imu"), (0, 0.01, 0.0, "imu"))


def census_row(t, delta, e1) -> dict:
    """The rule's inputs and verdict on one log's rows."""
    from tire_learning_env.observer.rows import MIDPOINT_FRAME_SHARE, steering_character

    out = steering_character(np.asarray(t, float), np.asarray(delta, float))
    out["frame_share"] = float(np.mean(np.isfinite(np.asarray(e1, float))))
    out["midpoint"] = bool(not out["smooth"] and out["frame_share"] < MIDPOINT_FRAME_SHARE)
    return out


def package_drives(n: int, seed: int, highway: int, progress) -> list[dict]:
    """The generalisation benchmark's drives (``n`` per camera family, ``highway`` highway-env ones)."""
    import bench_generalization as bg

    rows = []
    plan = [(f, i) for f in bg.FAMILIES for i in range(n)] + [(bg.HIGHWAY, i) for i in range(highway)]
    for family, i in progress(plan, desc="package drives"):
        sc = bg.sample_scenario(family, i, seed, False)
        _, built, _, _ = bg._build_with_redraws(sc, *bg.camera_drive_builders(sc))
        s = built[0].sensors
        rows.append({"source": family, "index": i, **census_row(s["t"], s["delta"], s["e1"])})
    return rows


def noisy_steering(clean, seed: int, noise_deg: float, step_deg: float):
    """The generator's steering ``clean`` [rad] seen through a sensor with gaussian noise of ``noise_deg`` and a
    quantiser of ``step_deg`` (0: none); the noise is drawn from seed ``100 + seed``, as the tests do."""
    delta = clean + np.deg2rad(noise_deg) * np.random.default_rng(100 + seed).standard_normal(len(clean))
    if step_deg:
        delta = np.deg2rad(step_deg) * np.round(delta / np.deg2rad(step_deg))
    return delta


def independent_drives(sweep_cases: int, noisy_seeds: int, progress) -> list[dict]:
    """The independent generator's sweep cases ``0 .. sweep_cases - 1`` and its sedan with steering-sensor
    noise (seeds ``0 .. noisy_seeds - 1``, every :data:`NOISY_VARIANTS`)."""
    from bench_independent_sweep import _generator

    gen, sweep = _generator()
    rows = []
    for i in progress(range(sweep_cases), desc="independent sweep"):
        _, out, _, _ = sweep.sweep_case(i)
        rows.append({"source": "independent_sweep", "index": i, **census_row(out["t"], out["delta"], out["e1"])})
    for seed in progress(range(noisy_seeds), desc="noisy steering sensor"):
        out, _ = gen.simulate("sedan", 60, np.random.default_rng(seed))
        t, clean = np.asarray(out["t"], float), np.asarray(out["delta"], float)
        for noise_deg, step_deg in NOISY_VARIANTS:
            delta = noisy_steering(clean, seed, noise_deg, step_deg)
            rows.append({"source": "independent_noisy_steering", "index": seed, "noise_deg": noise_deg,
                         "quantiser_deg": step_deg, **census_row(t, delta, out["e1"])})
    return rows


def sedan_log(seed: int, sensors: str = "camera", noise_deg: float = 0.0, step_deg: float = 0.0):
    """The independent generator's sedan, 60 s, seed ``seed``: ``(log, k_true, vehicle)``.

    ``log`` holds the rows a user would bring for ``sensors`` (``camera``: ``e1``/``e2``; ``imu``: yaw rate and
    accelerations; ``both``), with the steering seen through :func:`noisy_steering` when ``noise_deg`` or
    ``step_deg`` is set; ``k_true`` the true tire stiffness per axle [N/rad]; ``vehicle`` the vehicle file,
    8 % (front) and -6 % (rear) off it.
    """
    from bench_independent_sweep import _generator
    from tire_learning_env.params import VehicleParams

    gen, _ = _generator()
    out, truth = gen.simulate("sedan", 60, np.random.default_rng(seed))
    car = gen.VEHICLES["sedan"]
    keys = {"camera": ("e1", "e2"), "imu": ("yaw_rate", "ay", "ax"), "both": ("e1", "e2", "yaw_rate", "ay", "ax")}[sensors]
    log = {k: np.asarray(out[k], dtype=float) for k in ("t", "vx", "delta", "kappa") + keys}
    if noise_deg or step_deg:
        log["delta"] = noisy_steering(log["delta"], seed, noise_deg, step_deg)
    k_true = np.array([truth["Cf_tire"], truth["Cr_tire"]])
    vehicle = VehicleParams(m=car["m"], Iz=car["Iz"], lf=car["lf"], lr=car["lr"], Cf=1.08 * k_true[0], Cr=0.94 * k_true[1])
    return log, k_true, vehicle


def estimate_case(seed: int, noise_deg: float, step_deg: float, sensors: str) -> dict:
    """One :data:`ESTIMATE_CASES` entry estimated with the rule as it is (``now``) and without its sensor-noise
    test (``before``)."""
    import tire_learning_env.observer.rows as rows_module
    from tire_learning_env.observer import ObserverConfig, estimate

    log, k_true, vehicle = sedan_log(seed, sensors, noise_deg, step_deg)
    row = {"seed": seed, "noise_deg": noise_deg, "quantiser_deg": step_deg, "sensors": sensors}
    original = rows_module.CONTINUOUS_STEERING_HALF_POWER_SHARE
    for name, share in (("now", original), ("before", np.inf)):
        rows_module.CONTINUOUS_STEERING_HALF_POWER_SHARE = share
        try:
            res = estimate(log, vehicle, config=ObserverConfig(sensors=sensors))
        finally:
            rows_module.CONTINUOUS_STEERING_HALF_POWER_SHARE = original
        k, s = np.array(res.cornering_stiffness()), np.array(res.cornering_stiffness_std())
        hold = res.calibration["steering_hold"]
        row[name] = {"stiffness_error_pct": (100.0 * (k / k_true - 1.0)).round(3).tolist(),
                     "band_2sigma_pct": (200.0 * s / k_true).round(3).tolist(),
                     "truth_in_band": bool(np.all(np.abs(k - k_true) <= 2.0 * s)), "verdict": res.verdict,
                     "hold": "midpoint" if "reported" in hold else hold.get("used"), "sensor_noise": bool(hold.get("sensor_noise", False))}
    return row


def summarise(rows: list[dict]) -> dict:
    """Per source: drive count, ranges of roughness and half-power share, verdict counts."""
    out = {}
    for src in dict.fromkeys(r["source"] for r in rows):
        sel = [r for r in rows if r["source"] == src]
        share = [r["half_power_share"] for r in sel if np.isfinite(r["half_power_share"])]
        out[src] = {"drives": len(sel),
                    "roughness_range": [min(r["roughness"] for r in sel), max(r["roughness"] for r in sel)],
                    "half_power_share_range": [min(share), max(share)] if share else None,
                    "sensor_noise": sum(r["sensor_noise"] for r in sel), "smooth": sum(r["smooth"] for r in sel),
                    "midpoint": sum(r["midpoint"] for r in sel)}
    return out


def main(argv: list[str] | None = None) -> dict:
    from tqdm import tqdm

    from tire_learning_env.io import atomic_write_json
    from tire_learning_env.observer.rows import CONTINUOUS_STEERING_HALF_POWER_SHARE, SMOOTH_STEERING_ROUGHNESS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20, help="drives per camera family of bench_generalization")
    ap.add_argument("--seed", type=int, default=15, help="bench_generalization's seed")
    ap.add_argument("--highway", type=int, default=10, help="highway-env drives")
    ap.add_argument("--sweep", type=int, default=12, help="cases 0 .. N-1 of the independent sweep")
    ap.add_argument("--noisy-seeds", type=int, default=8, help="seeds of the noisy-steering variants")
    ap.add_argument("--estimate", action="store_true", help="also estimate the ESTIMATE_CASES (about 2 min)")
    ap.add_argument("--out", default=str(RESULTS))
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)

    def progress(it, desc):
        return tqdm(list(it), desc=desc, disable=args.no_progress, file=sys.stderr)

    rows = package_drives(args.n, args.seed, args.highway, progress) + independent_drives(args.sweep, args.noisy_seeds, progress)
    result = {"benchmark": "steering census (the estimator's hold rule, no estimation)",
              "thresholds": {"smooth_roughness_below": SMOOTH_STEERING_ROUGHNESS,
                             "sensor_noise_half_power_share_above": CONTINUOUS_STEERING_HALF_POWER_SHARE},
              "summary": summarise(rows), "drives": rows}
    if args.estimate:
        result["estimates"] = [estimate_case(*case) for case in progress(ESTIMATE_CASES, desc="estimates")]
    atomic_write_json(args.out, result)
    _bench_common.emit(result)
    return result


if __name__ == "__main__":
    main()
