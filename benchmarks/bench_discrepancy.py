"""Speed and accuracy of the discrepancy workflow (issue 6 targets), printed as JSON.

Suites (``--suite``, default ``speed``):

- ``speed``: a 120 s log at 100 Hz (identification road, two hidden effects) analysed on
  2 cores (target <= 60 s), beside two peers measured in the same run: the naive
  open-loop comparison (one simulation of the whole log with the nominal model, which
  drifts) and scipy ``least_squares`` on the full model (all ten effect parameters at
  once, the same multiple-shooting residual), with what each of them concludes.
- ``accuracy``: every library effect hidden at a realistic size in a 60 s log
  (identification road, 30 m/s; speed-dependent stiffness with the ``sine`` speed
  profile), camera at 100 Hz and 20 Hz with uniform +/-1 cm / +/-0.1 deg noise: verdict,
  named effects, parameter error (on the deviation from "absent"), gap ratios, runtime;
  plus two-effect cases and out-of-library effects.
- ``clean``: verdict on effect-free logs over ``--seeds`` noise seeds (target: ``none``
  in at least 19 of 20).
- ``robustness``: every library effect over ``--robustness-seeds`` other noise seeds.

Run: ``python benchmarks/bench_discrepancy.py --suite all --seeds 20``
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "2")  # the target is on 2 cores (before _common's default of 1)

from _common import emit  # noqa: E402

import numpy as np  # noqa: E402

from tire_learning_env.discrepancy import DiscrepancyConfig, analyze, get_effect  # noqa: E402
from tire_learning_env.discrepancy.effects import LIBRARY  # noqa: E402
from tire_learning_env.discrepancy.truth import simulate_hidden  # noqa: E402
from tire_learning_env.io import read_log, write_log  # noqa: E402

#: realistic sizes (chosen before measuring): name -> (hidden effects, library name, true parameters, speed profile)
CASES = {
    "tire_relaxation": ({"tire_relaxation": 0.5}, {"tire_relaxation": [0.5]}, "constant"),
    "camera_latency": ({"camera_latency": 0.1}, {"camera_latency": [0.1]}, "constant"),
    "road_bank": ({"road_bank": 0.02}, {"road_bank": [0.02]}, "constant"),
    "steering_offset": ({"steering_offset": 0.002}, {"steering_offset": [0.002]}, "constant"),
    "camera_heading_bias": ({"camera_heading_bias": 0.003}, {"camera_heading_bias": [0.003]}, "constant"),
    "cornering_stiffness_scale (front 0.85)": (
        {"cornering_stiffness_scale_front": 0.85}, {"cornering_stiffness_scale": [0.85, 1.0]}, "constant",
    ),  # fmt: skip
    "cornering_stiffness_scale (rear 0.85)": (
        {"cornering_stiffness_scale_rear": 0.85}, {"cornering_stiffness_scale": [1.0, 0.85]}, "constant",
    ),  # fmt: skip
    "load_transfer": ({"load_transfer": 6.0}, {"load_transfer": [6.0]}, "constant"),
    "crosswind": ({"crosswind": 300.0}, {"crosswind": [300.0]}, "constant"),
    "speed_dependent_stiffness": ({"speed_dependent_stiffness": 1e-4}, {"speed_dependent_stiffness": [1e-4]}, "sine"),
}
TWO_EFFECT_CASES = {
    "tire_relaxation + crosswind": (
        {"tire_relaxation": 0.5, "crosswind": 300.0}, {"tire_relaxation": [0.5], "crosswind": [300.0]}, "constant",
    ),  # fmt: skip
    "camera_latency + steering_offset": (
        {"camera_latency": 0.1, "steering_offset": 0.002}, {"camera_latency": [0.1], "steering_offset": [0.002]},
        "constant",
    ),  # fmt: skip
    "camera_heading_bias + load_transfer": (
        {"camera_heading_bias": 0.003, "load_transfer": 6.0}, {"camera_heading_bias": [0.003], "load_transfer": [6.0]},
        "constant",
    ),  # fmt: skip
}
OUT_OF_LIBRARY = {
    "steering_nonlinearity=100 1/rad^2": {"steering_nonlinearity": 100.0},
    "steering_nonlinearity=300 1/rad^2": {"steering_nonlinearity": 300.0},
}


def make_log(effects: dict, seed: int = 1, rate: float = 100.0, duration: float = 60.0, speed: str = "constant"):
    """A log through the CSV format (write + strict read), as the command sees it."""
    cols = simulate_hidden(effects, "identification", duration, camera_rate=rate, seed=seed, speed=speed)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "log.csv"
        write_log(path, cols)
        return read_log(path)


def parameter_errors(result, truth: dict) -> dict:
    """Relative error [%] of each fitted parameter's deviation from 'absent' (None if not named)."""
    found = {e["name"]: e for e in result.effects}
    out = {}
    for name, values in truth.items():
        eff = get_effect(name)
        true_dev = eff.size(values)
        if name not in found:
            out[name] = None
            continue
        fit = np.array([found[name]["parameters"][p] for p in eff.parameters])
        fit_dev = eff.size(fit)
        errs = {}
        for p, t, f in zip(eff.parameters, true_dev, fit_dev):
            # a parameter whose truth is 'absent' is scored against the effect's largest deviation
            ref = abs(t) if t != 0 else np.max(np.abs(true_dev))
            errs[p] = float(100.0 * abs(f - t) / ref)
        out[name] = errs
    return out


