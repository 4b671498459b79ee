"""Figures of the discrepancy report (PNG), in the style of :mod:`tire_learning_env.plotting`.

Each function takes a :class:`~.result.DiscrepancyResult` (or plain arrays), draws a new
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
    "plot_regime_residuals",
    "plot_worst_window",
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
    primary = "IMU" if result.data.kind == "imu" else "camera"
    ax.set_yscale("log")
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"{primary} normalised mean square per window")
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
    ax.set_xlabel(f"{primary} normalised mean square (1 = noise)")
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
    n = int((d.meas_chan == d.primary[0]).sum())
    ax.axhspan(-2 / math.sqrt(n), 2 / math.sqrt(n), color="0.85", label="white +/- 2/sqrt(n)")
    ax.set_xlabel("lag [s]")
    ax.set_ylabel("autocorrelation")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("residual whiteness (" + ("IMU" if d.kind == "imu" else "camera") + ")")
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


def _with_effects(result):
    """The evaluation with the accepted effects (found or partial) and its label, or None."""
    sel = result.selection
    if not sel.accepted:
        return None, None
    names = ", ".join(e.name for e, _, _ in sel.accepted)
    label = f"with {names}" + ("" if result.verdict == "found" else " (partial)")
    return sel.final, label


def _binned_mean(x, y, edges):
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
    mean = np.full(len(edges) - 1, np.nan)
    err = np.full(len(edges) - 1, np.nan)
    for k in range(len(edges) - 1):
        sel = idx == k
        if sel.sum() >= 20:
            mean[k] = float(np.mean(y[sel]))
            # standard error with ~0.5 s of correlated samples (band-limited residual)
            err[k] = float(np.std(y[sel]) / math.sqrt(max(sel.sum() / 50.0, 1.0)))
    return mean, err


def plot_regime_residuals(result, path=None):
    """IMU logs: mean band-limited residual (measured - model) of yaw rate and a_y.

    Left column: against the measured a_y (left / right turns), nominal model and with the
    accepted effects. Right column: against the a_x input (braking / traction), nominal
    model, separately in left turns, right turns and on straights (the thresholds of
    :func:`.diagnostics.turn_and_braking`): a residual of the same sign in left and right
    turns is even in a_y.
    """
    from ..metrics import centred_moving_average
    from .diagnostics import TURN_AY

    d = result.data
    ay_meas = np.full(len(d.t), np.nan)
    m_ay = d.meas_chan == CHANNELS.index("ay")
    ay_meas[d.meas_row[m_ay]] = d.meas_val[m_ay]
    fin = np.isfinite(ay_meas)
    ay_s = np.full(len(d.t), np.nan)
    ay_s[fin] = centred_moving_average(d.t[fin], ay_meas[fin], 0.5)
    series = [("nominal", result.nominal, "tab:red")]
    ev, label = _with_effects(result)
    if ev is not None:
        series.append((label, ev, "tab:blue"))
    smooth_nominal, _ = band_residual(d, result.nominal.resid)
    fig, axes = plt.subplots(2, 2, figsize=(12, 7.5), squeeze=False)
    edges_ay = np.linspace(-16, 16, 33)
    edges_ax = np.linspace(-10, 6, 17)
    for row, name in enumerate(("yaw_rate", "ay")):
        ch = CHANNELS.index(name)
        m = d.meas_chan == ch
        rows = d.meas_row[m]
        scale, unit = _SCALE[name]
        ax = axes[row, 0]
        x = ay_meas[rows]
        ok = np.isfinite(x)
        mid = 0.5 * (edges_ay[1:] + edges_ay[:-1])
        for lab, e, colour in series:
            smooth, _ = band_residual(d, e.resid)
            mean, err = _binned_mean(x[ok], (smooth[m] * d.sigma[ch] * scale)[ok], edges_ay)
            ax.errorbar(mid, mean, yerr=err, fmt="o-", ms=3, lw=1.0, color=colour, label=lab, capsize=2)
        ax.set_xlabel("measured a_y [m/s^2]")
        ax = axes[row, 1]
        y = smooth_nominal[m] * d.sigma[ch] * scale
        a, xa = ay_s[rows], d.ax[rows]
        mid = 0.5 * (edges_ax[1:] + edges_ax[:-1])
        for lab, sel, colour in (
            (f"left turns (a_y > {TURN_AY:g})", a > TURN_AY, "tab:green"),
            ("straight", np.abs(a) <= TURN_AY, "0.4"),
            (f"right turns (a_y < -{TURN_AY:g})", a < -TURN_AY, "tab:purple"),
        ):
            sel = sel & np.isfinite(a)
            mean, err = _binned_mean(xa[sel], y[sel], edges_ax)
            ax.errorbar(mid, mean, yerr=err, fmt="o-", ms=3, lw=1.0, color=colour, label=lab, capsize=2)
        ax.set_xlabel("a_x input [m/s^2] (nominal model)")
        for ax in axes[row]:
            ax.axhline(0.0, color="k", lw=0.6)
            ax.set_ylabel(f"{name} residual [{unit}]")
            ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    axes[0, 1].legend(fontsize=8)
    fig.suptitle("mean band-limited residual (measured - model) by regime; bars: standard error (0.5 s correlation)")
    fig.tight_layout()
    return save_figure(fig, path)


def plot_worst_window(result, path=None):
    """IMU logs: the window where the nominal model disagrees most: measured and model yaw
    rate and a_y (nominal and with the accepted effects), speed, steering and a_x."""
    d = result.data
    wins = result.windows_before
    w = int(np.argmax([x["mean_square"] for x in wins]))
    j0, j1 = int(d.win_meas[w]), int(d.win_end[w])
    rows = np.arange(j0, j1 + 1)
    t = d.t[rows]
    trajs = [("nominal", result.trajectories_before, "tab:red")]
    ev, label = _with_effects(result)
    if ev is not None:
        trajs.append((label, result.model.trajectories(ev), "tab:blue"))
    from ._model import OUT_AY, OUT_YAW

    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    for ax, name, col in ((axes[0], "yaw_rate", OUT_YAW), (axes[1], "ay", OUT_AY)):
        ch = CHANNELS.index(name)
        m = (d.meas_chan == ch) & (d.meas_row >= j0) & (d.meas_row <= j1)
        scale, unit = _SCALE[name]
        ax.plot(d.t[d.meas_row[m]], d.meas_val[m] * scale, ".", ms=2, color="0.4", label="measured")
        for lab, tr, colour in trajs:
            ax.plot(t, tr[rows, col] * scale, "-", lw=1.2, color=colour, label=lab)
        ax.set_ylabel(f"{name} [{unit}]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    ax = axes[2]
    ax.plot(t, d.vx[rows], color="k", label="vx [m/s]")
    ax.set_ylabel("vx [m/s]")
    ax2 = ax.twinx()
    ax2.plot(t, np.degrees(d.delta[rows]) * 10, color="tab:green", label="delta x10 [deg]")
    ax2.plot(t, d.ax[rows], color="tab:purple", label="ax [m/s^2]")
    ax2.legend(fontsize=8, loc="lower right")
    ax.set_xlabel("time [s]")
    ax.grid(alpha=0.3)
    fig.suptitle(f"worst window of the nominal model: {wins[w]['t_start']:.1f}-{wins[w]['t_end']:.1f} s "
                 f"(normalised mean square {wins[w]['mean_square']:.3g})")  # fmt: skip
    return save_figure(fig, path)
