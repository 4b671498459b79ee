"""How much of the low-order stiffness error is the curve's representation, printed as JSON (issue 15).

For each scenario of the generalisation benchmark's ``low_order_pacejka`` family (seed 15, the drive the
benchmark scores, redrawn as it does when the truth lost control) the observer runs with defaults. Then
the weights are fitted by least squares to the TRUE axle curve over the slip the drive covered, and read
out by the estimator's own stiffness read-out (:func:`~tire_learning_env.observer.readout.stiffness_readout`).
``representation_error_pct`` is what the basis and the read-out alone get wrong with a perfect curve;
``estimate_error_pct`` is the estimator's error on the same drive. The difference is the estimator's own.

Run: ``python benchmarks/bench_readout_bias.py [--scenarios 0,1,2,3,4]`` (about a minute each).
"""

from __future__ import annotations

import argparse

from _bench_common import emit

import numpy as np  # noqa: E402

import bench_generalization as bg  # noqa: E402

AXLES = ("front", "rear")


def scenario(i: int) -> dict:
    from tire_learning_env.observer import ObserverConfig, estimate
    from tire_learning_env.observer.readout import curve_gradient, stiffness_readout

    sc, (log, _, _, nominal, true_curve, k_true), _, _ = bg._build_with_redraws(
        bg.sample_scenario("low_order_pacejka", i, 15, False), bg.build, lambda b: bg.truth_summary(b[0], b[1], None))
    res = estimate(log.sensors, nominal, config=ObserverConfig(sensors="camera"))
    obs, slip = res.observer, res.trace.slip
    c_nom = (obs.vehicle.Cf, obs.vehicle.Cr)
    w_true = np.zeros(obs.n_weights)
    for ax in (0, 1):  # the weights whose curve is closest to the truth over the covered slip
        a = slip[:, ax][np.isfinite(slip[:, ax])]
        lo, hi = np.percentile(a, [0.5, 99.5])
        grid = np.linspace(min(lo, 0.0), max(hi, 0.0), 200)
        G = curve_gradient(obs, grid, ax)
        cols = np.flatnonzero(np.any(G != 0.0, axis=0))
        F = np.asarray(true_curve(grid, AXLES[ax])) - 2.0 * c_nom[ax] * grid
        w_true[cols] = np.linalg.lstsq(G[:, cols], F, rcond=None)[0]
    rep, est, rng = [], [], []
    for ax in (0, 1):
        g_true, info = stiffness_readout(obs, w_true, slip[:, ax], ax)
        g_est, _ = stiffness_readout(obs, res.weights, slip[:, ax], ax)
        rep.append(100.0 * ((c_nom[ax] + g_true @ w_true) / k_true[ax] - 1.0))
        est.append(100.0 * ((c_nom[ax] + g_est @ res.weights) / k_true[ax] - 1.0))
        rng.append(info["range_deg"])
    return {"vehicle": sc["vehicle"], "attempt": int(sc["attempt"]), "representation_error_pct": [float(e) for e in rep],
            "estimate_error_pct": [float(e) for e in est], "readout_range_deg": rng}  # fmt: skip


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", default="0,1,2,3,4", help="comma-separated low_order_pacejka scenario indices")
    args = ap.parse_args(argv)
    out = {str(i): scenario(i) for i in (int(x) for x in args.scenarios.split(","))}
    rep = [abs(e) for r in out.values() for e in r["representation_error_pct"]]
    est = [e for r in out.values() for e in r["estimate_error_pct"]]
    return {"benchmark": "readout_bias", "family": "low_order_pacejka", "seed": 15, "scenarios": out,
            "max_abs_representation_error_pct": float(max(rep)), "estimate_errors_negative": int(sum(bool(e < 0) for e in est)),
            "estimate_errors": len(est)}  # fmt: skip


if __name__ == "__main__":
    emit(main())