def score(result, truth: dict, expected_verdict: str = "found") -> dict:
    names = sorted(e["name"] for e in result.effects)
    errors = parameter_errors(result, truth) if truth else {}
    worst = max((v for e in errors.values() if e for v in e.values()), default=None)
    ratios = result.gap_ratios()
    return {
        "verdict": result.verdict,
        "named": names,
        "partial": sorted(e["name"] for e in result.partial_effects),
        "correct": result.verdict == expected_verdict and names == sorted(truth),
        "parameters": {e["name"]: e["parameters"] for e in result.effects},
        "parameter_error_pct": errors,
        "worst_parameter_error_pct": worst,
        "gap_ratio_all_channels": round(result.gap_ratio, 3),
        "gap_ratio_camera_band": round(ratios["normalised_band"]["camera"], 3),
        "gap_ratio_camera_raw_e1": round(ratios["raw"]["e1"], 3),
        "gap_ratio_camera_raw_e2": round(ratios["raw"]["e2"], 3),
        "whiteness_p_before": result.whiteness_before.p_value,
        "whiteness_p_after": result.whiteness_after.p_value,
        "runtime_s": round(result.runtime_s, 2),
        "evaluations": result.selection.n_evaluations,
    }


def suite_accuracy(rates=(100.0, 20.0)) -> dict:
    out = {}
    for rate in rates:
        block = {}
        for label, (hidden, truth, speed) in {**CASES, **TWO_EFFECT_CASES}.items():
            res = analyze(make_log(hidden, rate=rate, speed=speed), progress=False)
            block[label] = score(res, truth)
            print(f"[{rate:g} Hz] {label}: {block[label]['verdict']} {block[label]['named']} "
                  f"err {block[label]['worst_parameter_error_pct']} ratio {block[label]['gap_ratio_all_channels']}",
                  file=sys.stderr)  # fmt: skip
        for label, hidden in OUT_OF_LIBRARY.items():
            res = analyze(make_log(hidden, rate=rate), progress=False)
            block[label] = score(res, {}, expected_verdict="unexplained")
            print(f"[{rate:g} Hz] {label}: {res.verdict} partial {block[label]['partial']}", file=sys.stderr)
        out[f"{rate:g}_hz"] = block
    return out


def suite_robustness(seeds: int, rate: float) -> dict:
    """Every library effect over several noise seeds: how often it is named right, worst error and ratio."""
    out = {}
    for label, (hidden, truth, speed) in CASES.items():
        runs = [score(analyze(make_log(hidden, seed=200 + s, rate=rate, speed=speed), progress=False), truth)
                for s in range(seeds)]  # fmt: skip
        out[label] = {
            "correct": sum(r["correct"] for r in runs),
            "runs": seeds,
            "worst_parameter_error_pct": max((r["worst_parameter_error_pct"] or math.inf) for r in runs),
            "smallest_gap_ratio": min(r["gap_ratio_all_channels"] for r in runs),
            "verdicts": [r["verdict"] for r in runs],
        }
        print(f"[robustness {rate:g} Hz] {label}: {out[label]}", file=sys.stderr)
    return out


def suite_clean(seeds: int, rate: float = 100.0) -> dict:
    verdicts = []
    details = []
    for seed in range(seeds):
        res = analyze(make_log({}, seed=100 + seed, rate=rate), progress=False)
        verdicts.append(res.verdict)
        details.append({"seed": 100 + seed, "verdict": res.verdict, "named": [e["name"] for e in res.effects],
                        "whiteness_p": res.whiteness_before.p_value, "runtime_s": round(res.runtime_s, 2)})  # fmt: skip
        print(f"[clean {rate:g} Hz] seed {100 + seed}: {res.verdict}", file=sys.stderr)
    return {"rate_hz": rate, "seeds": seeds, "none": verdicts.count("none"), "target_none_of_20": 19, "runs": details}


