"""How long a piece of a fixed-weight pass must warm up (:func:`tire_learning_env.observer.passes.pass_pieces`),
printed as JSON.

A 300 s, 100 Hz lane-change log with the paper's 20 Hz camera noise (seed 3), weights drawn at 2 % of
the weight range (seed 0). The pass is run once as one piece and then as two halves whose second
starts ``overlap`` seconds early from a cold state; per overlap: the distance between the two
Gauss-Newton steps in posterior standard deviations (``sqrt(d^T A d)``), the relative change of the
cost and the largest change of the normal matrix relative to its largest entry.

Run: ``python benchmarks/bench_pass_pieces.py``.
"""

from __future__ import annotations

import math

from _bench_common import emit

OVERLAPS_S = (0.0, 2.0, 5.0, 10.0, 30.0)


def main() -> dict:
    import numpy as np

    from tire_learning_env.observer import ObserverConfig, build_observer, passes
    from tire_learning_env.params import CameraParams, VehicleParams
    from tire_learning_env.simulation import simulate

    log = simulate("lane_changes", 300.0, camera=CameraParams.paper_noise(rate=20.0), physics_rate=100.0, seed=3)
    s, t = log.sensors, np.asarray(log.sensors["t"])
    obs = build_observer(VehicleParams(), CameraParams.paper_noise(rate=20.0), ObserverConfig(), physics_dt=log.dt)
    w = np.random.default_rng(0).normal(0.0, 0.02, obs.n_weights) * obs.basis.weight_range
    fit_from = float(t[0]) + obs.settle_s
    lam = np.linalg.inv(obs.prior_covariance(offline=True))
    n, m = len(t), len(t) // 2
    orig = passes.pass_pieces
    try:
        passes.pass_pieces = lambda tt, settle: [(0, 0, n)]
        single, _ = passes._pass(obs, s, w, fit_from, 25.0)
        A = single.hess + lam
        step = np.linalg.solve(A, single.grad - lam @ w)
        rows = []
        for ov in OVERLAPS_S:
            a = int(np.searchsorted(t, t[m] - ov))
            passes.pass_pieces = lambda tt, settle, a=a: [(0, 0, m), (a, m, n)]
            two, _ = passes._pass(obs, s, w, fit_from, 25.0)
            d = np.linalg.solve(two.hess + lam, two.grad - lam @ w) - step
            rows.append({"overlap_s": ov, "step_difference_posterior_sd": math.sqrt(float(d @ A @ d)),
                         "cost_rel_change": float(two.stats[0] / single.stats[0] - 1.0),
                         "hessian_max_rel_change": float(np.abs(two.hess - single.hess).max() / np.abs(single.hess).max())})
    finally:
        passes.pass_pieces = orig
    return {"benchmark": "pass_pieces", "log": "lane_changes 300 s, 100 Hz rows, 20 Hz paper-noise camera, seed 3",
            "default_pieces": [list(p) for p in orig(t, obs.settle_s)], "default_overlap_s": passes.PIECE_OVERLAP_S,
            "by_overlap": rows}


if __name__ == "__main__":
    emit(main())
