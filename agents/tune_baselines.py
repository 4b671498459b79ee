#!/usr/bin/env python
"""Tune the scripted excitation baselines to the lateral-acceleration limit and write their parameters.

    python agents/tune_baselines.py                      # -> agents/configs/scripted_baselines.json

For every manoeuvre of :mod:`tire_learning_env.scripted` and every candidate shape
parameter below, the amplitude is bisected on the tuning seeds (10000-10002, never used
for evaluation) to the largest value whose max ``|a_y|`` stays within 95 % of the limit
and whose true ``|e1|`` stays within 95 % of the lane margin; among the candidates of a
manoeuvre the one with the lowest mean worse-axle tire-curve NRMSE on the tuning seeds
is kept (an engineer tuning the manoeuvre in simulation). The file records the scan.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

from _common import AGENTS_DIR, TUNING_SEEDS, versions  # noqa: E402

#: Shape candidates per manoeuvre (the amplitude is tuned for each).
CANDIDATES: dict[str, list[dict]] = {
    "none": [{}],
    "cornering": [{}],
    "lane_changes": [{"gap": 0.0}, {"gap": 30.0}, {"gap": 90.0}],
    "sine_road": [{"wavelength": 150.0}, {"wavelength": 300.0}, {"wavelength": 600.0}],
    "chirp_road": [{}],
    "sine_weave": [{"frequency": 0.3}, {"frequency": 0.4}, {"frequency": 0.5}, {"frequency": 0.7}],
    "chirp_weave": [{}],
}


def tune_all(seeds, fraction: float, iterations: int, duration: float | None, names: list[str] | None = None) -> dict:
    from tire_learning_env.scripted import make_manoeuvre, run_manoeuvre, tune_amplitude
    from tire_learning_env.wrappers.excitation import ExcitationConfig

    unfiltered = ExcitationConfig(safety_filter=False)  # a manoeuvre keeps the limits by itself
    out = []
    for name, candidates in CANDIDATES.items():
        if names and name not in names:
            continue
        scan = []
        for params in candidates:
            t0 = time.perf_counter()
            tuned = tune_amplitude(make_manoeuvre(name, **params), seeds=seeds, fraction=fraction, lane_fraction=fraction,
                                   iterations=iterations, duration=duration, config=unfiltered)  # fmt: skip
            m = tuned.manoeuvre
            scores = [run_manoeuvre(m, seed=s, duration=duration, config=unfiltered)["tire_curve_nrmse_max"] for s in seeds]
            entry = {
                "params": {**params, "amplitude": m.amplitude},
                "tuning_max_abs_ay": tuned.max_abs_ay,
                "tuning_max_abs_e1": tuned.max_abs_e1,
                "tuning_nrmse_max_mean": float(np.mean(scores)),
                "seconds": time.perf_counter() - t0,
            }
            scan.append(entry)
            print(f"{name:13s} {entry['params']}  max|ay|={tuned.max_abs_ay:.2f}  max|e1|={tuned.max_abs_e1:.2f}  "
                  f"nrmse={entry['tuning_nrmse_max_mean']:.4f}", flush=True)  # fmt: skip
        best = min(scan, key=lambda e: e["tuning_nrmse_max_mean"])
        out.append({"name": name, "params": best["params"], "amplitude_unit": make_manoeuvre(name).amplitude_unit, "scan": scan})
    return {
        "tuning": {"seeds": list(seeds), "ay_fraction": fraction, "lane_fraction": fraction, "iterations": iterations,
                   "duration_s": duration, "selection": "lowest mean worse-axle tire_curve_nrmse on the tuning seeds"},
        "manoeuvres": out,
        "versions": versions(),
    }  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=AGENTS_DIR / "configs" / "scripted_baselines.json")
    parser.add_argument("--fraction", type=float, default=0.95, help="fraction of the a_y limit and lane margin to use")
    parser.add_argument("--iterations", type=int, default=12, help="bisection iterations")
    parser.add_argument("--duration", type=float, default=None, help="driving time [s] (default: the episode time, 60 s)")
    parser.add_argument("--only", nargs="*", default=None, help="tune only these manoeuvres")
    args = parser.parse_args(argv)
    result = tune_all(TUNING_SEEDS, args.fraction, args.iterations, args.duration, args.only)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2))
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
