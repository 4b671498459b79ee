"""Linear read-outs of the learned curves: the axle force ``F(alpha) = 2 C alpha + g(alpha)^T w`` and
the per-tire cornering stiffness ``C_nominal + g^T w`` as functionals ``g`` of the weights
(re-exported by :mod:`.offline`)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .neuro_adaptive import NeuroAdaptiveObserver

__all__ = ["stiffness_gradient", "curve_gradient", "stiffness_readout"]


def stiffness_gradient(observer: NeuroAdaptiveObserver, axle: int) -> NDArray:
    """``g`` with per-tire stiffness ``= C_nominal + g^T w`` (half the slope at zero slip)."""
    b = observer.basis
    N = b.n_per_axle
    g = np.zeros(observer.n_weights)
    g[axle * N : (axle + 1) * N] = 0.5 * b.scale[axle] * b.slopes(0.0, axle)
    return g


def curve_gradient(observer: NeuroAdaptiveObserver, alpha: ArrayLike, axle: int) -> NDArray:
    """Rows ``g(alpha)`` with axle force ``F(alpha) = 2 C alpha + g(alpha)^T w`` [N], shape (n, nw)."""
    b = observer.basis
    N = b.n_per_axle
    a = np.atleast_1d(np.asarray(alpha, dtype=float))
    G = np.zeros((len(a), observer.n_weights))
    G[:, axle * N : (axle + 1) * N] = b.scale[axle] * b.activations(a, axle)
    return G


def stiffness_readout(observer: NeuroAdaptiveObserver, w: NDArray, slip: NDArray, axle: int, cap_deg: float = 2.0,
                      max_drop: float = 0.08, min_deg: float = 0.25, degree: int = 5) -> tuple[NDArray, dict]:  # fmt: skip
    """Linear functional ``g`` of the weights that reads the per-tire cornering stiffness from
    the whole linear range of the learned curve (``C_nominal + g^T w``).

    A polynomial of ``degree`` is fitted (least squares, weighted by where the drive put its
    slip) to the learned axle curve over the slip the drive covered, clipped to the range in
    which the curve's secant slope has dropped by at most ``max_drop``; its slope at zero,
    halved, is the stiffness. A quintic over that range reads an exact Magic-Formula curve
    to within a few hundredths of a percent, and it uses every sample in the range, where
    the slope at zero alone rests on the narrow innermost basis segment.
    """
    if getattr(observer, "pinned_slip", 0.0) > 0:  # stiffness given: the curve is pinned to it near zero
        return stiffness_gradient(observer, axle), {"range_deg": None, "method": "slope at zero (stiffness given, pinned)"}
    a = slip[np.isfinite(slip)]
    if len(a) < 10:
        return stiffness_gradient(observer, axle), {"range_deg": None, "method": "slope at zero (no slip data)"}
    lo_d, hi_d = np.percentile(a, [0.5, 99.5])
    cap = math.radians(cap_deg)
    c2 = 2.0 * (observer.vehicle.Cf if axle == 0 else observer.vehicle.Cr)
    hist_edges = np.linspace(min(lo_d, 0.0), max(hi_d, 0.0), 41)
    counts, _ = np.histogram(a, hist_edges)
    while True:
        r_lo, r_hi = max(min(lo_d, 0.0), -cap), min(max(hi_d, 0.0), cap)
        grid = np.linspace(r_lo, r_hi, 121)
        dens = np.interp(grid, 0.5 * (hist_edges[1:] + hist_edges[:-1]), counts.astype(float))
        wt = dens / max(dens.max(), 1.0) + 0.02
        X = np.vander(grid, degree + 1, increasing=True)
        Xw = X * wt[:, None]
        try:
            Pinv = np.linalg.solve(X.T @ Xw, Xw.T)  # (deg+1, n): weighted least-squares map
        except np.linalg.LinAlgError:  # a slip range too narrow for the polynomial (a short, quiet drive)
            return stiffness_gradient(observer, axle), {"range_deg": [math.degrees(r_lo), math.degrees(r_hi)],
                                                        "method": "slope at zero (slip range too narrow for a polynomial)"}  # fmt: skip
        G = curve_gradient(observer, grid, axle)
        g_axle = Pinv[1] @ G  # slope at zero = 2C + g_axle^T w
        k = c2 + float(g_axle @ w)
        # a range end next to zero (a drive that turned one way) says nothing of the curve's drop, and the
        # force there is mostly the curve's offset: only ends beyond a quarter of the range are tested
        ends = [e for e in (r_lo, r_hi) if abs(e) > max(1e-6, 0.25 * max(abs(r_lo), abs(r_hi)))]
        F = observer.axle_force(np.array(ends), axle, weights=w) if ends else np.zeros(0)
        drop = max([1.0 - f / (k * e) for f, e in zip(F, ends)], default=0.0)
        if drop <= max_drop or cap <= math.radians(min_deg):
            break
        cap *= 0.85
    info = {"range_deg": [math.degrees(r_lo), math.degrees(r_hi)], "secant_drop_at_range_end": float(drop),
            "method": f"weighted degree-{degree} polynomial fit of the learned curve over the range"}  # fmt: skip
    return 0.5 * g_axle, info
