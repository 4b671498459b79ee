r"""Compiled core of the neuro-adaptive estimator: one loop for every measurement model.

Model (SPEC §1-2 in body coordinates, exact for a time-varying speed). State
``x = [vy, r, e1, e2]`` (:class:`~.model.StateIndex`): lateral velocity of the centre of
gravity [m/s], yaw rate [rad/s] and, when a lane camera is used, the lateral offset [m]
and heading error [rad] to the path. IMU-only estimation uses the first two only
(``nx = 2``). Per row the inputs are the road-wheel steering ``delta`` [rad], the speed
``vx`` [m/s] (with ``ax`` [m/s^2] inside the row) and the path curvature ``kappa`` [1/m]::

    alpha_f = delta - (vy + lf r) / vx,      alpha_r = -(vy - lr r) / vx             (eq. 13)
    F_i     = 2 C_i alpha_i + gamma_i sum_j W_ij sigma_ij(alpha_i)                   (eq. 14, 29)
    vy_dot  = (F_f cos(delta) + F_r) / m - vx r
    r_dot   = (lf F_f cos(delta) - lr F_r) / Iz
    e1_dot  = vy + vx e2,                    e2_dot = r - vx kappa

With ``vy = e1_dot - vx e2`` and ``r = e2_dot + vx kappa`` this is SPEC §1's error-state
model (eqs. 1-8; ``cos(delta) = 1`` there). Measurement channels (NaN = not delivered):
camera ``[e1, e2]`` (optionally ``latency`` seconds old), IMU ``[a_y, r]`` with
``a_y = (F_f cos(delta) + F_r) / m`` (a feedthrough of the learned force) and optional
sensor offsets appended to the weight vector.

Per row: [camera frame: rewind to the instant it shows, correct there, replay to now]
-> [IMU sample: correct] -> record -> predict to the next row (RK4 sub-steps of at most
``h_max``; the sensitivity ``Upsilon = dx/dw`` and the state-error covariance ``Sigma``
by the second-order transition of the linearisation).

A correction with innovation ``nu = z - h(x, w)`` and regressor ``Psi = H Upsilon + D_w``:

- causal mode: weights by recursive least squares with the full innovation covariance
  ``Psi P_w Psi^T + H Sigma H^T + R``, projected on their box, then
  ``x += Upsilon dw + L nu``, ``Upsilon <- Upsilon - L Psi``, Joseph update of ``Sigma``
  with the certified gain ``L`` of the speed cell (:mod:`.gains`);
- fixed mode (offline refinement): weights held, ``Psi^T S^-1 Psi``, ``Psi^T S^-1 nu``
  and ``nu^T S^-1 nu`` accumulated for a Gauss-Newton step of the prediction-error fit
  (:mod:`.offline`), and the per-row score ``Psi^T S^-1 nu`` stored for its covariance.

Health (causal and fixed mode): the normalised innovation squared (NIS) over a sliding
window of updates against a chi-square bound, the time since the last measurement, and
the physical range of the state. Any trip freezes adaptation; entering a trip rolls the
weights back to a checkpoint taken at least ``rollback_s`` earlier; the flag recovers once
a fresh window is consistent again.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

# state layout (body states first, so an IMU-only estimator uses the prefix)
VY, R, E1, E2 = 0, 1, 2, 3
# measurement channels
CH_E1, CH_E2, CH_AY, CH_R = 0, 1, 2, 3
N_CHANNELS = 4
GROUP_CAMERA, GROUP_IMU = 0, 1
# health codes (trace.health)
HEALTH_OK, HEALTH_SETTLING, HEALTH_NO_DATA, HEALTH_INCONSISTENT, HEALTH_DIVERGED, HEALTH_RECOVERING = range(6)
HEALTH_NAMES = ("ok", "settling", "no_data", "inconsistent", "diverged", "recovering")
# modes
MODE_CAUSAL, MODE_FIXED = 0, 1
# health state vector layout
(HS_CODE, HS_LAST_MEAS, HS_TRIP_T, HS_SUM, HS_DOF, HS_COUNT, HS_HEAD, HS_LAST_CKPT, HS_N_CKPT,
 HS_CKPT_HEAD, HS_TRIPS, HS_STARTED, HS_T0, HS_PREV_T, HS_PREV_KAPPA, HS_KAPPA_RATE) = range(16)  # fmt: skip
N_HS = 16  # the last three: the previous row's time and curvature, and the curvature rate (not health)
# history meta: number of rows stored, head
HM_COUNT, HM_HEAD = 0, 1
V_FLOOR = 3.0  # [m/s]: speed floor of the slip angles (singular at standstill)
_Z_CHI = 3.719  # standard normal quantile of 1 - 1e-4 (chi-square bound of the health test)


class Model(NamedTuple):
    """Vehicle and basis constants of a run (all SI)."""

    veh: np.ndarray  # [m, Iz, lf, lr, 2 Cf, 2 Cr]
    lo: np.ndarray  # (2, N) soft-clip lower bounds [rad]
    hi: np.ndarray  # (2, N) upper bounds [rad]
    off: np.ndarray  # (2, N) offsets subtracted from the activations [rad]
    lam: float  # sharpness [1/rad]
    gamma: np.ndarray  # (2,) scales [N/rad]
    n_bias: int  # sensor offsets appended to w: 0, or 2 (a_y [m/s^2], yaw rate [rad/s])
    wlo: np.ndarray  # (nw,) weight box
    whi: np.ndarray  # (nw,)
    nx: int  # 2 (IMU) or 4 (camera, fused)
    q_force: np.ndarray  # (2,) force-error intensity front/rear [N^2 s]
    h_max: float  # largest integration sub-step [s]
    ub: np.ndarray  # (2, NB) distinct activation bounds of each axle [rad] (shared by neighbouring members)
    nub: np.ndarray  # (2,) int64: how many of ``ub`` are used per axle
    ilo: np.ndarray  # (2, N) int64: index of each member's lower bound in ``ub``
    ihi: np.ndarray  # (2, N) int64: ... of its upper bound


class Gains(NamedTuple):
    """Certified correction gains per speed cell."""

    edges: np.ndarray  # (n_cells + 1,) speed cell edges [m/s]
    L_cam: np.ndarray  # (n_cells, nx, 2) gain of the camera channels
    L_imu: np.ndarray  # (n_cells, nx, 2) gain of the IMU channels


class Settings(NamedTuple):
    """Run settings."""

    r_var: np.ndarray  # (4,) measurement noise variance of e1, e2, a_y, r
    use_cam: bool
    use_imu: bool
    latency: float  # camera latency [s]
    mode: int  # MODE_CAUSAL or MODE_FIXED
    adapt: bool  # causal mode: learn the weights
    q_w: float  # weight random-walk intensity [1/s] (variance per second)
    p_max: float  # cap of each weight variance
    settle_until: float  # no adaptation before this time [s]
    gap_limit: float  # health: longest time without a measurement [s]
    nis_factor: float  # health: window NIS may exceed the chi-square bound by this factor
    rollback_s: float  # weights restored from a checkpoint at least this old [s]
    gate: float  # fixed mode: updates with NIS above this are left out of the fit
    accumulate_from: float  # fixed mode: accumulate from this time [s]
    x0: np.ndarray  # (nx,) state after a divergence reset
    sig0: np.ndarray  # (nx, nx) its covariance
    dt_last: float  # prediction step after the last row [s]
    store_weights: bool
    store_scores: bool
    compute_std: bool
    kalman: bool  # correct with the Kalman gain Sigma H^T S^-1 instead of the certified gain
    record: bool  # store the per-row outputs (off: only the state and the accumulators are updated)
    shift_frames: bool  # fixed mode, camera only: delayed frames applied at their instant in one forward
    # sweep (the same corrections as the rewind-and-replay of the causal mode, without the replay)
    steering_ramp: bool  # steering ramps linearly to the next row's (first-order hold) instead of being held


class State(NamedTuple):
    """Mutable estimator state (updated in place)."""

    x: np.ndarray  # (nx,)
    w: np.ndarray  # (nw,)
    ups: np.ndarray  # (nx, nw) sensitivity dx/dw
    sig: np.ndarray  # (nx, nx) state-error covariance at exact weights
    pw: np.ndarray  # (nw, nw) weight covariance
    hs: np.ndarray  # (N_HS,) health state
    hring: np.ndarray  # (W, 2) NIS and dof of the last W updates
    ck_t: np.ndarray  # (C,) checkpoint times
    ck_w: np.ndarray  # (C, nw)
    ck_pw: np.ndarray  # (C, nw, nw)
    hist_t: np.ndarray  # (H,) history for delayed frames
    hist_x: np.ndarray  # (H, nx)
    hist_ups: np.ndarray  # (H, nx, nw)
    hist_sig: np.ndarray  # (H, nx, nx)
    hist_u: np.ndarray  # (H, 6) delta, vx, ax, kappa, z_ay, z_r
    hist_meta: np.ndarray  # (2,) int64: count, head


class Accumulator(NamedTuple):
    """Normal equations of the prediction-error fit (fixed mode)."""

    hess: np.ndarray  # (nw, nw) sum Psi^T S^-1 Psi
    grad: np.ndarray  # (nw,) sum Psi^T S^-1 nu
    stats: np.ndarray  # (4,) sum nu^T S^-1 nu, updates, dof, sum log det S
    innov: np.ndarray  # (n rows, 2) the camera innovations (e1, e2) of the fit, by frame row; (0, 2): not kept


class Outputs(NamedTuple):
    x: np.ndarray  # (n, nx) posterior state
    slip: np.ndarray  # (n, 2)
    fnl: np.ndarray  # (n, 2) nonlinear (learned) axle force [N]
    force: np.ndarray  # (n, 2) total axle force [N]
    w: np.ndarray  # (n, nw) or (0, nw) when not stored
    std: np.ndarray  # (n, nx) or (0, nx)
    nu: np.ndarray  # (n, 4) innovations (NaN without measurement)
    nis: np.ndarray  # (n,) NIS of the row's updates (NaN without)
    health: np.ndarray  # (n,) int8
    score: np.ndarray  # (n, nw) or (0, nw)


# -- model ------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _softplus(x):
    """``ln(1 + exp(x))``; exact to double precision without transcendentals for ``|x| > 37``."""
    if x > 37.0:
        return x
    if x < -37.0:
        return 0.0
    return max(x, 0.0) + math.log1p(math.exp(-abs(x)))


@njit(cache=True, inline="always")
def _half_tanh(x):
    """``tanh(x / 2)``, saturated (to double precision) beyond ``|x| > 40``."""
    if x > 40.0:
        return 1.0
    if x < -40.0:
        return -1.0
    return math.tanh(0.5 * x)


def bound_table(lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(ub, nub, ilo, ihi)`` of :class:`Model`: the distinct bounds of each axle's members
    (neighbouring members share a bound, so each softplus is evaluated once per bound)."""
    lower = np.asarray(lower, dtype=float)
    upper = np.asarray(upper, dtype=float)
    n_ax, N = lower.shape
    tables = [np.unique(np.r_[lower[i], upper[i]]) for i in range(n_ax)]
    NB = max(len(u) for u in tables)
    ub = np.zeros((n_ax, NB))
    nub = np.zeros(n_ax, dtype=np.int64)
    ilo = np.zeros((n_ax, N), dtype=np.int64)
    ihi = np.zeros((n_ax, N), dtype=np.int64)
    for i, u in enumerate(tables):
        ub[i, : len(u)] = u
        nub[i] = len(u)
        ilo[i] = np.searchsorted(u, lower[i])
        ihi[i] = np.searchsorted(u, upper[i])
    return ub, nub, ilo, ihi


