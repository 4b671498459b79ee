"""Figures (PNG) of the studies, like the paper's Figs. 3-18. Every plot a notebook shows comes from here.

Each function takes plain arrays (or a :class:`~tire_learning_env.simulation.SimulationLog`
and an estimate), draws on a new figure, saves it atomically if ``path`` is given, and
returns the figure.
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path
from typing import Callable, Sequence

import matplotlib

if os.environ.get("MPLBACKEND") is None and not os.environ.get("DISPLAY"):
    matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

from .io.writers import umask_mode  # noqa: E402

__all__ = [
    "save_figure",
    "plot_path_and_steering",
    "plot_states",
    "plot_slip_angles",
    "plot_nonlinear_force",
    "plot_weights",
    "plot_tire_curves",
    "plot_force_slip_loop",
    "plot_tire_models",
]

_DEG = 180.0 / math.pi
_STATE_LABELS = (r"$e_1$ [m]", r"$\dot e_1$ [m/s]", r"$e_2$ [deg]", r"$\dot e_2$ [deg/s]")
_STATE_SCALE = (1.0, 1.0, _DEG, _DEG)


def save_figure(fig, path: str | Path | None, dpi: int = 110):
    """Save ``fig`` as PNG atomically (temp file + rename) and return it."""
    if path is not None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=".png")
        os.close(fd)
        try:
            fig.savefig(tmp, dpi=dpi, bbox_inches="tight")
            os.chmod(tmp, umask_mode())
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        plt.close(fig)
    return fig


def plot_path_and_steering(geometry: dict, t: NDArray, delta: NDArray, title: str = "", path=None):
    """Desired path (x, y) and the steering input (paper Fig. 3 / 9 / 15)."""
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 3.6))
    a1.plot(geometry["x"], geometry["y"], "k-")
    a1.set_xlabel("X [m]")
    a1.set_ylabel("Y [m]")
    a1.set_title("desired path")
    a1.axis("equal")
    a2.plot(t, np.asarray(delta) * _DEG, "b-")
    a2.set_xlabel("time [s]")
    a2.set_ylabel(r"$\delta$ [deg]")
    a2.set_title("steering input")
    fig.suptitle(title)
    return save_figure(fig, path)


def _true_vs_estimated(t, true, estimated, ylabels, scales, layout, figsize, title, path):
    """Each column of ``true`` (black) and ``estimated`` (red dashed) against ``t``, times its
    scale, one subplot each in a ``layout`` (rows, columns) grid sharing the time axis."""
    fig, axes = plt.subplots(*layout, figsize=figsize, sharex=True)
    for i, ax in enumerate(axes.flat):
        ax.plot(t, true[:, i] * scales[i], "k-", lw=1.4, label="true")
        ax.plot(t, estimated[:, i] * scales[i], "r--", lw=1.0, label="estimated")
        ax.set_ylabel(ylabels[i])
        ax.grid(alpha=0.3)
    axes.flat[0].legend()
    for ax in np.reshape(axes, layout)[-1]:
        ax.set_xlabel("time [s]")
    fig.suptitle(title)
    return save_figure(fig, path)


def plot_states(t: NDArray, true: NDArray, estimated: NDArray, title: str = "", path=None):
    """The four error states, true vs estimated (paper Fig. 4 / 10 / 16)."""
    return _true_vs_estimated(t, true, estimated, _STATE_LABELS, _STATE_SCALE, (2, 2), (11, 6), title, path)


def plot_slip_angles(t: NDArray, true: NDArray, estimated: NDArray, title: str = "", path=None):
    """Front and rear slip angles, true vs estimated (paper Fig. 5 / 11 / 17)."""
    labels = tuple(rf"$\alpha_{name[0]}$ [deg]" for name in ("front", "rear"))
    return _true_vs_estimated(t, true, estimated, labels, (_DEG, _DEG), (2, 1), (10, 5.5), title, path)


def plot_nonlinear_force(t: NDArray, true: NDArray, estimated: NDArray, title: str = "", path=None):
    """Nonlinear part of the axle forces, true vs estimated (paper Fig. 6 / 12 / 18)."""
    labels = tuple(rf"$f_{{y{name[0]}}}$ [N]" for name in ("front", "rear"))
    return _true_vs_estimated(t, true, estimated, labels, (1.0, 1.0), (2, 1), (10, 5.5), title, path)


def plot_weights(t: NDArray, weights: NDArray, n_per_axle: int, title: str = "", path=None):
    """Weight trajectories per axle (paper Fig. 7 / 13)."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8), sharex=True)
    for i, (ax, name) in enumerate(zip(axes, ("front", "rear"))):
        block = weights[:, i * n_per_axle : (i + 1) * n_per_axle]
        for j in range(n_per_axle):
            ax.plot(t, block[:, j], lw=1.0, label=f"$W_{{{i + 1}{j + 1}}}$")
        ax.set_title(f"{name} axle weights")
        ax.set_xlabel("time [s]")
        ax.grid(alpha=0.3)
    axes[1].legend(fontsize=7, ncol=2, loc="best")
    fig.suptitle(title)
    return save_figure(fig, path)


