"""Write a discrepancy result as ``report.json``, a readable ``report.md`` and PNG figures.

:func:`write_report` fills a fresh temporary directory and swaps it in at the end
(:func:`tire_learning_env.io.atomic_directory`): an existing output directory is replaced
only once everything was written, never left half-way.
"""

from __future__ import annotations

import math
from pathlib import Path

from ..io import atomic_directory, atomic_write_json, atomic_write_text
from . import plots
from .result import DiscrepancyResult

__all__ = ["write_report", "render_markdown"]


def _fmt(x, digits: int = 4) -> str:
    if x is None:
        return "-"
    if isinstance(x, float):
        if math.isinf(x):
            return "inf"
        if x != 0 and (abs(x) < 1e-3 or abs(x) >= 1e5):
            return f"{x:.{digits - 1}e}"
        return f"{x:.{digits}g}"
    return str(x)


def write_report(result: DiscrepancyResult, out: str | Path, overwrite: bool = True) -> Path:
    """Write ``out/report.json``, ``out/report.md`` and the figures, atomically.

    Returns the output directory.
    """
    out = Path(out)
    with atomic_directory(out, overwrite=overwrite) as tmp:
        figures = {
            "residuals.png": plots.plot_residuals,
            "disagreement.png": plots.plot_disagreement,
            "candidates.png": plots.plot_candidates,
            "whiteness.png": plots.plot_whiteness,
        }
        if any(e["name"] == "tire_relaxation" for e in result.effects):
            figures["force_slip_loop.png"] = plots.plot_force_slip_loop
        if result.data.kind == "imu":
            figures["regime_residuals.png"] = plots.plot_regime_residuals
            figures["worst_window.png"] = plots.plot_worst_window
        for name, fn in figures.items():
            fn(result, path=tmp / name)
        doc = result.to_json()
        doc["figures"] = sorted(figures)
        atomic_write_json(tmp / "report.json", doc)
        atomic_write_text(tmp / "report.md", render_markdown(result, doc))
    return out


