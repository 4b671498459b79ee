"""Figures of the discrepancy report (PNG), in the style of :mod:`tire_learning_env.plotting`.

Each function takes a :class:`~.workflow.DiscrepancyResult` (or plain arrays), draws a new
figure, saves it atomically when ``path`` is given (:func:`~tire_learning_env.plotting.save_figure`)
and returns it.
"""

from __future__ import annotations

import math

import numpy as np

from ..plotting import plt, save_figure
from ._model import CHANNELS, OUT_ALPHA_F, OUT_FYF
from .diagnostics import UNITS, band_residual

__all__ = [
    "plot_residuals",
    "plot_disagreement",
    "plot_candidates",
    "plot_whiteness",
    "plot_force_slip_loop",
]

_SCALE = {
    "e1": (100.0, "cm"),
    "e2": (180.0 / math.pi, "deg"),
    "yaw_rate": (180.0 / math.pi, "deg/s"),
    "ay": (1.0, "m/s^2"),
}


def plot_residuals(result, path=None):
    """Residual per channel over time, before (nominal) and after (with the accepted effects).

    Raw residual as dots, its vehicle-dynamics band as a line; windows flagged as
    excessive before are shaded.
    """
    d = result.data
    chans = [c for c in CHANNELS if c in d.channels]
    fig, axes = plt.subplots(len(chans), 1, figsize=(11, 2.3 * len(chans) + 0.6), sharex=True, squeeze=False)
    tm = d.t[d.meas_row]
    series = [("before", result.nominal, "tab:red")]
    if result.verdict == "found":
        series.append(("after", result.final, "tab:blue"))
    for ax, name in zip(axes[:, 0], chans):
        ch = CHANNELS.index(name)
        m = d.meas_chan == ch
        scale, unit = _SCALE[name]
        sigma = d.sigma[ch]
        for label, ev, colour in series:
            smooth, _ = band_residual(d, ev.resid)
            step = max(1, int(m.sum() // 3000))
            ax.plot(tm[m][::step], ev.resid[m][::step] * sigma * scale, ".", ms=1.0, color=colour, alpha=0.25)
            ax.plot(tm[m], smooth[m] * sigma * scale, "-", lw=1.0, color=colour, label=f"{label} (band)")
        for win in result.windows_before:
            if win["flagged"]:
                ax.axvspan(win["t_start"], win["t_end"], color="0.85", zorder=0)
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_ylabel(f"{name} residual [{unit}]")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(f"residual (measured - model): verdict {result.verdict}; shaded: windows flagged before")
    return save_figure(fig, path)


def plot_disagreement(result, path=None):
    """Where and when: per-window mean square over time and by regime (1 = noise level)."""
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2), gridspec_kw={"width_ratios": [1.4, 1]})
    ax = axes[0]
    panels = (("before", result.windows_before, "tab:red"), ("after", result.windows_after, "tab:blue"))
    for label, wins, colour in panels:
        if label == "after" and result.verdict != "found":
            continue
        mids = [0.5 * (w["t_start"] + w["t_end"]) for w in wins]
        widths = [0.9 * (w["t_end"] - w["t_start"]) for w in wins]
        ax.bar(mids, [w["mean_square"] for w in wins], width=widths, color=colour, alpha=0.5, label=label)
    lim = [w["limit"] for w in result.windows_before]
    if lim:
        ax.axhline(float(np.median(lim)), color="k", ls="--", lw=1.0, label="noise limit (99 %)")
    ax.set_yscale("log")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("camera normalised mean square per window")
    ax.set_title("when: disagreement per window")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    ax = axes[1]
    names = list(result.regimes_before)
    ypos = []
    labels = []
    y = 0
    for name in names:
        for k, b in enumerate(result.regimes_before[name]["bins"]):
            ax.barh(y, b["mean_square"], color="tab:red", alpha=0.5)
            after = result.regimes_after.get(name, {}).get("bins", [])
            if result.verdict == "found" and k < len(after):
                ax.barh(y, after[k]["mean_square"], color="tab:blue", alpha=0.6, height=0.4)
            ypos.append(y)
            labels.append(f"{name} {b['low']:.3g}-{b['high']:.3g}")
            y += 1
        y += 0.6
    ax.set_yticks(ypos)
    ax.set_yticklabels(labels, fontsize=7)
    ax.axvline(1.0, color="k", ls="--", lw=1.0)
    ax.set_xscale("log")
    ax.set_xlabel("camera normalised mean square (1 = noise)")
    ax.set_title("in which regime (red before, blue after)")
    ax.grid(alpha=0.3, which="both")
    return save_figure(fig, path)