@njit(cache=True)
def _bounds_eval(a, axle, lam, ub, nub, spm, spp, ht, slopes):
    """Per distinct bound ``u`` of the axle, with ``x = lam (a - u)``: ``softplus(-x)`` into
    ``spm``, ``softplus(x)`` into ``spp`` and (``slopes``) ``tanh(x / 2)`` into ``ht`` (one
    exponential and one logarithm per bound, shared by the members meeting there)."""
    for u in range(nub[axle]):
        x = lam * (a - ub[axle, u])
        ax_ = abs(x)
        if ax_ > 40.0:
            spp[u] = x if x > 0.0 else 0.0
            spm[u] = -x if x < 0.0 else 0.0
            if slopes:
                ht[u] = 1.0 if x > 0.0 else -1.0
            continue
        em = math.expm1(-ax_)
        l = math.log1p(1.0 + em) if ax_ <= 37.0 else 0.0
        spp[u] = max(x, 0.0) + l
        spm[u] = max(-x, 0.0) + l
        if slopes:
            th = -em / (2.0 + em)  # tanh(|x| / 2)
            ht[u] = th if x >= 0.0 else -th


@njit(cache=True)
def _basis_arrays(a, axle, lam, g, ub, nub, ilo, ihi, off, w, phi, dphi, spm, spp, ht):
    """:func:`axle_basis` on plain arrays (the hot path)."""
    N = off.shape[1]
    _bounds_eval(a, axle, lam, ub, nub, spm, spp, ht, True)
    f = 0.0
    k = 0.0
    base = axle * N
    for j in range(N):
        ul = ilo[axle, j]
        uh = ihi[axle, j]
        s = a + (spm[ul] - spp[uh]) / lam - off[axle, j]
        d = 0.5 * (ht[ul] - ht[uh])
        p = g * s
        dp = g * d
        phi[base + j] = p
        dphi[base + j] = dp
        f += p * w[base + j]
        k += dp * w[base + j]
    return f, k