def render_markdown(result: DiscrepancyResult, doc: dict) -> str:
    """The human-readable report."""
    lines = [f"# Model discrepancy report: `{Path(result.source).name or result.source}`", ""]
    verdict_text = {
        "found": "the nominal model misses the effect(s) below; adding them closes the gap to the noise level.",
        "none": "the nominal model explains the data within the measurement noise.",
        "unexplained": "a structured residual remains that no candidate effect in the library explains. "
        "No effect is named.",
        "ambiguous": "several candidate effects explain the log about equally well; this log cannot tell them apart. "
        "No single one is named; the manoeuvre below would separate them.",
    }[result.verdict]
    lines += [f"**Verdict: `{result.verdict}`**: {verdict_text}", ""]
    if result.verdict == "ambiguous":
        lines += ["## Candidates that fit equally well", "",
                  "| candidate | parameters | chi2 | LR | p-value | BIC above the best |", "|---|---|---|---|---|---|"]
        for c in result.candidates:
            params = ", ".join(f"{k} = {_fmt(v)} {c['units'].get(k, '')}" for k, v in c["parameters"].items())
            lines.append(f"| `{c['name']}` | {params} | {_fmt(c['chi2'])} | {_fmt(c['likelihood_ratio'])} | "
                         f"{_fmt(c['p_value'], 2)} | {_fmt(c['delta_bic_to_best'], 3)} |")
        sm = result.separating_manoeuvre or {}
        lines += ["", f"**Separating manoeuvre** ({', '.join(sm.get('effects', []))}): {sm.get('manoeuvre', '-')}.", ""]
        check = sm.get("check_by_simulation")
        if check:
            if check.get("verified") is None:
                lines.append(f"Not checked by simulation: {check.get('reason')}.")
            else:
                lines.append("Checked by simulating the manoeuvre with each candidate as the truth: "
                             + ("it separates them" if check["verified"] else "it did NOT separate them") + " ("
                             + "; ".join(f"truth `{r['truth']}`: {r['verdict']} {r['named']}, BIC advantage "
                                         f"{_fmt(r['bic_advantage_of_truth'], 3)}" for r in check["runs"]) + ").")
            lines.append("")
    tire = doc["nominal_model"]["tire"]
    lines += [
        f"Nominal model: bicycle model + {tire['kind']} tire; vehicle m = {result.vehicle.m:g} kg, "
        f"Cf = {result.vehicle.Cf:g} N/rad, Cr = {result.vehicle.Cr:g} N/rad per tire "
        f"(vehicle: {doc['nominal_model'].get('vehicle_source', 'not recorded')}).",
        f"Log: {doc['log']['rows']} rows, {doc['log']['duration_s']:.1f} s, channels {', '.join(doc['comparison']['channels'])}. "
        f"Analysis took {result.runtime_s:.1f} s.",
        "",
    ]
    if result.effects:
        lines += ["## Effects found", "", "| effect | parameter | value | std. error | unit | LR | p-value | dBIC |", "|---|---|---|---|---|---|---|---|"]
        for e in result.effects:
            ev = e["evidence"]
            for p, v in e["parameters"].items():
                lines.append(
                    f"| `{e['name']}` | {p} | {_fmt(v)} | {_fmt(e['standard_errors'][p], 2)} | {e['units'][p]} | "
                    f"{_fmt(ev.get('likelihood_ratio'))} | {_fmt(ev.get('p_value'), 2)} | {_fmt(ev.get('delta_bic'))} |"
                )
        lines.append("")
        for e in result.effects:
            ev = e["evidence"]
            lines.append(f"- `{e['name']}`: {e['description']}.")
            if ev.get("runner_up"):
                lines.append(
                    f"  Runner-up in its round: `{ev['runner_up']['name']}` "
                    f"(BIC worse by {_fmt(ev['runner_up']['delta_bic_vs_accepted'])})."
                )
            if "note" in ev:
                lines.append(f"  Note: {ev['note']}.")
        lines.append("")
    imu = result.data.kind == "imu"
    primary = "IMU (yaw_rate, ay)" if imu else "camera"
    if result.partial_effects:
        lines += ["## Partial explanations (not the answer)", ""]
        for e in result.partial_effects:
            params = ", ".join(f"{k} = {_fmt(v)} {e['units'][k]}" for k, v in e["parameters"].items())
            lines.append(f"- `{e['name']}` ({params}) was significant but leaves a structured residual.")
        lines.append("")
        if imu:
            lines += _partial_table(result)
    lines += ["## Gap before and after", ""]
    lines += ["| channel | RMS before | RMS after | band RMS before | band RMS after | band ratio |", "|---|---|---|---|---|---|"]
    gb, ga = result.gap_before, result.gap_after
    ratios = result.gap_ratios()
    for ch in gb.rms:
        unit = doc["gap_before"]["units"][ch]
        lines.append(
            f"| {ch} [{unit}] | {_fmt(gb.rms[ch])} | {_fmt(ga.rms[ch])} | {_fmt(gb.band_rms[ch])} | "
            f"{_fmt(ga.band_rms[ch])} | {_fmt(ratios['band'][ch], 3)} |"
        )
    other = "camera" if "camera" in ratios["normalised_band"] else None
    lines += [
        "",
        f"Gap ratio (noise-normalised band RMS, all channels): **{_fmt(result.gap_ratio, 3)}**"
        + (f"; camera channels only: {_fmt(ratios['normalised_band'][other], 3)}." if other else "."),
        "",
        "![residuals](residuals.png)",
        "",
        "## Where and when they disagree",
        "",
    ]
    flagged = [w for w in result.windows_before if w["flagged"]]
    lines.append(
        f"{len(flagged)} of {len(result.windows_before)} windows exceed the 99 % noise limit with the nominal model"
        + (f"; {sum(w['flagged'] for w in result.windows_after)} with the accepted effects." if result.verdict == "found" else ".")
    )
    if flagged:
        worst = sorted(flagged, key=lambda w: -w["mean_square"])[:5]
        lines.append("Worst windows: " + ", ".join(f"{w['t_start']:.1f}-{w['t_end']:.1f} s ({w['mean_square']:.3g})" for w in worst) + ".")
    lines += ["", f"| regime | bin | {primary} mean square before | after |", "|---|---|---|---|"]
    for name, reg in result.regimes_before.items():
        after = result.regimes_after.get(name, {}).get("bins", [])
        for k, b in enumerate(reg["bins"]):
            a = after[k]["mean_square"] if k < len(after) else None
            lines.append(f"| {name} [{reg['unit']}] | {_fmt(b['low'], 3)} - {_fmt(b['high'], 3)} | {_fmt(b['mean_square'], 3)} | {_fmt(a, 3)} |")
    wb, wa = result.whiteness_before, result.whiteness_after
    lines += [
        "",
        f"Whiteness of the {primary} residual (portmanteau over {doc['config']['whiteness_lags']:g} s of lags, Monte Carlo null): "
        f"before p = {_fmt(wb.p_value, 2)} (statistic {_fmt(wb.statistic)}, null mean {_fmt(wb.null_mean)}); "
        f"after p = {_fmt(wa.p_value, 2)}.",
        "",
        "Largest cross-correlations of the nominal residual with the inputs:",
        "",
    ]
    cc = sorted(result.cross_correlation_before.items(), key=lambda kv: -abs(kv[1]["correlation"]))[:6]
    for key, v in cc:
        lines.append(f"- {key}: {v['correlation']:+.3f} at lag {v['lag_s']:+.2f} s (white band +/- {v['white_band']:.3f})")
    if imu:
        lines += _imu_regime_lines(result)
    lines += ["", "![disagreement](disagreement.png)", "", "![whiteness](whiteness.png)", "", "## Candidates", ""]
    lines += ["| round | candidate | score | fitted | chi2 reduction (LR) | p-value | dBIC | parameters |", "|---|---|---|---|---|---|---|---|"]
    for st in result.selection.steps:
        for name, info in sorted(st.tried.items(), key=lambda kv: -kv[1].get("lr", kv[1]["score"])):
            params = ", ".join(f"{k}={_fmt(v)}" for k, v in info.get("parameters", {}).items())
            mark = " (accepted)" if name == st.accepted else ""
            lines.append(
                f"| {st.round} | `{name}`{mark} | {_fmt(info['score'])} | {'yes' if info.get('fitted') else 'no'} | "
                f"{_fmt(info.get('lr'))} | {_fmt(info.get('p_value'), 2)} | {_fmt(info.get('delta_bic'))} | {params} |"
            )
    lines += ["", "![candidates](candidates.png)", ""]
    if "force_slip_loop.png" in doc.get("figures", []):
        lines += ["## Tire lag", "", "![force-slip loop](force_slip_loop.png)", ""]
    lines += [
        "## Method",
        "",
        doc["comparison"]["description"],
        "",
        "Selection: " + doc["selection"]["criterion"],
        "",
        "Verdict rules: " + doc["verdict_rules"],
        "",
    ]
    if imu:
        lines += ["## What an IMU-only log cannot tell apart", ""]
        for item in doc.get("identifiability", []):
            lines.append(f"- {', '.join(f'`{n}`' for n in item['effects'])}: {item['why']}.")
        lines.append("")
    if result.notes or doc["log"]["notes"]:
        lines += ["## Notes", ""] + [f"- {n}" for n in doc["log"]["notes"] + result.notes] + [""]
    return "\n".join(lines)