def plot_candidates(result, path=None):
    """Likelihood-ratio statistic of every candidate per selection round, with the acceptance threshold."""
    steps = result.selection.steps
    fig, axes = plt.subplots(1, len(steps), figsize=(4.2 * len(steps) + 1, 3.8), squeeze=False)
    n = result.data.n_measurements
    for ax, st in zip(axes[0], steps):
        names = list(st.tried)
        lr = [max(st.tried[k].get("lr", st.tried[k]["score"]), 1e-2) for k in names]
        fitted = [st.tried[k].get("fitted", False) for k in names]
        colours = ["tab:green" if k == st.accepted else ("tab:gray" if f else "0.8") for k, f in zip(names, fitted)]
        ax.barh(range(len(names)), lr, color=colours)
        ax.set_yticks(range(len(names)))
        ax.set_yticklabels(names, fontsize=8)
        thr = math.log(n)
        ax.axvline(thr, color="k", ls="--", lw=1.0, label="k ln n (k = 1)")
        ax.set_xscale("log")
        ax.set_xlabel("chi2 reduction (LR; light = score only)")
        ax.set_title(f"round {st.round}: accepted {st.accepted}", fontsize=9)
        ax.grid(alpha=0.3, which="both")
    axes[0, 0].legend(fontsize=8)
    return save_figure(fig, path)


def plot_whiteness(result, path=None):
    """Autocorrelation of the camera residuals before and after, with the white-noise band."""
    fig, ax = plt.subplots(figsize=(7, 4))
    d = result.data
    for label, test, style in (("before", result.whiteness_before, "-"), ("after", result.whiteness_after, "--")):
        if label == "after" and result.verdict != "found":
            continue
        for name, acf in test.acf.items():
            ch = CHANNELS.index(name)
            rows = d.meas_row[d.meas_chan == ch]
            rate = 1.0 / float(np.median(np.diff(d.t[rows])))
            lags = np.arange(1, len(acf) + 1) / rate
            ax.plot(lags, acf, style, label=f"{name} {label} (p = {test.p_value:.2g})")
    n = int((d.meas_chan == 0).sum())
    ax.axhspan(-2 / math.sqrt(n), 2 / math.sqrt(n), color="0.85", label="white +/- 2/sqrt(n)")
    ax.set_xlabel("lag [s]")
    ax.set_ylabel("autocorrelation")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("residual whiteness (camera)")
    return save_figure(fig, path)


def plot_force_slip_loop(result, path=None):
    """Front-axle force against kinematic slip: the hysteresis loop of the fitted tire lag.

    Drawn from the model with the accepted effects: every sample in grey, the most
    transient two seconds (largest steering rate) in red, and the steady-state curve of
    the nominal tire (times any fitted stiffness factor) dashed.
    """
    traj = result.trajectories_after
    d = result.data
    ok = np.isfinite(traj[:, OUT_ALPHA_F])
    slip = traj[:, OUT_ALPHA_F]
    force = traj[:, OUT_FYF]
    fig, ax = plt.subplots(figsize=(6.5, 4.8))
    idx = np.flatnonzero(ok)
    step = max(1, len(idx) // 20000)
    ax.plot(np.degrees(slip[idx[::step]]), force[idx[::step]], ".", ms=1.0, color="0.7", label="all samples")
    rate = np.abs(np.gradient(d.delta, d.t))
    rate[~ok] = 0.0
    j = int(np.argmax(rate))
    seg = np.flatnonzero(ok & (np.abs(d.t - d.t[j]) <= 1.0))
    label = f"{d.t[seg[0]]:.1f}-{d.t[seg[-1]]:.1f} s"
    ax.plot(np.degrees(slip[seg]), force[seg], "-", color="tab:red", lw=1.2, label=label)
    theta = result.final.theta
    from ._model import TH_SCALE_F

    grid = np.linspace(np.nanmin(slip[idx]), np.nanmax(slip[idx]), 200)
    ax.plot(np.degrees(grid), result.model.front_tire.lateral_force(grid) * theta[TH_SCALE_F], "k--", lw=1.0,
            label="steady-state tire")
    sigma = next((e["parameters"]["relaxation_length"] for e in result.effects if e["name"] == "tire_relaxation"), None)
    ax.set_xlabel("front kinematic slip angle [deg]")
    ax.set_ylabel("front axle lateral force [N]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(f"force vs slip loop, relaxation length {sigma:.3g} m" if sigma is not None else "force vs slip")
    return save_figure(fig, path)


def channel_unit(name: str) -> str:
    return UNITS[name]
