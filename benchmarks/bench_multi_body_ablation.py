"""Which of the multi-body car's dynamics make the observer read its stiffness low (issue 15), printed as JSON.

The generalisation benchmark's ``multi_body`` family reads the effective (steady-circle) stiffness about 4 % low
(median, n = 20), and the plan was a relaxation state in the observer's model. This ablation removes candidate
causes from the truth plant and re-runs the same scenarios end to end (``bench_generalization.run_scenario``: the
observer with defaults and the joint UKF given the frame rate and the measured noise, scored against the
effective stiffness of the plant as modified, which the scoring recomputes):

- ``as_drawn``: the family as benchmarked (tire relaxation 0.45 m, CommonRoad's roll camber);
- ``no_relaxation``: ``HighOrderConfig(relaxation_length=0)``;
- ``no_roll_camber``: the suspension's roll-camber coefficients ``D_f, D_r, E_f, E_r`` set to 0 (the wheels
  then lean with the body: camber = roll angle);
- ``neither``: both removed;
- ``no_camber_thrust``: the tire's camber terms ``p_hy3``, ``p_vy3`` (PAC2002's slip shift and force per camber)
  set to 0, so the body's roll adds no lateral force;
- ``no_camber_thrust_no_relaxation``: that and no tire relaxation.

Per variant: the observer's and the UKF's signed and absolute stiffness errors (median, p90, mean per axle), the
observer's band coverage, verdicts and model-error flags; and per CommonRoad vehicle the tire's own stiffness and the
effective one (``stiffness_references``: how much the roll's camber thrust adds on steady circles). If relaxation or roll camber made the low reading,
removing it would shrink the error.

Run: ``python benchmarks/bench_multi_body_ablation.py [--n 10] [--workers 2] [--variants ...] [--out FILE]``
(about 10 s per scenario and variant per worker).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses

from _bench_common import chosen, emit, map_jobs

import numpy as np  # noqa: E402

#: Keyword arguments of :func:`modified_plant` per variant.
VARIANTS = {
    "as_drawn": {"relaxation_length": None, "roll_camber": True},
    "no_relaxation": {"relaxation_length": 0.0, "roll_camber": True},
    "no_roll_camber": {"relaxation_length": None, "roll_camber": False},
    "neither": {"relaxation_length": 0.0, "roll_camber": False},
    "no_camber_thrust": {"relaxation_length": None, "roll_camber": True, "camber_thrust": False},
    "no_camber_thrust_no_relaxation": {"relaxation_length": 0.0, "roll_camber": True, "camber_thrust": False},
}


@contextlib.contextmanager
def modified_plant(relaxation_length: float | None = None, roll_camber: bool = True, camber_thrust: bool = True):
    """Every :class:`~tire_learning_env.high_order.MultiBodyPlant` built inside is modified: tire relaxation length
    [m] (``None``: as configured), the suspension's roll camber ``D``, ``E`` (``False``: 0) and the tire's camber
    thrust ``p_hy3``, ``p_vy3`` (``False``: 0). The class is restored on exit."""
    import tire_learning_env.high_order.plant as hp
    from tire_learning_env.high_order.params import HighOrderConfig

    original = hp.MultiBodyPlant.__init__

    def init(self, road, params=None, **kw):
        if relaxation_length is not None:
            kw.setdefault("config", HighOrderConfig(relaxation_length=relaxation_length))
        if params is not None:
            params = _modified_params(params, roll_camber, camber_thrust)
        original(self, road, params=params, **kw)

    hp.MultiBodyPlant.__init__ = init
    try:
        yield
    finally:
        hp.MultiBodyPlant.__init__ = original


def _modified_params(params, roll_camber: bool, camber_thrust: bool):
    if not roll_camber:
        params = dataclasses.replace(params, D_f=0.0, D_r=0.0, E_f=0.0, E_r=0.0)
    if not camber_thrust:
        params = dataclasses.replace(params, tire=dataclasses.replace(params.tire, p_hy3=0.0, p_vy3=0.0))
    return params


def run(job: tuple) -> dict:
    """One scenario under one variant: ``bench_generalization.run_scenario`` on the modified plant."""
    i, name, seed = job
    import bench_generalization as bg

    sc = bg.sample_scenario("multi_body", i, seed, False)
    with modified_plant(**VARIANTS[name]):
        r = bg.run_scenario(sc)
    o, u = r.get("observer") or {}, r.get("ukf") or {}
    return {"scenario": i, "variant": name, "vehicle": sc["vehicle"],
            "valid": bool((r.get("truth_summary") or {}).get("valid", False)),
            "true_stiffness_N_per_rad": r.get("true_stiffness_N_per_rad"),
            "observer_error_pct": o.get("stiffness_error_pct"), "observer_covered": o.get("covered_2sigma"),
            "observer_verdict": o.get("verdict"), "model_error_detected": o.get("model_error_detected"),
            "ukf_error_pct": u.get("stiffness_error_pct"), "error": r.get("error")}  # fmt: skip


def stiffness_references(name: str) -> dict:
    """Per CommonRoad vehicle of the family under variant ``name``: the tire's own per-tire stiffness at static load
    and the effective (steady-circle) one the family is scored against [N/rad]."""
    from tire_learning_env.high_order import MultiBodyParams
    from tire_learning_env.high_order.params import HighOrderConfig
    from tire_learning_env.high_order.plant import true_cornering_stiffness
    from tire_learning_env.high_order.simulate import effective_cornering_stiffness

    spec = VARIANTS[name]
    out = {}
    for vehicle in (1, 2):
        p = _modified_params(MultiBodyParams.from_commonroad(vehicle), spec.get("roll_camber", True),
                             spec.get("camber_thrust", True))  # fmt: skip
        config = None if spec["relaxation_length"] is None else HighOrderConfig(relaxation_length=spec["relaxation_length"])
        tire, eff = true_cornering_stiffness(p), effective_cornering_stiffness(p, config)
        out[f"commonroad_{vehicle}"] = {"tire_N_per_rad": [round(float(x)) for x in tire],
                                        "effective_N_per_rad": [round(float(x)) for x in eff],
                                        "effective_over_tire_pct": [round(100.0 * (e / t - 1.0), 2) for e, t in zip(eff, tire)]}  # fmt: skip
    return out


def summarise(rows: list[dict]) -> dict:
    ok = [r for r in rows if r["valid"] and r["observer_error_pct"] is not None]
    if not ok:
        return {"n": 0}
    e = np.array([r["observer_error_pct"] for r in ok])
    out = {"n": len(ok),
           "observer_abs_error_pct": {"median": round(float(np.median(np.abs(e))), 2),
                                      "p90": round(float(np.percentile(np.abs(e), 90)), 2)},
           "observer_mean_error_pct": e.mean(0).round(2).tolist(),
           "observer_coverage": round(float(np.mean([c for r in ok for c in (r["observer_covered"] or [])])), 3),
           "identified": sum(r["observer_verdict"] == "identified" for r in ok),
           "model_error_flagged": sum(bool(r["model_error_detected"]) for r in ok)}  # fmt: skip
    uk = [r["ukf_error_pct"] for r in ok if r["ukf_error_pct"] is not None]
    if uk:
        u = np.array(uk)
        out["ukf_abs_error_pct"] = {"median": round(float(np.median(np.abs(u))), 2), "p90": round(float(np.percentile(np.abs(u), 90)), 2)}
        out["ukf_mean_error_pct"] = u.mean(0).round(2).tolist()
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10, help="multi_body scenarios 0 .. n-1")
    ap.add_argument("--seed", type=int, default=15, help="the generalisation benchmark's seed")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated, of " + ", ".join(VARIANTS))
    ap.add_argument("--out", default=None, help="also write the JSON here (atomically)")
    args = ap.parse_args(argv)
    names = chosen(ap, args.variants, VARIANTS, "variant(s)")
    jobs = [(i, v, args.seed) for v in names for i in range(args.n)]
    rows = map_jobs(run, jobs, args.workers, "multi-body ablation")
    out = {"benchmark": "multi_body_ablation", "seed": args.seed, "n": args.n, "variants": {v: VARIANTS[v] for v in names},
           "summary": {v: summarise([r for r in rows if r["variant"] == v]) for v in names},
           "stiffness_references": {v: stiffness_references(v) for v in names}, "drives": rows}  # fmt: skip
    emit(out, args.out)
    return out


if __name__ == "__main__":
    main()