def plot_tire_curves(
    curves: dict[str, Callable[[NDArray, str], NDArray]],
    true_curve: Callable[[NDArray, str], NDArray] | None,
    excited: dict[str, Sequence[float]],
    samples: dict[str, tuple[NDArray, NDArray]] | None = None,
    span_deg: float | None = None,
    title: str = "",
    path=None,
    bands: dict[str, Callable[[NDArray, str], NDArray]] | None = None,
):
    """Axle force vs slip: learned curves against the truth, excited range marked (paper Fig. 8 / 14).

    Parameters
    ----------
    curves : dict label -> ``(alpha, axle) -> force``
    true_curve : truth ``(alpha, axle) -> force`` or None
    excited : axle -> ``[lo_deg, hi_deg]`` (drawn as a dotted box)
    samples : axle -> ``(slip, force)`` scatter (e.g. true samples or a measured cloud)
    span_deg : half-width of the plotted slip range [deg] (default: 1.6 x the excited range)
    bands : dict label -> ``(alpha, axle) -> std`` [N]
        A +/- 2 sigma band is shaded around the curve of the same label.
    """
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, axle in zip(axes, ("front", "rear")):
        lo, hi = excited[axle]
        span = span_deg if span_deg is not None else 1.6 * max(abs(lo), abs(hi), 0.2)
        grid = np.radians(np.linspace(-span, span, 401))
        if samples and axle in samples:
            s_slip, s_force = samples[axle]
            step = max(1, len(s_slip) // 4000)
            ax.plot(np.asarray(s_slip)[::step] * _DEG, np.asarray(s_force)[::step], ".", ms=1.5, color="0.6", label="samples")
        if true_curve is not None:
            ax.plot(grid * _DEG, true_curve(grid, axle), "k-", lw=1.6, label="true")
        for (label, fn), style in zip(curves.items(), ("r--", "b-.", "g:", "m--", "c-.", "y:")):
            f = fn(grid, axle)
            ax.plot(grid * _DEG, f, style, lw=1.3, label=label)
            if bands and label in bands:
                # the band on every 4th point, drawn through the rest: a band is a long-run variance per
                # direction, smooth in slip; where the scores stay correlated beyond the lags ScoreLongRun
                # computes directly (a noise-free 1 kHz camera) each direction is an FFT of the log's scores
                coarse = grid[::4]
                sd = np.interp(grid, coarse, bands[label](coarse, axle))
                ax.fill_between(grid * _DEG, f - 2 * sd, f + 2 * sd, color=style[0], alpha=0.2, lw=0,
                                label=f"{label} +/-2 sigma")
        ylo, yhi = ax.get_ylim()
        ax.add_patch(plt.Rectangle((lo, ylo), hi - lo, yhi - ylo, fill=False, ls=":", ec="b", lw=1.2))
        ax.set_xlabel(r"slip angle [deg]")
        ax.set_ylabel(f"{axle} axle lateral force [N]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(title)
    return save_figure(fig, path)


def plot_force_slip_loop(slip: NDArray, force: NDArray, steady: Callable[[NDArray], NDArray] | None = None,
                         title: str = "", path=None):
    """Axle force against slip over time: hysteresis from tire lag (paper Fig. 2)."""
    fig, ax = plt.subplots(figsize=(6, 4.5))
    ax.plot(np.asarray(slip) * _DEG, force, "r-", lw=0.8, label="generated")
    if steady is not None:
        grid = np.linspace(np.min(slip), np.max(slip), 200)
        ax.plot(grid * _DEG, steady(grid), "k--", lw=1.2, label="steady-state tire model")
    return _finish_force_slip(fig, ax, "lateral force [N]", title, path)


def plot_tire_models(models: dict[str, Callable[[NDArray], NDArray]], span_deg: float = 12.0, title: str = "", path=None):
    """Force-slip curves of several tire models (notebook 1)."""
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    grid = np.radians(np.linspace(-span_deg, span_deg, 481))
    for label, fn in models.items():
        ax.plot(grid * _DEG, fn(grid), lw=1.4, label=label)
    return _finish_force_slip(fig, ax, "axle lateral force [N]", title, path)


def _finish_force_slip(fig, ax, ylabel: str, title: str, path):
    """Labels (slip angle [deg] against ``ylabel``), grid, legend and title of a one-axes force-slip figure; saved."""
    ax.set_xlabel("slip angle [deg]")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title(title)
    return save_figure(fig, path)