def _partial_table(result: DiscrepancyResult) -> list[str]:
    """Evidence of the partial effects and the gap they close (IMU logs)."""
    lines = [
        "| effect | LR (raw) | variance inflation | LR used | p-value | dBIC | closest other signature |",
        "|---|---|---|---|---|---|---|",
    ]
    for e in result.partial_effects:
        ev = e["evidence"]
        corr = ev.get("signature_correlation", {})
        close = max(corr, key=corr.get) if corr else None
        lines.append(
            f"| `{e['name']}` | {_fmt(ev.get('likelihood_ratio_raw'))} | {_fmt(ev.get('inflation'), 3)} | "
            f"{_fmt(ev.get('likelihood_ratio'))} | {_fmt(ev.get('p_value'), 2)} | {_fmt(ev.get('delta_bic'))} | "
            + (f"`{close}` ({corr[close]:.3f})" if close else "-")
            + " |"
        )
    if result.gap_after_partial is not None:
        gb, gp = result.gap_before, result.gap_after_partial
        lines += ["", "Gap with the partial effects added:", "", "| channel | band RMS before | band RMS with partial effects | ratio |", "|---|---|---|---|"]
        for ch in gb.band_rms:
            ratio = gb.band_rms[ch] / gp.band_rms[ch] if gp.band_rms[ch] > 0 else math.inf
            lines.append(f"| {ch} | {_fmt(gb.band_rms[ch])} | {_fmt(gp.band_rms[ch])} | {_fmt(ratio, 3)} |")
        allr = gb.normalised_band_rms["all"] / gp.normalised_band_rms["all"]
        lines += ["", f"Normalised band ratio, all channels: {_fmt(allr, 3)}."]
    lines.append("")
    return lines


