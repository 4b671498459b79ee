"""Logs this package did not make: the independent generator's random camera sweep, estimated as a new user would.

The generator (``benchmarks/independent_logs/camera_sweep/gen.py``) does not import ``tire_learning_env``: a
Frenet-frame single-track car with Pacejka axle tires (RK4 at 1 kHz), a preview driver at 100 Hz through an
80 ms steering actuator, its own roads, camera (frames interpolated from the truth at their capture time,
delivered on the first row after their latency, noise, drops) and IMU. ``sweep.py``'s case ``i`` (seed
``1000 + i``) draws the vehicle (compact, sedan, SUV in turn), 12-35 m/s, a 10-60 Hz camera with gaussian or
uniform noise of 0.5-2 cm and 0.05-1 deg, 0-150 ms latency, 0-15 % dropped frames, 50/100/200 Hz rows,
60/120/300 s, mixed, lane-change or arc roads, and a vehicle file whose stiffness is 5-15 % off.

Each log is written as CSV and read back with :func:`tire_learning_env.io.read_log` (the path of
``tire-learning estimate``); then, on the same rows:

- the observer, :func:`tire_learning_env.observer.estimate` with default settings (sensors picked from the
  columns: the camera; noise and latency estimated from the log);
- the joint UKF, ``run_ukf_baseline`` given what the log tells (frame rate, the noise measured on it:
  ``bench_generalization.ukf_camera_from_log``), its band from the filter's log-stiffness std.

Scored against the generator's tire stiffness (``Cax / 2``, per tire): error [%], whether the two-sigma band
holds it, the verdict, runtime. Summary: median / p90 / worst |error| over both axles of every log with a
stiffness, band coverage, verdict counts.

Run: ``python benchmarks/bench_independent_sweep.py [--n 12 | --cases 1,5] [--out benchmarks/results/independent_sweep.json]``
(about 3 minutes for 12 logs on one core). JSON on stdout and written atomically.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import _bench_common

_bench_common.set_one_thread_env()

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
GENERATOR = HERE / "independent_logs" / "camera_sweep"
RESULTS = HERE / "results" / "independent_sweep.json"
AXLES = ("front", "rear")


def _generator():
    """``(gen, sweep)``: the generator's modules (imported from its folder, which is not a package)."""
    sys.path.insert(0, str(GENERATOR))
    try:
        import gen
        import sweep
    finally:
        sys.path.remove(str(GENERATOR))
    return gen, sweep


def run_case(i: int, folder: Path) -> dict:
    """Make case ``i``, write and read it as a user's log, run the observer and the UKF, score."""
    from bench_generalization import ukf_camera_from_log

    from tire_learning_env.baselines.ukf import run_ukf_baseline
    from tire_learning_env.io import read_log
    from tire_learning_env.observer import estimate
    from tire_learning_env.params import VehicleParams

    gen, sweep = _generator()
    name, out, truth, vj = sweep.sweep_case(i)
    path = folder / f"{name}.csv"
    gen.write_csv(str(path), out)
    log = read_log(path)
    vehicle = VehicleParams(**vj)
    k_true = np.array([truth["Cf_tire"], truth["Cr_tire"]])
    rec: dict = {"name": name, "case": {k: truth[k] for k in ("veh", "v0", "cam_rate", "noise", "lat", "log_rate", "dur",
                                                              "drop", "road")},
                 "true_stiffness_N_per_rad": k_true.tolist(),
                 "nominal_error_pct": [100.0 * (vj["Cf"] / k_true[0] - 1.0), 100.0 * (vj["Cr"] / k_true[1] - 1.0)]}
    t0 = time.perf_counter()
    res = estimate(log.sensors, vehicle)
    k, s = np.array(res.cornering_stiffness()), np.array(res.cornering_stiffness_std())
    cal = res.calibration
    rec["observer"] = {
        "stiffness_error_pct": (100.0 * (k / k_true - 1.0)).tolist(),
        "band_2sigma_pct": (200.0 * s / k_true).tolist(),
        "covered_2sigma": [bool(abs(k[j] - k_true[j]) <= 2.0 * s[j]) for j in range(2)],
        "verdict": res.verdict,
        "identified": [bool(res.stiffness_report()[a]["identified"]) for a in AXLES],
        "latency_s": (cal.get("latency") or {}).get("latency_s"),
        "steering_hold": {x: cal["steering_hold"].get(x) for x in ("used", "roughness", "smooth", "reported")},
        "runtime_s": time.perf_counter() - t0,
    }
    try:
        t0 = time.perf_counter()
        cam, given = ukf_camera_from_log(log.sensors)
        u = run_ukf_baseline(log.sensors, vehicle, cam)
        ku = np.array(u.cornering_stiffness())
        lstd = np.array([float(u.filter_std[-1, 4]), float(u.filter_std[-1, 5])])
        rec["ukf"] = {
            "stiffness_error_pct": (100.0 * (ku / k_true - 1.0)).tolist(),
            "covered_2sigma": [bool(ku[j] * math.exp(-2 * lstd[j]) <= k_true[j] <= ku[j] * math.exp(2 * lstd[j]))
                               for j in range(2)],
            "camera_given": given,
            "runtime_s": time.perf_counter() - t0,
        }
    except Exception as exc:  # noqa: BLE001
        rec["ukf"] = {"error": f"{type(exc).__name__}: {exc}"}
    return rec


def summarise(records: list[dict], est: str) -> dict:
    from bench_generalization import _stats

    errors, covered, verdicts, runtime = [], [], {}, []
    for r in records:
        e = r.get(est, {})
        if "stiffness_error_pct" not in e:
            continue
        errors += [abs(x) for x in e["stiffness_error_pct"] if x is not None]
        covered += e["covered_2sigma"]
        runtime.append(e["runtime_s"])
        if "verdict" in e:
            verdicts[e["verdict"]] = verdicts.get(e["verdict"], 0) + 1
    return {"abs_stiffness_error_pct": _stats(errors), "band_coverage": float(np.mean(covered)) if covered else None,
            "axles": len(covered), "verdicts": verdicts or None, "runtime_s": _stats(runtime)}


def main(argv: list[str] | None = None) -> dict:
    from tqdm import tqdm

    from tire_learning_env.io import atomic_write_json

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=12, help="cases 0 .. n-1 of sweep.py")
    ap.add_argument("--cases", default=None, help="only these cases of sweep.py, comma-separated (instead of --n)")
    ap.add_argument("--out", default=str(RESULTS))
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)
    try:
        cases = [int(c) for c in args.cases.split(",")] if args.cases else list(range(args.n))
    except ValueError:
        ap.error(f"--cases takes comma-separated case numbers, got {args.cases!r}")
    t0 = time.perf_counter()
    records = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in tqdm(cases, desc="independent logs", disable=args.no_progress, file=sys.stderr):
            records.append(run_case(i, Path(tmp)))
    result = {"benchmark": "independent generator, random camera sweep (benchmarks/independent_logs/camera_sweep)",
              "settings": "observer: estimate() defaults; UKF: frame rate and noise measured on the log",
              "cases_run": cases, "observer": summarise(records, "observer"), "ukf": summarise(records, "ukf"),
              "cases": records, "elapsed_s": time.perf_counter() - t0}
    atomic_write_json(args.out, result)
    _bench_common.emit(result)
    return result


if __name__ == "__main__":
    main()