@njit(cache=True)
def _force_arrays(a, axle, lam, g, ub, nub, ilo, ihi, off, w, spm, spp):
    """The learned part of the axle force alone (no activations stored, no slopes)."""
    N = off.shape[1]
    _bounds_eval(a, axle, lam, ub, nub, spm, spp, spm, False)
    f = 0.0
    base = axle * N
    for j in range(N):
        s = a + (spm[ilo[axle, j]] - spp[ihi[axle, j]]) / lam - off[axle, j]
        f += s * w[base + j]
    return g * f


@njit(cache=True)
def axle_basis(a, axle, M, w, phi, dphi, wk):
    """Activations ``gamma sigma`` (eq. 30) into ``phi[axle N : (axle+1) N]``, their slopes into
    ``dphi``; returns ``(f, df/da)`` of the learned part of the axle force."""
    return _basis_arrays(a, axle, M.lam, M.gamma[axle], M.ub, M.nub, M.ilo, M.ihi, M.off, w, phi, dphi, wk.spm,
                         wk.spp, wk.ht)  # fmt: skip


@njit(cache=True)
def slip_angles(vy, r, delta, vx, lf, lr):
    """Front and rear slip angles [rad] (eq. 13, body form); ``vx`` floored at ``V_FLOOR``."""
    v = vx if vx > V_FLOOR else V_FLOOR
    return delta - (vy + lf * r) / v, -(vy - lr * r) / v


@njit(cache=True)
def forces(vy, r, delta, vx, w, M, wk):
    """``(alpha_f, alpha_r, F_f, F_r, f_f, f_r, k_f, k_r)``: slips, total and learned axle
    forces [N] and total slopes [N/rad]; fills ``phi``/``dphi`` (eqs. 13, 14, 29)."""
    af, ar = slip_angles(vy, r, delta, vx, M.veh[2], M.veh[3])
    ff, kf = axle_basis(af, 0, M, w, wk.phi, wk.dphi, wk)
    fr, kr = axle_basis(ar, 1, M, w, wk.phi, wk.dphi, wk)
    return af, ar, M.veh[4] * af + ff, M.veh[5] * ar + fr, ff, fr, M.veh[4] + kf, M.veh[5] + kr


@njit(cache=True)
def _rhs_arrays(x, delta, cd, vx, kappa, w, veh, nx, lam, gam, ub, nub, ilo, ihi, off, phi, dphi, spm, spp, ht, out,
                full):  # fmt: skip
    """``out = x_dot``; returns the total slopes ``(k_f, k_r)`` at ``x`` (``full``: also the
    activations ``phi``, ``dphi``; else the forces alone and zero slopes)."""
    m, Iz, lf, lr = veh[0], veh[1], veh[2], veh[3]
    v = vx if vx > V_FLOOR else V_FLOOR
    af, ar = slip_angles(x[VY], x[R], delta, v, lf, lr)
    if full:
        ff, kf = _basis_arrays(af, 0, lam, gam[0], ub, nub, ilo, ihi, off, w, phi, dphi, spm, spp, ht)
        fr, kr = _basis_arrays(ar, 1, lam, gam[1], ub, nub, ilo, ihi, off, w, phi, dphi, spm, spp, ht)
        kf += veh[4]
        kr += veh[5]
    else:
        ff = _force_arrays(af, 0, lam, gam[0], ub, nub, ilo, ihi, off, w, spm, spp)
        fr = _force_arrays(ar, 1, lam, gam[1], ub, nub, ilo, ihi, off, w, spm, spp)
        kf = 0.0
        kr = 0.0
    Ff = veh[4] * af + ff
    Fr = veh[5] * ar + fr
    out[VY] = (Ff * cd + Fr) / m - v * x[R]
    out[R] = (lf * Ff * cd - lr * Fr) / Iz
    if nx == 4:
        out[E1] = x[VY] + v * x[E2]
        out[E2] = x[R] - v * kappa
    return kf, kr


@njit(cache=True, inline="always")
def _jacobian(cd, vx, kf, kr, m, Iz, lf, lr, nx, J):
    """``J = d x_dot / d x`` at total slopes ``k_f``, ``k_r`` (plain arguments: the hot path)."""
    v = vx if vx > V_FLOOR else V_FLOOR
    J[:, :] = 0.0
    J[VY, VY] = -(kf * cd + kr) / (m * v)
    J[VY, R] = -(kf * cd * lf - kr * lr) / (m * v) - v
    J[R, VY] = -(lf * kf * cd - lr * kr) / (Iz * v)
    J[R, R] = -(lf * lf * kf * cd + lr * lr * kr) / (Iz * v)
    if nx == 4:
        J[E1, VY] = 1.0
        J[E1, E2] = v
        J[E2, R] = 1.0


class _Work(NamedTuple):
    phi: np.ndarray  # (nw,)
    dphi: np.ndarray
    k1: np.ndarray  # (nx,)
    k2: np.ndarray
    k3: np.ndarray
    k4: np.ndarray
    y: np.ndarray
    J: np.ndarray  # (nx, nx)
    Phi: np.ndarray
    Gm: np.ndarray
    T1: np.ndarray  # (nx, nx)
    U: np.ndarray  # (nx, nw)
    H: np.ndarray  # (2, nx)
    Dw: np.ndarray  # (2, nw)
    Psi: np.ndarray  # (2, nw)
    PsiP: np.ndarray  # (2, nw)
    Kw: np.ndarray  # (nw, 2)
    dw: np.ndarray  # (nw,)
    Lk: np.ndarray  # (nx, 2) Kalman gain
    spm: np.ndarray  # (NB,) softplus(-lam (a - u)) per distinct bound u
    spp: np.ndarray  # (NB,) softplus(lam (a - u))
    ht: np.ndarray  # (NB,) tanh(lam (a - u) / 2)


def make_work(nx: int, nw: int, nb: int = 64) -> _Work:
    e = np.empty
    return _Work(e(nw), e(nw), e(nx), e(nx), e(nx), e(nx), e(nx), e((nx, nx)), e((nx, nx)), e((nx, nx)),
                 e((nx, nx)), e((nx, nw)), e((2, nx)), e((2, nw)), e((2, nw)), e((2, nw)), e((nw, 2)), e(nw), e((nx, 2)),
                 e(nb), e(nb), e(nb))  # fmt: skip


@njit(cache=True)
def predict(st, dt, delta, ddot, vx0, ax, kappa, kdot, M, S, wk):
    """Advance ``x``, ``Upsilon``, ``Sigma`` (and the weight random walk) by ``dt`` [s] with the
    steering ramping with ``ddot`` [rad/s] (0: held), the speed with ``ax`` and the path
    curvature with ``kdot`` [1/(m s)]."""
    if dt <= 0.0:
        return
    _predict_arrays(dt, delta, ddot, vx0, ax, kappa, kdot, st.x, st.w, st.ups, st.sig, M.veh, M.nx, M.lam, M.gamma, M.ub, M.nub,
                    M.ilo, M.ihi, M.off, M.q_force, M.h_max, wk.phi, wk.dphi, wk.spm, wk.spp, wk.ht, wk.k1, wk.k2,
                    wk.k3, wk.k4, wk.y, wk.J, wk.Phi, wk.Gm, wk.T1, wk.U)  # fmt: skip
    if S.mode == MODE_CAUSAL and S.adapt and S.q_w > 0.0:
        for a in range(st.w.shape[0]):
            st.pw[a, a] += S.q_w * dt


