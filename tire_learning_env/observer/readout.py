"""Linear read-outs of the learned curves: the axle force ``F(alpha) = 2 C alpha + g(alpha)^T w`` and
the per-tire cornering stiffness ``C_nominal + g^T w`` as functionals ``g`` of the weights
(re-exported by :mod:`.offline`)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:  # annotations only: the observer's block law reads the stiffness through this module
    from .neuro_adaptive import NeuroAdaptiveObserver

__all__ = ["stiffness_gradient", "curve_gradient", "stiffness_readout", "weights_at_bound"]


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


def weights_at_bound(observer: NeuroAdaptiveObserver, w: NDArray, functionals: NDArray, tolerance: float = 0.05,
                     min_share: float = 0.2) -> list[dict]:  # fmt: skip
    """Per axle: whether the learned curve is capped by the weight box.

    The basis scales every weight by the vehicle file's stiffness (``gamma_i = 2 C_i``,
    :func:`.basis.two_sided_basis`) and bounds it, so the learned slope stays within a fixed
    multiple of the file's: a file far from the truth caps the curve, and the fit reports the
    cap (or a curve bent around it) as the answer with a band that does not reach the truth
    (a file at 0.6 x the truth's stiffness: -4.1 % with a 2-sigma band of +/-1.3 %). A weight
    is at its bound when it lies within ``tolerance`` of the box width ``W_hi - W_lo`` of
    ``W_hi`` or ``W_lo``. The curve is capped when

    - a weight the stiffness read-out leans on (``|g_j| >= min_share max_j |g_j|`` on that
      axle) is at either bound, or
    - any slip-segment weight is at its upper bound: a slope above ``1 + W_hi`` times the
      file's anywhere (a file at 0.5 x: the read-out's own weights at 0.85 of the bound, the
      segments beside them at 0.97, the stiffness -24 %). The lower bound away from the
      read-out is not counted: past the peak of the curve the slope is rightly below
      ``1 + W_lo`` times the file's.

    Parameters
    ----------
    observer : NeuroAdaptiveObserver
        Holds the basis (its weight box).
    w : ndarray (nw,)
        The fitted weights.
    functionals : ndarray (2, nw)
        The stiffness read-out ``g`` per axle (:func:`stiffness_readout`).
    tolerance : float
        Distance to a bound, as a fraction of the box width, that counts as at the bound.
    min_share : float
        Share of the largest ``|g_j|`` of the axle above which weight ``j`` counts as one the
        read-out leans on.

    Returns
    -------
    list of dict
        Front, rear: ``at_bound`` (bool), ``read_out_weights`` and ``upper_weights`` (indices
        into the axle's basis members at a bound, by the two rules above) and
        ``largest_fraction`` (of the bound reached, ``w / W_hi`` or ``w / W_lo``, over the
        slip-segment weights).
    """
    b = observer.basis
    N = b.n_per_axle
    w = np.asarray(w, dtype=float)
    g = np.asarray(functionals, dtype=float)
    out = []
    for i in (0, 1):
        wi = w[i * N : (i + 1) * N]
        gi = np.abs(g[i, i * N : (i + 1) * N])
        lo, hi = b.weight_lower[i], b.weight_upper[i]
        width = hi - lo
        segment = (b.lower[i] != b.upper[i]) & (width > 0)
        leans = segment & (gi >= min_share * gi.max()) if gi.max() > 0 else np.zeros(N, dtype=bool)
        at_hi = segment & (wi >= hi - tolerance * width)
        at_lo = segment & (wi <= lo + tolerance * width)
        read_out = leans & (at_hi | at_lo)
        frac = np.where(wi >= 0, wi / np.where(hi > 0, hi, np.inf), wi / np.where(lo < 0, lo, -np.inf))
        out.append({
            "at_bound": bool(read_out.any() or at_hi.any()),
            "read_out_weights": [int(j) for j in np.flatnonzero(read_out)],
            "upper_weights": [int(j) for j in np.flatnonzero(at_hi)],
            "largest_fraction": float(frac[segment].max()) if segment.any() else 0.0,
        })  # fmt: skip
    return out
