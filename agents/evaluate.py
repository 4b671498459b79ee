#!/usr/bin/env python
"""Evaluate excitation policies and the scripted baselines on held-out seeds; write the table and figures.

    python agents/evaluate.py                                   # committed policies, 10 seeds, 60 s
    python agents/evaluate.py --policies runs/ppo_seed0/best_model.zip --out /tmp/eval
    python agents/evaluate.py --seeds 1000 1001 --duration 10 --out /tmp/short   # short budget

Every policy (each trained model and each scripted manoeuvre of
``agents/configs/scripted_baselines.json``) drives ``TireLearning-Excitation-v0`` for the
same time budget on the same seeds (same truth tires and camera noise per seed). Written
to ``--out``:

- ``excitation_table.json``: per policy the aggregate and every episode's metrics,
- ``excitation_table.md``: the table (mean +/- std over the seeds) and the target check,
- ``figures/excitation_curves.png``: the recovered tire curves of every policy on the
  first seed against the truth, and their error,
- ``figures/excitation_error_vs_time.png``: the median tire-curve error over time.

Every policy drives with the env's predictive a_y safety filter (``ExcitationConfig.safety_filter``,
on by default); the scripted manoeuvres, tuned without it, are also driven without it
(rows "(no filter)"), and the best scripted row of either kind is the one to beat.

Metrics: ``tire_curve_nrmse`` per axle over the fixed target slip range (``|alpha| <=``
the slip of steady nominal cornering at the a_y limit: 1.01 deg front, 0.70 deg rear at
4 m/s^2), the true slip range excited (0.5/99.5 % quantiles), the time after which the
worse-axle error stays below 5 %, lane violations (policy steps with true ``|e1|`` beyond
the 0.7 m lane margin; departures), max ``|a_y|`` (IMU, 1 kHz) and max steering rate
(change of the 50 ms step-mean road-wheel angle per second).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any, Callable

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

from _common import AGENTS_DIR, EVALUATION_SEEDS, REPO_DIR, load_model, model_policy, versions  # noqa: E402

DEFAULT_POLICIES = sorted((AGENTS_DIR / "policies").glob("*.zip"))
DEFAULT_BASELINES = AGENTS_DIR / "configs" / "scripted_baselines.json"
#: ``--policy-filter`` / ``--baseline-filter`` choices -> the safety-filter settings to drive with.
FILTER_CHOICES = {"both": (True, False), "on": (True,), "off": (False,)}


def row_label(name: str, safety_filter: bool) -> str:
    """A table row's name: ``name``, marked when the row drove without the safety filter."""
    return name if safety_filter else f"{name} (no filter)"


def _policy_name(path: Path) -> str:
    meta = path.with_suffix(".json")
    if meta.exists():
        name = json.loads(meta.read_text()).get("name")
        if name:
            return str(name)
    return path.stem


def load_baselines(path: Path) -> list[Any]:
    """Scripted manoeuvres with their tuned parameters."""
    from tire_learning_env.scripted import make_manoeuvre

    data = json.loads(Path(path).read_text())
    return [make_manoeuvre(m["name"], **m["params"]) for m in data["manoeuvres"]]


def evaluate_policy(
    name: str, act: Callable, road, seeds: list[int], duration: float, kind: str, safety_filter: bool = True,
    env_name: str = "straight",
) -> dict[str, Any]:
    from tire_learning_env.scripted import run_policy
    from tire_learning_env.wrappers.excitation import ExcitationConfig, make_excitation_env, make_highway_excitation_env

    config = ExcitationConfig(safety_filter=safety_filter)
    if env_name == "highway":  # the highway-env traffic scene brings its own road
        env = make_highway_excitation_env(config=config)
    else:
        env = make_excitation_env(config=config, road=road)
    t0 = time.perf_counter()
    episodes = []
    for s in seeds:
        r = run_policy(act, seed=s, duration=duration, env=env)
        r["final_weights"] = env.observer.weights.tolist()
        episodes.append(r)
    return {"name": name, "kind": kind, "safety_filter": bool(safety_filter), "episodes": episodes,
            "aggregate": aggregate(episodes), "seconds": time.perf_counter() - t0}  # fmt: skip


