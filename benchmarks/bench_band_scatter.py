"""Is the stiffness band as wide as the estimate's real scatter? One drive, many camera-noise draws (issue 15's band
coverage), printed as JSON.

The generalisation benchmark scores one noise draw per drive, so a band that misses the truth there can be an
unlucky draw or a band too narrow. This benchmark separates the two: it takes a scenario of a camera family
(the drive the benchmark scores, redrawn as it is when the truth lost control) and simulates the same drive
(same vehicle, truth, road, speed, driver and camera settings) again with ``--draws`` other seeds of the
simulator, which draws the camera noise and the dropped frames; the driver steers on the noisy frames, so every
draw is a closed-loop log as the benchmark's. The observer runs with defaults on each.

Per axle it reports, over the draws:

- the errors and the reported standard deviations;
- ``mean_error_pct`` (the estimator's bias on this drive) and ``scatter_pct`` (the sample standard deviation of
  the errors: the estimate's real scatter);
- ``median_reported_std_pct`` and their ratio ``scatter_over_reported_std``: about 1 for a calibrated band
  (a ratio r from n draws has a chi-square spread: 95 % of ``r^2 (n - 1)`` lies in the chi-square (n - 1)
  quantiles, printed as ``ratio_95pct_if_calibrated``);
- ``coverage_2sigma``: the fraction of draws whose truth lies inside estimate +/- 2 std.

Run: ``python benchmarks/bench_band_scatter.py [--family low_order_pacejka] [--scenarios 3] [--draws 8] > FILE``
(20-60 s per draw on one core).
"""

from __future__ import annotations

import argparse
import copy
import time

from _bench_common import emit

import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402
from tqdm import tqdm  # noqa: E402

import bench_generalization as bg  # noqa: E402

CAMERA_FAMILIES = ("low_order_pacejka", "multi_body", "held_out")


def scenario(family: str, i: int, draws: int, seed: int, progress: bool) -> dict:
    from tire_learning_env.observer import ObserverConfig, estimate

    sc, built, _, _ = bg._build_with_redraws(bg.sample_scenario(family, i, seed, False), bg.build,
                                              lambda b: bg.truth_summary(b[0], b[1], None))  # fmt: skip
    runs = []
    for k in tqdm(range(draws + 1), desc=f"{family} {i}", disable=not progress):
        if k == 0:  # the benchmark's own draw
            this = sc
        else:
            this = copy.deepcopy(sc)
            this["sim_seed"] = int(sc["sim_seed"]) + k
            built = bg.build(this)
        log, plant, _, nominal, _, k_true = built
        if not bg.truth_summary(log, plant, this)["valid"]:
            runs.append({"sim_seed": int(this["sim_seed"]), "skipped": "the truth lost control on this draw"})
            continue
        t0 = time.perf_counter()
        res = estimate(log.sensors, nominal, config=ObserverConfig(sensors="camera"))
        k_hat, s = res.cornering_stiffness(), res.cornering_stiffness_std()
        runs.append({
            "sim_seed": int(this["sim_seed"]),
            "benchmark_draw": k == 0,
            "stiffness_error_pct": [100.0 * (k_hat[j] / k_true[j] - 1.0) for j in range(2)],
            "std_pct": [100.0 * s[j] / k_true[j] for j in range(2)],
            "z": [(k_hat[j] - k_true[j]) / s[j] if s[j] > 0 else None for j in range(2)],
            "verdict": res.summary().get("verdict"),
            "runtime_s": time.perf_counter() - t0,
        })  # fmt: skip
    ok = [r for r in runs if "skipped" not in r]
    err = np.array([r["stiffness_error_pct"] for r in ok])
    std = np.array([r["std_pct"] for r in ok])
    n = len(ok)
    summary: dict = {"draws_used": n}
    if n >= 3:
        scatter = err.std(axis=0, ddof=1)
        med = np.median(std, axis=0)
        lo, hi = stats.chi2.ppf([0.025, 0.975], n - 1)
        summary.update(
            mean_error_pct=err.mean(axis=0).tolist(),
            scatter_pct=scatter.tolist(),
            median_reported_std_pct=med.tolist(),
            scatter_over_reported_std=(scatter / med).tolist(),
            ratio_95pct_if_calibrated=[float(np.sqrt(lo / (n - 1))), float(np.sqrt(hi / (n - 1)))],
            coverage_2sigma=(np.abs(err) <= 2.0 * std).mean(axis=0).tolist(),
        )  # fmt: skip
    return {"vehicle": sc["vehicle"], "camera": sc["camera"], "attempt": int(sc["attempt"]), "runs": runs,
            "summary": summary}  # fmt: skip


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--family", default="low_order_pacejka", choices=CAMERA_FAMILIES)
    ap.add_argument("--scenarios", default="3", help="comma-separated scenario indices of the family")
    ap.add_argument("--draws", type=int, default=8, help="noise draws besides the benchmark's own")
    ap.add_argument("--seed", type=int, default=15, help="the generalisation benchmark's seed")
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)
    if args.draws < 2:
        ap.error("--draws must be at least 2 (a scatter needs three draws)")
    result = {"benchmark": "band_scatter", "family": args.family, "seed": args.seed, "draws": args.draws,
              "observer_call": 'estimate(log.sensors, nominal_vehicle, config=ObserverConfig(sensors="camera"))',
              "scenarios": {}}  # fmt: skip
    for i in [int(x) for x in args.scenarios.split(",")]:
        result["scenarios"][str(i)] = scenario(args.family, i, args.draws, args.seed, not args.no_progress)
    return result


if __name__ == "__main__":
    emit(main())
