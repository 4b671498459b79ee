"""Compiled kernels of the joint UKF (:mod:`.ukf`): the filter state's layout, the model
(Pacejka axle curves, eq. 13 slips through the observer core's :func:`slip_angles`, RK4),
the unscented predict, the camera update and the loop over a log's rows.

Filter state (:data:`STATE_NAMES`): ``[e1, e1_dot, e2, e2_dot, ln(Cf/Cf0), ln(Cr/Cr0), ln mu_f,
ln mu_r]``; constants vector indexed by ``K_*``; inputs held between rows by ``U_*``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numba import njit

from .._jit_cache import key_on_family
from ..observer._kernel import KERNEL_FAMILY, slip_angles

STATE_NAMES = ("e1", "e1_dot", "e2", "e2_dot", "log_cf", "log_cr", "log_mu_f", "log_mu_r")
PARAM_NAMES = ("Cf", "Cr", "mu_f", "mu_r")
# filter state (STATE_NAMES): the error state (dynamics.StateIndex's order), then the log-parameters
X_E1, X_E1_DOT, X_E2, X_E2_DOT, X_LOG_CF, X_LOG_CR, X_LOG_MU_F, X_LOG_MU_R = range(8)
N_ERR = 4  # the error-state prefix
N_X = 8
N_SIGMA = 2 * N_X + 1
# constants vector
K_M, K_IZ, K_LF, K_LR, K_CF0, K_CR0, K_FZF, K_FZR, K_CS, K_E = range(10)
N_CONST = 10


@njit(cache=True)
def _axle_force(alpha, stiffness, peak, cs, e):
    """Pacejka axle force [N] with slope ``stiffness`` [N/rad] at zero slip and peak ``peak`` [N]."""
    b = stiffness / (cs * peak)
    x = b * alpha
    return peak * math.sin(cs * math.atan(x - e * (x - math.atan(x))))


@njit(cache=True)
def _forces(s, delta, vx, pdd, k):
    """Slips (eq. 13) and axle forces of filter state ``s`` -> ``(af, ar, Ff, Fr)``."""
    vy = s[X_E1_DOT] - vx * s[X_E2]  # body states from the error state (SPEC section 1)
    r = s[X_E2_DOT] + pdd
    af, ar = slip_angles(vy, r, delta, vx, k[K_LF], k[K_LR])  # eq. (13), the core's one implementation
    ff = _axle_force(af, 2.0 * k[K_CF0] * math.exp(s[X_LOG_CF]), math.exp(s[X_LOG_MU_F]) * k[K_FZF], k[K_CS], k[K_E])
    fr = _axle_force(ar, 2.0 * k[K_CR0] * math.exp(s[X_LOG_CR]), math.exp(s[X_LOG_MU_R]) * k[K_FZR], k[K_CS], k[K_E])
    return af, ar, ff, fr


@njit(cache=True)
def _rhs(s, delta, vx, ax, pdd, pddd, k, out):
    _, _, ff, fr = _forces(s, delta, vx, pdd, k)
    out[X_E1] = s[X_E1_DOT]
    out[X_E1_DOT] = (ff + fr) / k[K_M] - vx * pdd + ax * s[X_E2]
    out[X_E2] = s[X_E2_DOT]
    out[X_E2_DOT] = (k[K_LF] * ff - k[K_LR] * fr) / k[K_IZ] - pddd
    for i in range(X_LOG_CF, N_X):
        out[i] = 0.0


@njit(cache=True)
def _rk4(s, dt, delta, vx, ax, pdd, pddd, k, work):
    """In place RK4 step of the (deterministic part of the) model; ``work`` (5, N_X)."""
    k1, k2, k3, k4, y = work[0], work[1], work[2], work[3], work[4]
    _rhs(s, delta, vx, ax, pdd, pddd, k, k1)
    vm = vx + 0.5 * dt * ax
    for i in range(N_X):
        y[i] = s[i] + 0.5 * dt * k1[i]
    _rhs(y, delta, vm, ax, pdd, pddd, k, k2)
    for i in range(N_X):
        y[i] = s[i] + 0.5 * dt * k2[i]
    _rhs(y, delta, vm, ax, pdd, pddd, k, k3)
    for i in range(N_X):
        y[i] = s[i] + dt * k3[i]
    _rhs(y, delta, vx + dt * ax, ax, pdd, pddd, k, k4)
    for i in range(N_X):
        s[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


@njit(cache=True)
def _cholesky(P, L):
    """Lower Cholesky factor of symmetric ``P`` into ``L``; non-positive pivots are floored."""
    n = P.shape[0]
    for j in range(n):
        d = P[j, j]
        for m in range(j):
            d -= L[j, m] * L[j, m]
        if d < 1e-30:
            d = 1e-30
        L[j, j] = math.sqrt(d)
        for i in range(j + 1, n):
            v = P[i, j]
            for m in range(j):
                v -= L[i, m] * L[j, m]
            L[i, j] = v / L[j, j]
        for i in range(j):
            L[i, j] = 0.0


@njit(cache=True)
def ukf_predict(x, P, q, dt, delta, vx, ax, pdd, pddd, k, wm, wc, gamma, sig, work, L):
    """Unscented predict over ``dt`` [s], in place on ``x`` (N_X,) and ``P`` (N_X, N_X).

    ``q`` (N_X,): process-noise intensities (``Q = diag(q) dt``); ``wm``, ``wc`` the
    sigma-point weights, ``gamma = sqrt(n + lambda)``; ``sig`` (N_SIGMA, N_X), ``work``
    (5, N_X) and ``L`` (N_X, N_X) are scratch.
    """
    n = N_X
    _cholesky(P, L)
    for i in range(n):
        sig[0, i] = x[i]
    for j in range(n):
        for i in range(n):
            sig[1 + j, i] = x[i] + gamma * L[i, j]
            sig[1 + n + j, i] = x[i] - gamma * L[i, j]
    for p in range(2 * n + 1):
        _rk4(sig[p], dt, delta, vx, ax, pdd, pddd, k, work)
    for i in range(n):
        acc = 0.0
        for p in range(2 * n + 1):
            acc += wm[p] * sig[p, i]
        x[i] = acc
    for i in range(n):
        for j in range(i, n):
            acc = 0.0
            for p in range(2 * n + 1):
                acc += wc[p] * (sig[p, i] - x[i]) * (sig[p, j] - x[j])
            P[i, j] = acc
            P[j, i] = acc
        P[i, i] += q[i] * dt


@njit(cache=True)
def ukf_update(x, P, z1, z2, r1, r2, xc=0.0):
    """Kalman update with the camera frame ``z = [e1, e2]`` (variances ``r1``, ``r2``), in place.

    ``e1`` is measured ``xc`` [m] ahead of the CG (``VehicleParams.camera_x``; the path's bend
    over ``xc`` already taken off ``z1``): ``h = [e1 + xc sin(e2), e2]``, linearised at the
    state (``H = [[1, 0, xc cos(e2), 0, ...], [0, 0, 1, 0, ...]]``); ``xc = 0`` is the
    selection of ``e1`` and ``e2``.
    Returns ``(nu_e1, nu_e2, nis)``: the innovation before the correction and its normalised
    square ``nu^T S^-1 nu`` (``S`` the innovation covariance).
    """
    n = N_X
    c = xc * math.cos(x[X_E2])
    ph0 = np.empty(n)  # P H0^T
    ph1 = np.empty(n)  # P H1^T
    for i in range(n):
        ph0[i] = P[i, X_E1] + c * P[i, X_E2]
        ph1[i] = P[i, X_E2]
    s11 = ph0[X_E1] + c * ph0[X_E2] + r1
    s12 = ph1[X_E1] + c * ph1[X_E2]
    s22 = ph1[X_E2] + r2
    det = s11 * s22 - s12 * s12
    i11, i12, i22 = s22 / det, -s12 / det, s11 / det
    y1, y2 = z1 - (x[X_E1] + xc * math.sin(x[X_E2])), z2 - x[X_E2]
    nis = y1 * (i11 * y1 + i12 * y2) + y2 * (i12 * y1 + i22 * y2)
    Kg = np.empty((n, 2))
    for i in range(n):
        Kg[i, 0] = ph0[i] * i11 + ph1[i] * i12
        Kg[i, 1] = ph0[i] * i12 + ph1[i] * i22
    for i in range(n):
        x[i] += Kg[i, 0] * y1 + Kg[i, 1] * y2
    # P <- P - K S K^T = P - K (P H^T)^T
    for i in range(n):
        for j in range(n):
            P[i, j] -= Kg[i, 0] * ph0[j] + Kg[i, 1] * ph1[j]
    for i in range(n):
        for j in range(i + 1, n):
            v = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = v
            P[j, i] = v
    return y1, y2, nis


#: inputs held between rows, in :func:`ukf_run_rows`' ``u_prev``: steering, speed, ax, psi_dot_des, psi_ddot_des
U_DELTA, U_VX, U_AX, U_PDD, U_PDDD = range(5)


@njit(cache=True)
def ukf_run_rows(x, P, q, r1, r2, t, delta, vx, ax, pdd, pddd, e1, e2, k, wm, wc, gamma, u_prev, t_now, dt_last,
                 predict_last, out_x, out_pd, out_c12, out_aux, out_nu, out_nis, xc=0.0):  # fmt: skip
    """Filter rows ``t_j`` (any spacing) from the filter's time ``t_now``, as every estimator's ``run``.

    Per row: predict from ``t_now`` to ``t_j`` with the previous row's inputs held (before the
    first row of a call: the inputs ``u_prev`` the previous call ended with, when ``t_0 >
    t_now``), correct with the frame delivered at ``t_j`` (if neither channel is NaN), record
    the posterior (state ``out_x``, its variances ``out_pd``, the covariance of ``e1_dot`` and
    ``e2`` ``out_c12``, ``af, ar, Ff, Fr`` in ``out_aux``, the innovation and NIS); after the
    last row, predict ``dt_last`` further when ``predict_last``. ``u_prev`` is left holding the
    last row's inputs.

    Returns ``(rows done, time reached)``; rows done < n when the estimate became non-finite.
    """
    n = t.shape[0]
    sig = np.empty((N_SIGMA, N_X))
    work = np.empty((5, N_X))
    L = np.zeros((N_X, N_X))
    for j in range(n):
        if j > 0:
            ukf_predict(x, P, q, t[j] - t_now, delta[j - 1], vx[j - 1], ax[j - 1], pdd[j - 1], pddd[j - 1], k, wm, wc,
                        gamma, sig, work, L)  # fmt: skip
        elif t[0] > t_now:  # continue from the previous call with its last inputs
            ukf_predict(x, P, q, t[0] - t_now, u_prev[U_DELTA], u_prev[U_VX], u_prev[U_AX], u_prev[U_PDD],
                        u_prev[U_PDDD], k, wm, wc, gamma, sig, work, L)  # fmt: skip
        t_now = t[j]
        if e1[j] == e1[j] and e2[j] == e2[j]:
            y1, y2, nis = ukf_update(x, P, e1[j], e2[j], r1, r2, xc)
            out_nu[j, 0] = y1
            out_nu[j, 1] = y2
            out_nis[j] = nis
        for i in range(N_X):
            out_x[j, i] = x[i]
            out_pd[j, i] = P[i, i]
        out_c12[j] = P[X_E1_DOT, X_E2]
        af, ar, ff, fr = _forces(x, delta[j], vx[j], pdd[j], k)
        out_aux[j, 0] = af
        out_aux[j, 1] = ar
        out_aux[j, 2] = ff
        out_aux[j, 3] = fr
        for i in range(N_X):
            if not math.isfinite(x[i]):
                return j, t_now
    if n > 0:
        u_prev[U_DELTA] = delta[n - 1]
        u_prev[U_VX] = vx[n - 1]
        u_prev[U_AX] = ax[n - 1]
        u_prev[U_PDD] = pdd[n - 1]
        u_prev[U_PDDD] = pddd[n - 1]
        if predict_last:
            ukf_predict(x, P, q, dt_last, delta[n - 1], vx[n - 1], ax[n - 1], pdd[n - 1], pddd[n - 1], k, wm, wc, gamma,
                        sig, work, L)  # fmt: skip
            t_now = t[n - 1] + dt_last
    return n, t_now


#: the observer's compiled family plus this file: an edit to the slip angles invalidates this module's numba cache
#: (:func:`tire_learning_env._jit_cache.key_on_family`)
UKF_FAMILY = (*KERNEL_FAMILY, Path(__file__))
key_on_family(globals(), UKF_FAMILY)