def aggregate(episodes: list[dict[str, Any]]) -> dict[str, Any]:
    """Mean/std/max over the episodes of one policy."""

    def stats(values):
        v = np.asarray(values, dtype=float)
        return {"mean": float(np.mean(v)), "std": float(np.std(v)), "min": float(np.min(v)), "max": float(np.max(v))}

    conv = [e["convergence_time_s"] for e in episodes]
    reached = [c for c in conv if c is not None]
    return {
        "seeds": [e["seed"] for e in episodes],
        "tire_curve_nrmse": {a: stats([e["tire_curve_nrmse"][a] for e in episodes]) for a in ("front", "rear")},
        "tire_curve_nrmse_max": stats([e["tire_curve_nrmse_max"] for e in episodes]),
        "excited_slip_range_deg": {
            a: [float(np.mean([e["excited_slip_range_deg"][a][0] for e in episodes])),
                float(np.mean([e["excited_slip_range_deg"][a][1] for e in episodes]))]
            for a in ("front", "rear")
        },  # fmt: skip
        "target_coverage": {a: float(np.mean([e["target_coverage"][a] for e in episodes])) for a in ("front", "rear")},
        "convergence_time_s": {
            "median": float(np.median([c if c is not None else math.inf for c in conv])) if conv else None,
            "mean_of_reached": float(np.mean(reached)) if reached else None,
            "never": len(conv) - len(reached),
        },
        "lane_violation_steps": int(sum(e["lane_violation_steps"] for e in episodes)),
        "departures": int(sum(e["departed"] for e in episodes)),
        "max_abs_e1": float(max(e["max_abs_e1"] for e in episodes)),
        "max_abs_ay": float(max(e["max_abs_ay"] for e in episodes)),
        "ay_violation_steps": int(sum(e["ay_violation_steps"] for e in episodes)),
        "filter_active_fraction": float(sum(e["filter_active_steps"] for e in episodes) / sum(e["steps"] for e in episodes)),
        "max_steering_rate": float(max(e["max_steering_rate"] for e in episodes)),
        "information_gain": stats([e["information_gain"] for e in episodes]),
        "return": stats([e["return"] for e in episodes]),
    }


def target_check(results: list[dict[str, Any]], ay_limit: float) -> dict[str, Any]:
    """Each learned policy against the best scripted baseline (lowest mean worse-axle NRMSE)."""
    scripted = [r for r in results if r["kind"] == "scripted"]
    learned = [r for r in results if r["kind"] == "learned" and r.get("safety_filter", True)]
    if not scripted:
        return {}
    best = min(scripted, key=lambda r: r["aggregate"]["tire_curve_nrmse_max"]["mean"])
    best_name = row_label(best["name"], best.get("safety_filter", True))
    out = {"best_scripted": best_name, "policies": {}}
    for r in learned:
        a, b = r["aggregate"], best["aggregate"]
        per_seed_wins = sum(
            ea["tire_curve_nrmse_max"] < eb["tire_curve_nrmse_max"] for ea, eb in zip(r["episodes"], best["episodes"])
        )
        lower = {ax: a["tire_curve_nrmse"][ax]["mean"] < b["tire_curve_nrmse"][ax]["mean"] for ax in ("front", "rear")}
        safe = a["lane_violation_steps"] == 0 and a["departures"] == 0 and a["max_abs_ay"] <= ay_limit
        out["policies"][r["name"]] = {
            "nrmse_max_mean": a["tire_curve_nrmse_max"]["mean"],
            "best_scripted_nrmse_max_mean": b["tire_curve_nrmse_max"]["mean"],
            "lower_worse_axle_nrmse": a["tire_curve_nrmse_max"]["mean"] < b["tire_curve_nrmse_max"]["mean"],
            "lower_per_axle": lower,
            "per_seed_wins": f"{per_seed_wins}/{len(r['episodes'])}",
            "zero_lane_violations": a["lane_violation_steps"] == 0 and a["departures"] == 0,
            "ay_within_limit": a["max_abs_ay"] <= ay_limit,
            "target_met": bool(a["tire_curve_nrmse_max"]["mean"] < b["tire_curve_nrmse_max"]["mean"] and safe),
        }
    return out