@njit(cache=True)
def _predict_arrays(dt, delta0, ddot, vx0, ax, kappa0, kdot, x, w, ups, sig, veh, nx, lam, gam, ub, nub, ilo, ihi, off, q_force,
                    h_max, phi, dphi, spm, spp, ht, k1, k2, k3, k4, y, J, Phi, Gm, T1, U):  # fmt: skip
    """:func:`predict` on plain arrays (the hot path: no tuple access inside the loops)."""
    nw = w.shape[0]
    N2 = 2 * off.shape[1]
    m, Iz, lf, lr = veh[0], veh[1], veh[2], veh[3]
    n_sub = int(math.ceil(dt / h_max - 1e-9))
    if n_sub < 1:
        n_sub = 1
    h = dt / n_sub
    for s in range(n_sub):
        delta = delta0 + ddot * s * h
        delta_m = delta + 0.5 * h * ddot
        delta_1 = delta + h * ddot
        cd = math.cos(delta)
        cd_m = math.cos(delta_m)
        cd_1 = math.cos(delta_1)
        v0 = vx0 + ax * s * h
        vm = v0 + 0.5 * h * ax
        v1 = v0 + h * ax
        kappa = kappa0 + kdot * s * h
        kappa_m = kappa + 0.5 * h * kdot
        kappa_1 = kappa + h * kdot
        kf, kr = _rhs_arrays(x, delta, cd, v0, kappa, w, veh, nx, lam, gam, ub, nub, ilo, ihi, off, phi, dphi, spm, spp,
                             ht, k1, True)  # fmt: skip
        # linearised transition over the sub-step: Phi = I + hJ + (hJ)^2/2, Gm = h (I + hJ/2)
        _jacobian(cd, v0, kf, kr, m, Iz, lf, lr, nx, J)
        for i in range(nx):
            for j in range(nx):
                acc = 0.0
                for q in range(nx):
                    acc += J[i, q] * J[q, j]
                Phi[i, j] = h * J[i, j] + 0.5 * h * h * acc
                Gm[i, j] = 0.5 * h * h * J[i, j]
            Phi[i, i] += 1.0
            Gm[i, i] += h
        # Upsilon <- Phi Upsilon + Gm B_w (B_w: force input of each weight)
        ev0f, ev1f = cd / m, lf * cd / Iz
        ev0r, ev1r = 1.0 / m, -lr / Iz
        for a in range(nw):
            if a < N2:
                if a < N2 // 2:
                    b0 = ev0f * phi[a]
                    b1 = ev1f * phi[a]
                else:
                    b0 = ev0r * phi[a]
                    b1 = ev1r * phi[a]
            else:
                b0 = 0.0
                b1 = 0.0
            for i in range(nx):
                acc = Gm[i, VY] * b0 + Gm[i, R] * b1
                for q in range(nx):
                    acc += Phi[i, q] * ups[q, a]
                U[i, a] = acc
        for i in range(nx):
            for a in range(nw):
                ups[i, a] = U[i, a]
        # Sigma <- Phi Sigma Phi^T + h Q (force-error intensity on both axles)
        for i in range(nx):
            for j in range(nx):
                acc = 0.0
                for q in range(nx):
                    acc += Phi[i, q] * sig[q, j]
                T1[i, j] = acc
        for i in range(nx):
            for j in range(nx):
                acc = 0.0
                for q in range(nx):
                    acc += T1[i, q] * Phi[j, q]
                sig[i, j] = acc
        qf, qr = q_force[0] * h, q_force[1] * h
        sig[VY, VY] += qf * ev0f * ev0f + qr * ev0r * ev0r
        sig[VY, R] += qf * ev0f * ev1f + qr * ev0r * ev1r
        sig[R, VY] += qf * ev0f * ev1f + qr * ev0r * ev1r
        sig[R, R] += qf * ev1f * ev1f + qr * ev1r * ev1r
        # RK4 of the state (the speed ramps within the sub-step)
        for i in range(nx):
            y[i] = x[i] + 0.5 * h * k1[i]
        _rhs_arrays(y, delta_m, cd_m, vm, kappa_m, w, veh, nx, lam, gam, ub, nub, ilo, ihi, off, phi, dphi, spm, spp, ht,
                    k2, False)  # fmt: skip
        for i in range(nx):
            y[i] = x[i] + 0.5 * h * k2[i]
        _rhs_arrays(y, delta_m, cd_m, vm, kappa_m, w, veh, nx, lam, gam, ub, nub, ilo, ihi, off, phi, dphi, spm, spp, ht,
                    k3, False)  # fmt: skip
        for i in range(nx):
            y[i] = x[i] + h * k3[i]
        _rhs_arrays(y, delta_1, cd_1, v1, kappa_1, w, veh, nx, lam, gam, ub, nub, ilo, ihi, off, phi, dphi, spm, spp, ht,
                    k4, False)  # fmt: skip
        for i in range(nx):
            x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


# -- corrections ------------------------------------------------------------------------------
@njit(cache=True)
def _cell(edges, vx):
    n = edges.shape[0] - 1
    c = 0
    while c < n - 1 and vx >= edges[c + 1]:
        c += 1
    return c


