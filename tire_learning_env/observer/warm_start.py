"""Least-squares warm start of the weights (SPEC §4, eq. 28) and the learned tire curve (eq. 29).

1. Run the observer, store ``Gamma Phi(sigma_hat)`` and ``f_hat`` per sample.
2. Set ``f_hat = 0`` where ``|alpha_hat| < threshold`` (the linear region; 0.5 deg).
3. ``w0 = (X^T X + rho I)^-1 X^T y`` with rows ``Gamma Phi^k`` and ``y = f_hat^k`` (eq. 28).
4. Restart the observer from ``w0``.

Step 2 assumes the nominal cornering stiffness is right (then the nonlinear part is
zero near zero slip). When the stiffness is unknown (Study 2) the learned part must
carry the stiffness error right down to zero slip: pass ``linear_region=0`` there.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from .basis import SoftClipBasis
from .trace import EstimateTrace as ObserverTrace

__all__ = ["least_squares_weights", "regressors"]


def regressors(basis: SoftClipBasis, slip: NDArray, axle: int) -> NDArray:
    """Rows ``gamma_i sigma_i(alpha^k)`` of the axle's block of ``Gamma Phi``, shape (n, N)."""
    return basis.scale[axle] * basis.activations(slip, axle)


def least_squares_weights(
    basis: SoftClipBasis,
    trace: ObserverTrace,
    linear_region: float = math.radians(0.5),
    rho: float | None = None,
    burn_in: float = 2.0,
    prior: NDArray | None = None,
) -> NDArray:
    """Regularised least-squares weights from an observer run (eq. 28).

    Parameters
    ----------
    basis : SoftClipBasis
        The observer's basis.
    trace : ObserverTrace
        Estimated slip ``alpha_hat`` and nonlinear force ``f_hat`` of a first run.
    linear_region : float
        ``|alpha_hat|`` below which ``f_hat`` is set to zero [rad] (SPEC §4 step 2); 0 disables.
    rho : float, optional
        Ridge regularisation [N^2]; default ``1e-4`` times the mean diagonal of ``X^T X``
        (keeps rarely excited segments near the nominal curve, negligible where the
        driving excites the tire).
    burn_in : float
        Samples before this time [s] (observer transient) are left out.
    prior : ndarray (2N, 2N), optional
        Prior correlation of the weights: the ridge becomes ``rho prior^-1`` (Tikhonov),
        ``rho I`` of eq. (28) when omitted.

    Returns
    -------
    ndarray, shape (2N,)
        ``w0``, clipped to the weight box ``[W_lo, W_hi]``.
    """
    keep = trace.t >= trace.t[0] + burn_in
    w0 = []
    N = basis.n_per_axle
    for axle in (0, 1):
        a = trace.slip[keep, axle]
        y = trace.force_nonlinear[keep, axle].copy()
        y[np.abs(a) < linear_region] = 0.0
        X = regressors(basis, a, axle)
        XtX = X.T @ X
        reg = 1e-4 * float(np.mean(np.diag(XtX))) if rho is None else float(rho)
        tik = np.eye(N) if prior is None else np.linalg.inv(prior[axle * N : (axle + 1) * N, axle * N : (axle + 1) * N])
        w0.append(np.linalg.solve(XtX + reg * tik, X.T @ y))
    return np.clip(np.concatenate(w0), basis.weight_lower.ravel(), basis.weight_upper.ravel())