def markdown(results: list[dict[str, Any]], check: dict[str, Any], meta: dict[str, Any]) -> str:
    def ms(s, scale=100.0, fmt="{:.2f}"):
        return f"{fmt.format(scale * s['mean'])} ± {fmt.format(scale * s['std'])}"

    lines = [
        f"Excitation policies on `{meta['env_id']}`: {meta['duration_s']:.0f} s of driving per episode, "
        f"seeds {meta['seeds'][0]}-{meta['seeds'][-1]} ({len(meta['seeds'])} held-out seeds: new truth tires and camera "
        f"noise), a_y limit {meta['ay_limit']:.1f} m/s², lane margin {meta['lane_margin']:.2f} m. Tire-curve NRMSE over "
        f"the fixed target range |α_f| ≤ {meta['target_slip_deg']['front']:.2f}°, |α_r| ≤ "
        f"{meta['target_slip_deg']['rear']:.2f}° (mean ± std over seeds, in %). Excited slip: true 0.5/99.5 % "
        f"quantiles (mean over seeds). a_y: the IMU at 1 kHz, max over all seeds; steps above the limit counted "
        f"over all {len(meta['seeds'])} × {int(round(meta['duration_s'] * 20))} policy steps. Safety filter: the env's "
        f"predictive a_y filter (`ExcitationConfig.safety_filter`, on by default) changed the offset on the given share of "
        f"steps; rows marked 'no filter' drive without it (scripted manoeuvres are tuned without it).",
        "",
        "| policy | NRMSE front [%] | NRMSE rear [%] | NRMSE worse axle [%] | excited α_f [deg] | excited α_r [deg] "
        "| t(err < 5 %) median [s] | never < 5 % | lane violations (steps / departures) "
        "| max abs(a_y) [m/s²] (steps above the limit) | max steering rate [rad/s] | filter active [% of steps] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        a = r["aggregate"]
        ef, er = a["excited_slip_range_deg"]["front"], a["excited_slip_range_deg"]["rear"]
        conv = a["convergence_time_s"]["median"]
        conv_s = "—" if conv is None or not math.isfinite(conv) else f"{conv:.1f}"
        name = f"**{r['name']}** (learned)" if r["kind"] == "learned" else r["name"]
        label = row_label(name, r.get("safety_filter", True))
        active = f"{100 * a['filter_active_fraction']:.1f}" if r.get("safety_filter", True) else "—"
        lines.append(
            f"| {label} | {ms(a['tire_curve_nrmse']['front'])} | {ms(a['tire_curve_nrmse']['rear'])} "
            f"| {ms(a['tire_curve_nrmse_max'])} | [{ef[0]:.2f}, {ef[1]:.2f}] | [{er[0]:.2f}, {er[1]:.2f}] | {conv_s} "
            f"| {a['convergence_time_s']['never']}/{len(a['seeds'])} | {a['lane_violation_steps']} / {a['departures']} "
            f"| {a['max_abs_ay']:.2f} ({a['ay_violation_steps']}) | {a['max_steering_rate']:.3f} | {active} |"
        )
    if check:
        lines += ["", f"Best scripted baseline (lowest mean worse-axle NRMSE, with or without the filter, whether "
                      f"or not it kept the limits itself): **{check['best_scripted']}**.", ""]
        for name, c in check["policies"].items():
            verdict = "met" if c["target_met"] else "NOT met"
            lines.append(
                f"- `{name}`: worse-axle NRMSE {100 * c['nrmse_max_mean']:.2f} % vs {100 * c['best_scripted_nrmse_max_mean']:.2f} % "
                f"(lower per axle: front {c['lower_per_axle']['front']}, rear {c['lower_per_axle']['rear']}; lower on "
                f"{c['per_seed_wins']} seeds), zero lane violations: {c['zero_lane_violations']}, |a_y| within the limit: "
                f"{c['ay_within_limit']} → target **{verdict}**."
            )
    return "\n".join(lines) + "\n"


def plot(results: list[dict[str, Any]], out_dir: Path) -> list[Path]:
    """Recovered curves on the first seed and the median error over time, per policy (rows with the filter)."""
    results = [r for r in results if r.get("safety_filter", True)] or results
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tire_learning_env.plotting import save_figure
    from tire_learning_env.wrappers.excitation import TruthRandomization, make_excitation_env

    env = make_excitation_env()
    obs_ = env.observer
    first = results[0]["episodes"][0]
    plant = TruthRandomization().build_plant(env.vehicle, first["truth_draw"])
    tgt = env.target
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    fig, axes = plt.subplots(2, 2, figsize=(12, 8), sharex="col")
    for col, axle in enumerate(("front", "rear")):
        span = 1.6 * tgt[col]
        grid = np.linspace(-span, span, 401)
        deg = np.degrees(grid)
        truth = plant.true_axle_curve(grid, axle)
        inside = np.abs(grid) <= tgt[col]
        scale = float(np.max(np.abs(truth[inside])))
        axes[0, col].plot(deg, truth, "k-", lw=2.2, label="truth")
        nominal = 2 * (env.vehicle.Cf if axle == "front" else env.vehicle.Cr) * grid
        axes[0, col].plot(deg, nominal, color="0.6", ls=":", lw=1.2, label="nominal (no learning)")
        for i, r in enumerate(results):
            ep = r["episodes"][0]
            w = np.asarray(ep["final_weights"])
            f = obs_.axle_force(grid, axle, weights=w)
            style = {"lw": 2.0, "ls": "-"} if r["kind"] == "learned" else {"lw": 1.1, "ls": "--"}
            c = colors[i % len(colors)]
            axes[0, col].plot(deg, f, color=c, label=r["name"], **style)
            axes[1, col].plot(deg, 100 * (f - truth) / scale, color=c, label=r["name"], **style)
        for ax in axes[:, col]:
            ax.axvspan(-math.degrees(tgt[col]), math.degrees(tgt[col]), color="tab:green", alpha=0.07)
            ax.grid(alpha=0.3)
        axes[0, col].set_title(f"{axle} axle (seed {first['seed']}; shaded: target slip range)")
        axes[0, col].set_ylabel("axle lateral force [N]")
        axes[1, col].set_ylabel("learned − true [% of max |F| in range]")
        axes[1, col].set_xlabel("slip angle [deg]")
        axes[1, col].set_ylim(-15, 15)
    axes[0, 0].legend(fontsize=7, loc="upper left")
    fig.suptitle("Tire curves recovered after the drive, per excitation policy")
    curves = out_dir / "figures" / "excitation_curves.png"
    save_figure(fig, curves)

    fig, ax = plt.subplots(figsize=(8, 4.5))
    for i, r in enumerate(results):
        hist = [np.asarray(e["error_history"]["nrmse_max"]) for e in r["episodes"]]
        n = min(len(h) for h in hist)
        t = np.asarray(r["episodes"][0]["error_history"]["t"][:n])
        med = np.median(np.stack([h[:n] for h in hist]), axis=0)
        style = {"lw": 2.0} if r["kind"] == "learned" else {"lw": 1.0, "ls": "--"}
        ax.semilogy(t, 100 * med, color=colors[i % len(colors)], label=r["name"], **style)
    ax.axhline(5.0, color="k", lw=0.8, ls=":")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("worse-axle tire-curve NRMSE [%] (median over seeds)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    history = out_dir / "figures" / "excitation_error_vs_time.png"
    save_figure(fig, history)
    return [curves, history]


def _compact(results: list[dict[str, Any]], every: int = 10) -> list[dict[str, Any]]:
    """Results for the JSON file: error histories every ``every`` steps, floats to 6 significant digits."""

    def rounded(x):
        if isinstance(x, float):
            return float(f"{x:.6g}")
        if isinstance(x, dict):
            return {k: rounded(v) for k, v in x.items()}
        if isinstance(x, list):
            return [rounded(v) for v in x]
        return x

    out = []
    for r in results:
        episodes = []
        for e in r["episodes"]:
            e = dict(e)
            h = e["error_history"]
            e["error_history"] = {"t": h["t"][every - 1 :: every], "nrmse_max": h["nrmse_max"][every - 1 :: every]}
            episodes.append(e)
        out.append(rounded({**r, "episodes": episodes}))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--policies", nargs="*", type=Path, default=DEFAULT_POLICIES, help="trained SB3 models (.zip)")
    parser.add_argument("--baselines", type=Path, default=DEFAULT_BASELINES, help="tuned scripted baselines JSON")
    parser.add_argument("--no-baselines", action="store_true", help="evaluate the trained policies only")
    parser.add_argument("--seeds", nargs="*", type=int, default=list(EVALUATION_SEEDS), help="held-out reset seeds")
    parser.add_argument("--duration", type=float, default=60.0, help="driving time per episode [s]")
    parser.add_argument("--out", type=Path, default=REPO_DIR / "docs", help="output directory")
    parser.add_argument("--no-figures", action="store_true")
    parser.add_argument("--baseline-filter", choices=tuple(FILTER_CHOICES), default="both",
                        help="drive the scripted manoeuvres with the safety filter, without it, or both (default)")
    parser.add_argument("--policy-filter", choices=tuple(FILTER_CHOICES), default="on",
                        help="drive the trained policies with the safety filter (default), without it, or both")
    parser.add_argument("--env", choices=("straight", "highway"), default="straight",
                        help="TireLearning-Excitation-v0 (default) or TireLearning-HighwayExcitation-v0 "
                             "(highway-env traffic; trained policies only)")
    args = parser.parse_args(argv)

    from tire_learning_env.roads import StraightRoad
    from tire_learning_env.wrappers.excitation import ExcitationConfig, make_excitation_env

    if args.env == "highway" and not args.no_baselines:
        print("--env highway: the scripted manoeuvres need their own roads, evaluating the trained policies only")
        args.no_baselines = True
    results = []
    policy_filters = FILTER_CHOICES[args.policy_filter]
    for path in args.policies:
        model = load_model(path)
        name = _policy_name(path)
        for filtered in policy_filters:
            results.append(evaluate_policy(name, model_policy(model), StraightRoad(), args.seeds, args.duration, "learned",
                                           filtered, args.env))  # fmt: skip
            results[-1]["path"] = str(path)
            print(f"{row_label(name, filtered):28s} worse-axle NRMSE {100 * results[-1]['aggregate']['tire_curve_nrmse_max']['mean']:.2f} %",
                  flush=True)  # fmt: skip
    if not args.no_baselines:
        dt = 1.0 / 20.0
        max_offset = ExcitationConfig().max_steering_offset
        for filtered in FILTER_CHOICES[args.baseline_filter]:
            for m in load_baselines(args.baselines):
                def act(obs, k, m=m):
                    return m.offset(k * dt) / max_offset

                results.append(evaluate_policy(m.name, act, m.road(), args.seeds, args.duration, "scripted", filtered))
                results[-1]["manoeuvre"] = m.describe()
                print(f"{row_label(m.name, filtered):28s} worse-axle NRMSE {100 * results[-1]['aggregate']['tire_curve_nrmse_max']['mean']:.2f} %",
                      flush=True)  # fmt: skip
    if not results:
        parser.error("nothing to evaluate: give --policies and/or baselines")
    env = make_excitation_env()
    meta = {
        "env_id": "TireLearning-HighwayExcitation-v0" if args.env == "highway" else "TireLearning-Excitation-v0",
        "seeds": list(args.seeds),
        "duration_s": args.duration,
        "ay_limit": env.config.ay_limit,
        "lane_margin": env.config.lane_margin,
        "safety_filter": {k: getattr(env.config, k) for k in ("safety_filter", "safety_stiffness_uncertainty",
                                                              "safety_horizon", "safety_noise_sigmas")},
        "target_slip_deg": {a: math.degrees(v) for a, v in zip(("front", "rear"), env.target)},
        "versions": versions(),
    }
    check = target_check(results, env.config.ay_limit)
    args.out.mkdir(parents=True, exist_ok=True)
    table_json = args.out / "excitation_table.json"
    table_md = args.out / "excitation_table.md"
    summary = [{k: v for k, v in r.items() if k != "episodes"} for r in results]
    table_json.write_text(
        json.dumps({"meta": meta, "target_check": check, "summary": summary, "results": _compact(results)})
    )
    table_md.write_text(markdown(results, check, meta))
    written = [table_json, table_md]
    if not args.no_figures:
        written += plot(results, args.out)
    print(table_md.read_text())
    for p in written:
        print(p)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