def suite_speed() -> dict:
    from scipy import optimize

    from tire_learning_env.discrepancy.data import prepare
    from tire_learning_env.discrepancy.residuals import ResidualModel
    from tire_learning_env.discrepancy._model import N_OUT, THETA_NOMINAL, simulate_rows
    from tire_learning_env.params import TireParams, VehicleParams
    from tire_learning_env.tires import axle_tires

    hidden = {"camera_latency": 0.1, "steering_offset": 0.002}
    t0 = time.perf_counter()
    log = make_log(hidden, duration=120.0)
    sim_s = time.perf_counter() - t0
    # warm-up on a short log (numba compilation is cached on disk after the first run ever)
    analyze(make_log({}, duration=15.0), progress=False)
    load_before = os.getloadavg()
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    res = analyze(log, progress=False)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - cpu0
    ours = score(res, {"camera_latency": [0.1], "steering_offset": [0.002]})

    vehicle = VehicleParams()
    config = DiscrepancyConfig()
    data = prepare(log, config)
    model = ResidualModel(data, vehicle, *axle_tires(vehicle, "pacejka", TireParams()), config)
    # peer 1: naive open-loop comparison (one simulation of the whole log from the first window's guess)
    t0 = time.perf_counter()
    traj = np.empty((len(data.t), N_OUT))
    simulate_rows(data.x0_guess[0], int(data.win_sim[0]), len(data.t) - 1, data.t, data.delta, data.dslope, data.vx,
                  data.pdd, model.veh, model.tf, model.tr, model.tabf, model.tabr, THETA_NOMINAL.copy(), config.step,
                  traj)  # fmt: skip
    naive_s = time.perf_counter() - t0
    frames = np.isfinite(log.sensors["e1"])
    rows = np.arange(int(data.win_sim[0]), len(data.t))
    drift = np.abs(traj[rows - int(data.win_sim[0]), 0][frames[rows]] - log.sensors["e1"][rows][frames[rows]])
    # peer 2: scipy least_squares on the full model (every effect parameter at once)
    idx, lo, hi, scale = [], [], [], []
    for e in LIBRARY:
        if e.needs_speed_variation:
            continue
        for i, b, s in zip(e.theta_index, e.bounds, e.scale):
            idx.append(i)
            lo.append(b[0] / s)
            hi.append(b[1] / s)
            scale.append(s)
    idx, lo, hi, scale = np.array(idx), np.array(lo), np.array(hi), np.array(scale)
    t0 = time.perf_counter()
    warm = {"x0": model.converged().x0}

    def fun(z):
        # the same objective as ours: window states converged, warm-started
        th = THETA_NOMINAL.copy()
        th[idx] = z * scale
        ev = model.evaluate(th, x0_guess=warm["x0"], converge=True)
        warm["x0"] = ev.x0
        return ev.resid

    z0 = np.clip(THETA_NOMINAL[idx] / scale, lo + 1e-6 * (hi - lo), hi - 1e-6 * (hi - lo))
    full = optimize.least_squares(fun, z0, bounds=(lo, hi), method="trf", diff_step=1e-3, max_nfev=400)
    full_s = time.perf_counter() - t0
    th_full = THETA_NOMINAL.copy()
    th_full[idx] = full.x * scale
    chi2_full = model.converged(th_full, warm["x0"]).chi2
    full_params = {e.name: e.as_dict(e.values_in(th_full)) for e in LIBRARY if not e.needs_speed_variation}
    return {
        "log": {"duration_s": 120.0, "rows": len(log), "row_rate_hz": 100.0, "camera_hz": 100.0,
                "hidden": hidden, "simulation_s": round(sim_s, 2)},  # fmt: skip
        "ours": {"wall_s": round(wall, 2), "cpu_s": round(cpu, 2), "target_s": 60.0, **ours},
        "peer_naive_open_loop": {
            "wall_s": round(naive_s, 4),
            "e1_error_median_m": float(np.median(drift)),
            "e1_error_max_m": float(np.max(drift)),
            "note": "one simulation of the whole log: fast, but it drifts (errors of metres), so it cannot say "
            "where or why the model is wrong",
        },
        "peer_least_squares_full_model": {
            "wall_s": round(full_s, 2),
            "nfev": int(full.nfev),
            "status": int(full.status),
            "parameters": full_params,
            "chi2": chi2_full,
            "chi2_ours": res.final.chi2,
            "n_parameters": len(idx),
            "note": "every parameter at once from the nominal model: no selection, no significance test; "
            "confounded parameters share the gap",
        },
        "load_average_before": [round(x, 2) for x in load_before],
        "numba_threads": int(os.environ.get("NUMBA_NUM_THREADS", "0")),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suite", choices=["speed", "accuracy", "clean", "robustness", "all"], default="speed")
    ap.add_argument("--seeds", type=int, default=20, help="clean suite: number of noise seeds")
    ap.add_argument("--robustness-seeds", type=int, default=5, help="robustness suite: noise seeds per effect")
    ap.add_argument("--rates", type=float, nargs="+", default=[100.0, 20.0], help="accuracy suite: camera rates [Hz]")
    args = ap.parse_args()
    result: dict = {"benchmark": "discrepancy"}
    if args.suite in ("speed", "all"):
        result["speed"] = suite_speed()
    if args.suite in ("accuracy", "all"):
        result["accuracy"] = suite_accuracy(tuple(args.rates))
    if args.suite in ("clean", "all"):
        result["clean"] = {f"{r:g}_hz": suite_clean(args.seeds, r) for r in args.rates}
    if args.suite in ("robustness", "all"):
        result["robustness"] = {f"{r:g}_hz": suite_robustness(args.robustness_seeds, r) for r in args.rates}
    emit(result)


if __name__ == "__main__":
    main()