@njit(cache=True)
def _measurement(group, st, delta, vx, M, S, zk, wk):
    """Innovation, ``H`` (2, nx), ``D_w`` (2, nw), ``Psi`` and present flags of a channel group.

    Returns ``(nu0, nu1, p0, p1)``; absent channels have zero rows.
    """
    nx = M.nx
    nw = st.w.shape[0]
    N2 = 2 * M.lo.shape[1]
    c0 = CH_E1 if group == GROUP_CAMERA else CH_AY
    z0 = zk[c0]
    z1 = zk[c0 + 1]
    p0 = z0 == z0
    p1 = z1 == z1
    wk.H[:, :] = 0.0
    wk.Dw[:, :] = 0.0
    x = st.x
    if group == GROUP_CAMERA:
        h0 = x[E1]
        h1 = x[E2]
        wk.H[0, E1] = 1.0
        wk.H[1, E2] = 1.0
    else:
        m, lf, lr = M.veh[0], M.veh[2], M.veh[3]
        v = vx if vx > V_FLOOR else V_FLOOR
        cd = math.cos(delta)
        _, _, Ff, Fr, _, _, kf, kr = forces(x[VY], x[R], delta, v, st.w, M, wk)
        h0 = (Ff * cd + Fr) / m
        h1 = x[R]
        wk.H[0, VY] = -(kf * cd + kr) / (m * v)
        wk.H[0, R] = -(kf * cd * lf - kr * lr) / (m * v)
        wk.H[1, R] = 1.0
        for a in range(N2):
            wk.Dw[0, a] = (cd * wk.phi[a] if a < N2 // 2 else wk.phi[a]) / m
        if M.n_bias == 2:
            h0 += st.w[N2]
            h1 += st.w[N2 + 1]
            wk.Dw[0, N2] = 1.0
            wk.Dw[1, N2 + 1] = 1.0
    nu0 = z0 - h0 if p0 else 0.0
    nu1 = z1 - h1 if p1 else 0.0
    for c in range(2):
        present = p0 if c == 0 else p1
        for a in range(nw):
            if present:
                acc = wk.Dw[c, a]
                for i in range(nx):
                    acc += wk.H[c, i] * st.ups[i, a]
                wk.Psi[c, a] = acc
            else:
                wk.Psi[c, a] = 0.0
        if not present:
            for i in range(nx):
                wk.H[c, i] = 0.0
    return nu0, nu1, p0, p1


@njit(cache=True)
def _inv2(s00, s01, s11):
    det = s00 * s11 - s01 * s01
    if not det > 0.0:
        det = 1e-300
    return s11 / det, -s01 / det, s00 / det


@njit(cache=True)
def update(group, st, delta, vx, zk, M, G, S, adapt, accumulate, acc, score, k, wk):
    """Correct with the channel group's measurement at the current instant.

    Returns ``(nis, dof, nu0, nu1)``: the NIS and the innovation before the correction
    (``dof = 0``: nothing measured). ``adapt``: learn the weights (causal mode);
    ``accumulate``: add to the fit's normal equations (fixed mode).
    """
    nx = M.nx
    nw = st.w.shape[0]
    c0 = CH_E1 if group == GROUP_CAMERA else CH_AY
    nu0, nu1, p0, p1 = _measurement(group, st, delta, vx, M, S, zk, wk)
    dof = (1 if p0 else 0) + (1 if p1 else 0)
    if dof == 0:
        return 0.0, 0, np.nan, np.nan
    r0 = S.r_var[c0] if p0 else 0.0
    r1 = S.r_var[c0 + 1] if p1 else 0.0
    # state-error part of the innovation covariance: H Sigma H^T + R
    sx00 = r0
    sx01 = 0.0
    sx11 = r1
    for i in range(nx):
        for j in range(nx):
            sx00 += wk.H[0, i] * st.sig[i, j] * wk.H[0, j]
            sx01 += wk.H[0, i] * st.sig[i, j] * wk.H[1, j]
            sx11 += wk.H[1, i] * st.sig[i, j] * wk.H[1, j]
    if not p0:
        sx00 = 1.0
        sx01 = 0.0
    if not p1:
        sx11 = 1.0
        sx01 = 0.0
    # weight part: Psi P_w Psi^T
    sw00 = 0.0
    sw01 = 0.0
    sw11 = 0.0
    if adapt:  # P_w Psi^T is needed for the gain
        for c in range(2):
            for b in range(nw):
                acc_ = 0.0
                for a in range(nw):
                    acc_ += wk.Psi[c, a] * st.pw[a, b]
                wk.PsiP[c, b] = acc_
        for a in range(nw):
            sw00 += wk.PsiP[0, a] * wk.Psi[0, a]
            sw01 += wk.PsiP[0, a] * wk.Psi[1, a]
            sw11 += wk.PsiP[1, a] * wk.Psi[1, a]
    else:  # the quadratic form alone, from the upper triangle of the (symmetric) P_w
        for a in range(nw):
            pa0 = wk.Psi[0, a]
            pa1 = wk.Psi[1, a]
            if pa0 == 0.0 and pa1 == 0.0:
                continue
            t0 = 0.0
            t1 = 0.0
            for b in range(a + 1, nw):
                pab = st.pw[a, b]
                t0 += pab * wk.Psi[0, b]
                t1 += pab * wk.Psi[1, b]
            paa = st.pw[a, a]
            sw00 += pa0 * (paa * pa0 + 2.0 * t0)
            sw11 += pa1 * (paa * pa1 + 2.0 * t1)
            sw01 += pa0 * (paa * pa1 + t1) + pa1 * t0
    i00, i01, i11 = _inv2(sx00 + sw00, sx01 + sw01, sx11 + sw11)
    nis = nu0 * nu0 * i00 + 2.0 * nu0 * nu1 * i01 + nu1 * nu1 * i11
    nu0_prior = nu0 if p0 else np.nan
    nu1_prior = nu1 if p1 else np.nan
    if accumulate and nis <= S.gate * dof:
        j00, j01, j11 = _inv2(sx00, sx01, sx11)
        # S^-1 Psi and S^-1 nu
        for a in range(nw):
            q0 = j00 * wk.Psi[0, a] + j01 * wk.Psi[1, a]
            q1 = j01 * wk.Psi[0, a] + j11 * wk.Psi[1, a]
            if q0 != 0.0 or q1 != 0.0:
                for b in range(a, nw):  # upper triangle; run_rows mirrors it at the end
                    acc.hess[a, b] += q0 * wk.Psi[0, b] + q1 * wk.Psi[1, b]
            sc = q0 * nu0 + q1 * nu1
            acc.grad[a] += sc
            if S.store_scores:
                score[k, a] += sc
        acc.stats[0] += nu0 * nu0 * j00 + 2.0 * nu0 * nu1 * j01 + nu1 * nu1 * j11
        acc.stats[1] += 1.0
        acc.stats[2] += dof
        acc.stats[3] += math.log(max(sx00 * sx11 - sx01 * sx01, 1e-300))
    if adapt:
        # RLS: K_w = P_w Psi^T (S_x + S_w)^-1, projected step, covariance update
        for a in range(nw):
            wk.Kw[a, 0] = wk.PsiP[0, a] * i00 + wk.PsiP[1, a] * i01
            wk.Kw[a, 1] = wk.PsiP[0, a] * i01 + wk.PsiP[1, a] * i11
        moved = False
        for a in range(nw):
            wn = st.w[a] + wk.Kw[a, 0] * nu0 + wk.Kw[a, 1] * nu1
            if wn > M.whi[a]:
                wn = M.whi[a]
            elif wn < M.wlo[a]:
                wn = M.wlo[a]
            wk.dw[a] = wn - st.w[a]
            if wk.dw[a] != 0.0:
                moved = True
            st.w[a] = wn
        for a in range(nw):
            for b in range(nw):
                st.pw[a, b] -= wk.Kw[a, 0] * wk.PsiP[0, b] + wk.Kw[a, 1] * wk.PsiP[1, b]
        for a in range(nw):
            if st.pw[a, a] > S.p_max:
                sc_ = math.sqrt(S.p_max / st.pw[a, a])
                for b in range(nw):
                    st.pw[a, b] *= sc_
                    st.pw[b, a] *= sc_
        if moved:
            for i in range(nx):
                a_ = 0.0
                for a in range(nw):
                    a_ += st.ups[i, a] * wk.dw[a]
                st.x[i] += a_
            nu0, nu1, p0, p1 = _measurement(group, st, delta, vx, M, S, zk, wk)
    # state correction: the certified gain of the speed cell, or the Kalman gain
    if S.kalman:
        L = wk.Lk
        j00, j01, j11 = _inv2(sx00, sx01, sx11)
        for i in range(nx):
            a0 = 0.0
            a1 = 0.0
            for q in range(nx):
                a0 += st.sig[i, q] * wk.H[0, q]
                a1 += st.sig[i, q] * wk.H[1, q]
            L[i, 0] = a0 * j00 + a1 * j01 if p0 else 0.0
            L[i, 1] = a0 * j01 + a1 * j11 if p1 else 0.0
    else:
        c = _cell(G.edges, vx)
        L = G.L_cam[c] if group == GROUP_CAMERA else G.L_imu[c]
    for i in range(nx):
        st.x[i] += L[i, 0] * nu0 + L[i, 1] * nu1
    for a in range(nw):
        q0 = wk.Psi[0, a]
        q1 = wk.Psi[1, a]
        for i in range(nx):
            st.ups[i, a] -= L[i, 0] * q0 + L[i, 1] * q1
    # Joseph form: Sigma = (I - L H) Sigma (I - L H)^T + L R L^T
    for i in range(nx):
        for j in range(nx):
            wk.T1[i, j] = (1.0 if i == j else 0.0) - L[i, 0] * wk.H[0, j] - L[i, 1] * wk.H[1, j]
    for i in range(nx):
        for j in range(nx):
            a_ = 0.0
            for q in range(nx):
                a_ += wk.T1[i, q] * st.sig[q, j]
            wk.Phi[i, j] = a_
    for i in range(nx):
        for j in range(nx):
            a_ = L[i, 0] * r0 * L[j, 0] + L[i, 1] * r1 * L[j, 1]
            for q in range(nx):
                a_ += wk.Phi[i, q] * wk.T1[j, q]
            st.sig[i, j] = a_
    return nis, dof, nu0_prior, nu1_prior


# -- health -----------------------------------------------------------------------------------
@njit(cache=True)
def _chi2_upper(dof):
    """Wilson-Hilferty upper quantile (1 - 1e-4) of chi-square with ``dof`` degrees of freedom."""
    d = max(dof, 1.0)
    c = 2.0 / (9.0 * d)
    return d * (1.0 - c + _Z_CHI * math.sqrt(c)) ** 3


@njit(cache=True)
def _save_checkpoint(st, t):
    C = st.ck_t.shape[0]
    h = int(st.hs[HS_CKPT_HEAD])
    st.ck_t[h] = t
    for a in range(st.w.shape[0]):
        st.ck_w[h, a] = st.w[a]
        for b in range(st.w.shape[0]):
            st.ck_pw[h, a, b] = st.pw[a, b]
    st.hs[HS_CKPT_HEAD] = (h + 1) % C
    st.hs[HS_N_CKPT] = min(st.hs[HS_N_CKPT] + 1.0, float(C))
    st.hs[HS_LAST_CKPT] = t


@njit(cache=True)
def _rollback(st, t, S, M):
    """Restore the newest checkpoint at least ``rollback_s`` old (the oldest if none is)."""
    n = int(st.hs[HS_N_CKPT])
    if n == 0:
        return
    C = st.ck_t.shape[0]
    best = -1
    oldest = -1
    for q in range(n):
        i = (int(st.hs[HS_CKPT_HEAD]) - 1 - q) % C
        oldest = i
        if st.ck_t[i] <= t - S.rollback_s and best < 0:
            best = i
    if best < 0:
        best = oldest
    nw = st.w.shape[0]
    for a in range(nw):
        d = st.ck_w[best, a] - st.w[a]
        for i in range(M.nx):
            st.x[i] += st.ups[i, a] * d
        st.w[a] = st.ck_w[best, a]
        for b in range(nw):
            st.pw[a, b] = st.ck_pw[best, a, b]


@njit(cache=True)
def _trip(st, t, code, S, M):
    if st.hs[HS_CODE] == HEALTH_OK and S.mode == MODE_CAUSAL and S.adapt:
        _rollback(st, t, S, M)
    if st.hs[HS_CODE] == HEALTH_OK or st.hs[HS_CODE] == HEALTH_SETTLING:
        st.hs[HS_TRIPS] += 1.0
    st.hs[HS_CODE] = code
    st.hs[HS_TRIP_T] = t
    st.hs[HS_SUM] = 0.0
    st.hs[HS_DOF] = 0.0
    st.hs[HS_COUNT] = 0.0
    st.hs[HS_HEAD] = 0.0


@njit(cache=True)
def _health_push(st, t, nis, dof, S, M):
    """Add an update's NIS to the window and re-evaluate the flag."""
    W = st.hring.shape[0]
    h = int(st.hs[HS_HEAD])
    if st.hs[HS_COUNT] >= W:
        st.hs[HS_SUM] -= st.hring[h, 0]
        st.hs[HS_DOF] -= st.hring[h, 1]
    else:
        st.hs[HS_COUNT] += 1.0
    st.hring[h, 0] = nis
    st.hring[h, 1] = dof
    st.hs[HS_SUM] += nis
    st.hs[HS_DOF] += dof
    st.hs[HS_HEAD] = (h + 1) % W
    st.hs[HS_LAST_MEAS] = t
    full = st.hs[HS_COUNT] >= W
    bound = S.nis_factor * _chi2_upper(st.hs[HS_DOF])
    code = st.hs[HS_CODE]
    if full and st.hs[HS_SUM] > bound:
        if code != HEALTH_INCONSISTENT:
            _trip(st, t, HEALTH_INCONSISTENT, S, M)
        return
    if code == HEALTH_SETTLING:
        if t >= S.settle_until:
            st.hs[HS_CODE] = HEALTH_OK
    elif code != HEALTH_OK:
        if code == HEALTH_NO_DATA or code == HEALTH_DIVERGED:
            st.hs[HS_CODE] = HEALTH_RECOVERING
        elif full:
            st.hs[HS_CODE] = HEALTH_OK


@njit(cache=True)
def _health_tick(st, t, S, M):
    """Per-row checks: data gap, divergence, checkpoints."""
    if st.hs[HS_STARTED] == 0.0:
        st.hs[HS_STARTED] = 1.0
        st.hs[HS_T0] = t
        st.hs[HS_LAST_MEAS] = t
        st.hs[HS_LAST_CKPT] = -1e300
    code = st.hs[HS_CODE]
    if t - st.hs[HS_LAST_MEAS] > S.gap_limit and code != HEALTH_NO_DATA:
        _trip(st, t, HEALTH_NO_DATA, S, M)
    ok = True
    for i in range(M.nx):
        if not math.isfinite(st.x[i]):
            ok = False
    if ok and (abs(st.x[VY]) > 20.0 or abs(st.x[R]) > 5.0):
        ok = False
    if not ok:
        _trip(st, t, HEALTH_DIVERGED, S, M)
        for i in range(M.nx):
            st.x[i] = S.x0[i]
            for a in range(st.w.shape[0]):
                st.ups[i, a] = 0.0
            for j in range(M.nx):
                st.sig[i, j] = S.sig0[i, j]
    if st.hs[HS_CODE] == HEALTH_OK and t - st.hs[HS_LAST_CKPT] >= 0.5 * S.rollback_s:
        _save_checkpoint(st, t)


# -- delayed camera frames --------------------------------------------------------------------
# History slots are addressed by a running row counter (hist_meta[HM_HEAD] = rows pushed so
# far, across calls), stored at ``slot % H``; the row being processed is ``HEAD - 1``.
@njit(cache=True)
def _store_state(st, slot):
    i = slot % st.hist_t.shape[0]
    for a in range(st.x.shape[0]):
        st.hist_x[i, a] = st.x[a]
        for b in range(st.w.shape[0]):
            st.hist_ups[i, a, b] = st.ups[a, b]
        for b in range(st.x.shape[0]):
            st.hist_sig[i, a, b] = st.sig[a, b]


@njit(cache=True)
def _push_history(st, t, delta, vx, ax, kappa, kdot, ddot, zk):
    """Store the prior and the inputs of the row being processed; advance the counter."""
    H = st.hist_t.shape[0]
    slot = int(st.hist_meta[HM_HEAD])
    i = slot % H
    st.hist_t[i] = t
    st.hist_u[i, 0] = delta
    st.hist_u[i, 1] = vx
    st.hist_u[i, 2] = ax
    st.hist_u[i, 3] = kappa
    st.hist_u[i, 4] = zk[CH_AY]
    st.hist_u[i, 5] = zk[CH_R]
    st.hist_u[i, 6] = kdot
    st.hist_u[i, 7] = ddot
    _store_state(st, slot)
    st.hist_meta[HM_HEAD] = slot + 1
    st.hist_meta[HM_COUNT] = min(st.hist_meta[HM_COUNT] + 1, H)


@njit(cache=True)
def _restore_state(st, slot):
    i = slot % st.hist_t.shape[0]
    for a in range(st.x.shape[0]):
        st.x[a] = st.hist_x[i, a]
        for b in range(st.w.shape[0]):
            st.ups[a, b] = st.hist_ups[i, a, b]
        for b in range(st.x.shape[0]):
            st.sig[a, b] = st.hist_sig[i, a, b]


@njit(cache=True)
def _stored_imu(st, slot, zrow):
    i = slot % st.hist_t.shape[0]
    zrow[CH_E1] = np.nan
    zrow[CH_E2] = np.nan
    zrow[CH_AY] = st.hist_u[i, 4]
    zrow[CH_R] = st.hist_u[i, 5]


@njit(cache=True)
def delayed_camera(st, zk, M, G, S, adapt, accumulate, acc, score, k, wk, zrow):
    """Correct with a frame that shows the instant ``t_now - latency`` (out-of-sequence update).

    Rewinds to the stored prior of the newest row at or before that instant, replays that
    row's IMU correction, predicts to the instant, corrects there (learning as usual), and
    replays the rows since (IMU corrections without learning, predictions with the new
    weights), rewriting their stored priors. Returns what :func:`update` returns.
    """
    H = st.hist_t.shape[0]
    now = int(st.hist_meta[HM_HEAD]) - 1
    oldest = now - int(st.hist_meta[HM_COUNT]) + 1
    tau = st.hist_t[now % H] - S.latency
    j = now
    while j > oldest and st.hist_t[j % H] > tau:
        j -= 1
    sj = j % H
    _restore_state(st, j)
    d, v, a, kap, kd, dd = (st.hist_u[sj, 0], st.hist_u[sj, 1], st.hist_u[sj, 2], st.hist_u[sj, 3], st.hist_u[sj, 6],
                            st.hist_u[sj, 7])  # fmt: skip
    if S.use_imu:
        _stored_imu(st, j, zrow)
        update(GROUP_IMU, st, d, v, zrow, M, G, S, False, False, acc, score, k, wk)
    dtp = max(tau - st.hist_t[sj], 0.0)
    predict(st, dtp, d, dd, v, a, kap, kd, M, S, wk)
    res = update(GROUP_CAMERA, st, d + dd * dtp, v + a * dtp, zk, M, G, S, adapt, accumulate, acc, score, k, wk)
    if j == now:
        return res
    predict(st, st.hist_t[(j + 1) % H] - st.hist_t[sj] - dtp, d + dd * dtp, dd, v + a * dtp, a, kap + kd * dtp, kd, M,
            S, wk)  # fmt: skip
    for i in range(j + 1, now):
        si = i % H
        _store_state(st, i)
        if S.use_imu:
            _stored_imu(st, i, zrow)
            update(GROUP_IMU, st, st.hist_u[si, 0], st.hist_u[si, 1], zrow, M, G, S, False, False, acc, score, k, wk)
        predict(st, st.hist_t[(i + 1) % H] - st.hist_t[si], st.hist_u[si, 0], st.hist_u[si, 7], st.hist_u[si, 1],
                st.hist_u[si, 2], st.hist_u[si, 3], st.hist_u[si, 6], M, S, wk)  # fmt: skip
    _store_state(st, now)
    return res


# -- the loop ---------------------------------------------------------------------------------
@njit(cache=True)
def _frame_instant(t, k, latency, H):
    """``(j, dtp)``: the row ``j`` whose interval holds the instant frame ``k`` shows, and the
    offset of that instant in it (exactly the rewind target of :func:`delayed_camera` with a
    history of ``H`` rows started at row 0)."""
    tau = t[k] - latency
    oldest = k - H + 1
    if oldest < 0:
        oldest = 0
    j = k
    while j > oldest and t[j] > tau:
        j -= 1
    d = tau - t[j]
    return j, (d if d > 0.0 else 0.0)


@njit(cache=True)
def _next_frame(z, k):
    """First row at or after ``k`` with a camera channel (``len(z)`` if none)."""
    n = z.shape[0]
    while k < n and not (z[k, CH_E1] == z[k, CH_E1] or z[k, CH_E2] == z[k, CH_E2]):
        k += 1
    return k


@njit(cache=True)
def run_rows(t, delta, vx, ax, kappa, z, M, G, S, st, acc, out, wk, predict_last):
    """Process all rows (module docstring); state, health and accumulators are updated in place.

    With ``S.shift_frames`` (fixed mode, camera only, a latency, nothing recorded) every
    delayed frame is applied at the instant it shows while sweeping forward, which gives the
    same corrections and accumulated fit as the rewind-and-replay of :func:`delayed_camera`
    at the cost of one prediction per row.
    """
    n = t.shape[0]
    nx = M.nx
    nw = st.w.shape[0]
    zrow = np.empty(N_CHANNELS)
    zk = np.empty(N_CHANNELS)
    delayed = S.use_cam and S.latency > 0.0
    causal = S.mode == MODE_CAUSAL
    shift = delayed and S.shift_frames and S.mode == MODE_FIXED and not S.use_imu and not S.record
    H = st.hist_t.shape[0]
    nf = _next_frame(z, 0) if shift else n
    for k in range(n):
        tk = t[k]
        for c in range(N_CHANNELS):
            zk[c] = z[k, c]
        if S.record:
            for c in range(N_CHANNELS):
                out.nu[k, c] = np.nan
        # the path curvature's rate over the coming interval: the backward difference of the last two
        # rows (causal, and the same whether the rows come in one call or several)
        kd = 0.0
        if st.hs[HS_PREV_T] == st.hs[HS_PREV_T] and tk > st.hs[HS_PREV_T] and kappa[k] == kappa[k] \
                and st.hs[HS_PREV_KAPPA] == st.hs[HS_PREV_KAPPA]:
            kd = (kappa[k] - st.hs[HS_PREV_KAPPA]) / (tk - st.hs[HS_PREV_T])
        st.hs[HS_PREV_T] = tk
        st.hs[HS_PREV_KAPPA] = kappa[k]
        st.hs[HS_KAPPA_RATE] = kd
        # the steering's ramp to the next row (first-order hold; the last row of a call is held)
        dd = 0.0
        if S.steering_ramp and k < n - 1 and t[k + 1] > tk and delta[k + 1] == delta[k + 1]:
            dd = (delta[k + 1] - delta[k]) / (t[k + 1] - tk)
        if delayed and not shift:
            _push_history(st, tk, delta[k], vx[k], ax[k], kappa[k], kd, dd, zk)
        accumulate = S.mode == MODE_FIXED and tk >= S.accumulate_from
        nis_row = 0.0
        dof_row = 0
        if not shift and S.use_cam and (zk[CH_E1] == zk[CH_E1] or zk[CH_E2] == zk[CH_E2]):
            adapt_now = causal and S.adapt and st.hs[HS_CODE] == HEALTH_OK and tk >= S.settle_until
            if delayed:
                nis, dof, n0, n1 = delayed_camera(st, zk, M, G, S, adapt_now, accumulate, acc, out.score, k, wk, zrow)
            else:
                nis, dof, n0, n1 = update(GROUP_CAMERA, st, delta[k], vx[k], zk, M, G, S, adapt_now, accumulate, acc,
                                          out.score, k, wk)  # fmt: skip
            if dof > 0:
                if S.record:
                    out.nu[k, CH_E1] = n0
                    out.nu[k, CH_E2] = n1
                if accumulate and k < acc.innov.shape[0]:
                    acc.innov[k, 0] = n0
                    acc.innov[k, 1] = n1
                nis_row += nis
                dof_row += dof
                _health_push(st, tk, nis, dof, S, M)
        if S.use_imu and (zk[CH_AY] == zk[CH_AY] or zk[CH_R] == zk[CH_R]):
            adapt_now = causal and S.adapt and st.hs[HS_CODE] == HEALTH_OK and tk >= S.settle_until
            nis, dof, n0, n1 = update(GROUP_IMU, st, delta[k], vx[k], zk, M, G, S, adapt_now, accumulate, acc,
                                      out.score, k, wk)  # fmt: skip
            if dof > 0:
                if S.record:
                    out.nu[k, CH_AY] = n0
                    out.nu[k, CH_R] = n1
                nis_row += nis
                dof_row += dof
                _health_push(st, tk, nis, dof, S, M)
        _health_tick(st, tk, S, M)
        if S.record:  # the posterior
            af, ar, Ff, Fr, ff, fr, _, _ = forces(st.x[VY], st.x[R], delta[k], vx[k], st.w, M, wk)
            for i in range(nx):
                out.x[k, i] = st.x[i]
            out.slip[k, 0] = af
            out.slip[k, 1] = ar
            out.fnl[k, 0] = ff
            out.fnl[k, 1] = fr
            out.force[k, 0] = Ff
            out.force[k, 1] = Fr
            out.nis[k] = nis_row if dof_row > 0 else np.nan
            out.health[k] = int(st.hs[HS_CODE])
            if S.store_weights:
                for a in range(nw):
                    out.w[k, a] = st.w[a]
            if S.compute_std:
                for i in range(nx):  # sig_ii + ups_i P_w ups_i^T from the upper triangle of P_w
                    var = st.sig[i, i]
                    for a in range(nw):
                        ua = st.ups[i, a]
                        if ua != 0.0:
                            row = 0.0
                            for b in range(a + 1, nw):
                                row += st.pw[a, b] * st.ups[i, b]
                            var += ua * (st.pw[a, a] * ua + 2.0 * row)
                    out.std[k, i] = math.sqrt(max(var, 0.0))
        if k < n - 1 or predict_last:
            dt_row = t[k + 1] - tk if k < n - 1 else S.dt_last
            if shift:
                # the frames showing an instant of this interval, in order, then the rest of it
                done = 0.0
                while nf < n:
                    j, dtp = _frame_instant(t, nf, S.latency, H)
                    if j > k:
                        break
                    if dtp < done:
                        dtp = done
                    if dtp > done:
                        predict(st, dtp - done, delta[k] + dd * done, dd, vx[k] + ax[k] * done, ax[k],
                                kappa[k] + kd * done, kd, M, S, wk)  # fmt: skip
                    done = dtp
                    for c in range(N_CHANNELS):
                        zrow[c] = z[nf, c]
                    acc_f = t[nf] >= S.accumulate_from
                    nis, dof, n0, n1 = update(GROUP_CAMERA, st, delta[k] + dd * dtp, vx[k] + ax[k] * dtp, zrow, M, G, S, False,
                                              acc_f, acc, out.score, nf, wk)  # fmt: skip
                    if dof > 0:
                        _health_push(st, t[nf], nis, dof, S, M)
                        if acc_f and nf < acc.innov.shape[0]:
                            acc.innov[nf, 0] = n0
                            acc.innov[nf, 1] = n1
                    nf = _next_frame(z, nf + 1)
                if k < n - 1 or predict_last:
                    predict(st, dt_row - done, delta[k] + dd * done, dd, vx[k] + ax[k] * done, ax[k], kappa[k] + kd * done,
                            kd, M, S, wk)  # fmt: skip
            else:
                predict(st, dt_row, delta[k], dd, vx[k], ax[k], kappa[k], kd, M, S, wk)
    if S.mode == MODE_FIXED:  # the fit's normal matrix is accumulated in its upper triangle
        for a in range(nw):
            for b in range(a + 1, nw):
                acc.hess[b, a] = acc.hess[a, b]
