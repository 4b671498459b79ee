"""Figures of the IMU variant (saved atomically with :func:`..plotting.save_figure`)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..plotting import plt, save_figure

__all__ = ["plot_axle_comparison", "plot_sideslip"]

_DEG = 180.0 / math.pi


def _thin(*arrays, n=6000):
    step = max(1, len(arrays[0]) // n)
    return [np.asarray(a)[::step] for a in arrays]


def plot_axle_comparison(
    axle: str,
    slip_hat: NDArray,
    force_hat: NDArray,
    slip_meas: NDArray | None,
    force_meas: NDArray | None,
    learned,
    nominal,
    measured_curve=None,
    path=None,
):
    """One axle: measured cloud (reference sensor) and estimated cloud, measured and learned curves."""
    fig, ax = plt.subplots(figsize=(7.5, 5.0))
    if slip_meas is not None:
        a, f = _thin(slip_meas, force_meas)
        ax.plot(a * _DEG, f, ".", ms=1.2, color="0.65", label="measured (reference sensor)")
    a, f = _thin(slip_hat, force_hat)
    ax.plot(a * _DEG, f, ".", ms=1.2, color="tab:orange", alpha=0.5, label="observer estimate")
    if measured_curve is not None:
        lo, hi = measured_curve.ranges[axle]
        span = 1.15 * max(abs(lo), abs(hi))
    else:
        lo, hi = np.percentile(slip_hat, [0.5, 99.5])
        span = 1.15 * max(abs(lo), abs(hi))
    grid = np.linspace(-span, span, 401)
    if measured_curve is not None:
        g = np.linspace(lo, hi, 201)
        ax.plot(g * _DEG, measured_curve(g, axle), "k-", lw=2.0, label="measured curve (binned mean)")
        ax.axvspan(lo * _DEG, hi * _DEG, color="b", alpha=0.04, label="covered slip range")
    ax.plot(grid * _DEG, learned(grid, axle), "r--", lw=1.8, label="learned curve")
    ax.plot(grid * _DEG, nominal(grid, axle), "b:", lw=1.3, label="nominal linear")
    ax.set_xlabel("slip angle [deg]")
    ax.set_ylabel(f"{axle} axle lateral force [N]")
    ax.set_title(f"{axle} axle: learned vs measured")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, markerscale=6)
    return save_figure(fig, path)


def plot_sideslip(t: NDArray, beta_hat: NDArray, beta_kf: NDArray, beta_ref: NDArray | None, path=None,
                  beta_observer: NDArray | None = None):  # fmt: skip
    """Sideslip over time [deg]: the reported estimate, the linear Kalman baseline, the causal
    observer alone (optional) and the reference sensor (optional)."""
    fig, ax = plt.subplots(figsize=(12, 4.0))
    if beta_ref is not None:
        ax.plot(t, np.asarray(beta_ref) * _DEG, "k-", lw=1.2, label="reference sensor")
    ax.plot(t, np.asarray(beta_kf) * _DEG, "b-", lw=0.7, alpha=0.7, label="linear KF (baseline)")
    if beta_observer is not None:
        ax.plot(t, np.asarray(beta_observer) * _DEG, "g-", lw=0.6, alpha=0.7, label="neuro-adaptive observer (causal)")
    ax.plot(t, np.asarray(beta_hat) * _DEG, "r-", lw=0.8, label="reported (observer / KF blend)")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("sideslip [deg]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return save_figure(fig, path)