def _imu_regime_lines(result: DiscrepancyResult) -> list[str]:
    """Signed mean residual by measured a_y (left / right turns) and a_x (braking / traction)."""
    lines = ["", "Signed mean residual (measured - model) by regime, nominal model (and final model when an effect was found):", ""]
    lines += ["| regime | bin | yaw_rate mean [rad/s] | ay mean [m/s^2] | after: yaw_rate | after: ay |", "|---|---|---|---|---|---|"]
    for name in ("ay", "ax", "speed"):
        reg = result.regimes_before.get(name)
        if not reg:
            continue
        after = result.regimes_after.get(name, {}).get("bins", [])
        for k, b in enumerate(reg["bins"]):
            mb = b.get("mean_residual", {})
            ma = after[k].get("mean_residual", {}) if k < len(after) and result.verdict == "found" else {}
            lines.append(
                f"| {name} [{reg['unit']}] | {_fmt(b['low'], 3)} - {_fmt(b['high'], 3)} | {_fmt(mb.get('yaw_rate'), 3)} | "
                f"{_fmt(mb.get('ay'), 3)} | {_fmt(ma.get('yaw_rate'), 3)} | {_fmt(ma.get('ay'), 3)} |"
            )
    tb = result.turn_braking_before
    if tb:
        lines += ["", "Mean band-limited residual by turn direction and longitudinal phase (nominal model; "
                  f"turns |a_y| > {tb['thresholds_mps2']['turn_ay']:g} m/s^2, braking / traction |a_x| > "
                  f"{tb['thresholds_mps2']['brake_ax']:g} m/s^2):", ""]
        lines += ["| phase / turn | samples | yaw_rate [rad/s] | ay [m/s^2] |", "|---|---|---|---|"]
        for cell, v in tb["cells"].items():
            lines.append(f"| {cell} | {v['n']} | {_fmt(v.get('yaw_rate'), 3)} | {_fmt(v.get('ay'), 3)} |")
        lines += ["", "| phase | odd in turn direction (left - right)/2: yaw_rate, ay | even (left + right)/2: yaw_rate, ay |",
                  "|---|---|---|"]
        for ph in tb["odd"]:
            o, e = tb["odd"][ph], tb["even"][ph]
            lines.append(f"| {ph} | {_fmt(o.get('yaw_rate'), 3)}, {_fmt(o.get('ay'), 3)} | "
                         f"{_fmt(e.get('yaw_rate'), 3)}, {_fmt(e.get('ay'), 3)} |")
    lines += ["", "![residual by regime](regime_residuals.png)", "", "![worst window](worst_window.png)", ""]
    return lines
