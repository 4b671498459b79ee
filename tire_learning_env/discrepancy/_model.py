"""Compiled (numba) augmented bicycle model and multiple-shooting residuals.

Pure functions of arrays. The *augmented model* is the error-coordinate bicycle model of
SPEC §1 (eqs. 1, 5, 13) with a tire model (linear, Pacejka or tabulated, evaluated by
:func:`tire_learning_env._kernels.tire_force`) and every candidate effect of
:mod:`.effects` switched on or off by one parameter vector ``theta`` (layout ``TH_*``;
:data:`THETA_NOMINAL` is the plain model).

The residual is a **multiple-shooting output error**: the log is cut into windows; in
each window the model is simulated open loop (classical RK4, inputs held / interpolated
between rows) from an initial state that is fitted to that window's own measurements by
Gauss-Newton (:func:`window_residuals`). Open-loop drift is therefore bounded by the window
length, and the residual of a correct model is the measurement noise (minus its projection
on the four initial-state directions).

Measurement channels (``CH_*``): camera ``e1`` [m] and ``e2`` [rad] (a frame delivered at
``t`` shows the state at ``t - latency``; ``e2`` carries the heading bias), IMU yaw rate
[rad/s] and lateral acceleration (specific force) [m/s^2].
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numba import njit, prange

from .. import _kernels
from .._jit_cache import key_on_family
from .._kernels import V_CAMERA_X, V_HCG, V_IZ, V_LF, V_LR, V_M, V_TRACK, bicycle_slip_angles, tire_force

# theta layout: one entry per physical parameter of the effect library
(
    TH_RELAX,  # tire relaxation length [m]
    TH_LATENCY,  # camera latency [s]
    TH_BANK,  # road bank angle [rad]
    TH_STEER_OFFSET,  # steering-angle offset [rad]
    TH_E2_BIAS,  # camera heading bias [rad]
    TH_SCALE_F,  # front cornering-stiffness scale [-]
    TH_SCALE_R,  # rear cornering-stiffness scale [-]
    TH_LOAD_TRANSFER,  # lateral load-transfer strength [-]
    TH_WIND,  # constant lateral force at the CG [N]
    TH_SPEED_COEF,  # speed-dependent stiffness coefficient [s^2/m^2]
    # entries used by the body-frame model of IMU-only logs only (:mod:`._body_model`)
    TH_LONG_LT,  # longitudinal load transfer: effective CG height [m]
    TH_LAT_LT_F,  # lateral load transfer: front axle force loss at |a_y| = 1 g [-]
    TH_LAT_LT_R,  # lateral load transfer: rear axle force loss at |a_y| = 1 g [-]
    TH_STEER_QUICK,  # steering-ratio nonlinearity: relative extra road-wheel angle at 0.1 rad [-]
    TH_STEER_COMP,  # steering compliance: road-wheel angle lost per newton of front axle force [rad/N]
    TH_YAW_BIAS,  # yaw-rate sensor bias [rad/s]
    TH_AY_BIAS,  # lateral accelerometer bias [m/s^2]
    TH_IZ_SCALE,  # yaw inertia scale [-]
    TH_ACC_OFFSET,  # accelerometer position ahead of the CG [m]
    TH_STEER_DELAY,  # steering signal delay relative to the IMU [s]
    TH_AY_SCALE,  # lateral accelerometer scale error (roll-induced gravity component) [-]
    # road geometry and sensor/steering effects of the camera model (issue 18)
    TH_SUPER_RATE,  # superelevation per unit path curvature [rad m] (the outer edge raised)
    TH_SUPER_CAP,  # largest superelevation [rad]
    TH_E2_DRIFT,  # drift rate of the camera heading bias [rad/s] (about each window's middle)
    TH_STEER_RATIO,  # steering-ratio error: road-wheel angle = (1 + this) * logged delta [-]
) = range(25)
N_THETA = 25
THETA_NOMINAL = np.array(
    [0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0,
     0.0, 0.1, 0.0, 0.0]
)

# measurement channels
CH_E1, CH_E2, CH_YAW, CH_AY = range(4)
CHANNELS = ("e1", "e2", "yaw_rate", "ay")
# per-row outputs of simulate_rows
(
    OUT_E1,
    OUT_E1D,
    OUT_E2,
    OUT_E2D,
    OUT_YAW,
    OUT_AY,
    OUT_ALPHA_F,  # kinematic slip angle [rad] (eq. 13, with the steering offset)
    OUT_ALPHA_R,
    OUT_FYF,  # axle force [N] (lagged when relaxation is on)
    OUT_FYR,
    OUT_LAG_F,  # lagged slip [rad] (equals the kinematic slip without relaxation)
    OUT_LAG_R,
) = range(12)
N_OUT = 12
# columns of a block of rows (``blk_rows[b]`` of :func:`steering_sensitivity`, built by :mod:`.noise`)
(
    BLK_FIRST,  # the block's first row
    BLK_STOP,  # the row after its last one (excluded)
) = range(2)

_G = 9.81
#: relaxation lengths at or below this act instantly (time constant < 0.4 ms at 25 m/s) [m]
RELAX_MIN = 0.01


@njit(cache=True, nogil=True)
def road_bank(th, kappa):
    """Bank angle of the road [rad] (positive raises the left edge) at path curvature ``kappa`` [1/m].

    A constant crossfall ``th[TH_BANK]`` plus the superelevation of a curve, which raises the
    outer edge in proportion to the curvature up to a cap (road design:
    ``e = min(rate |kappa|, e_max)``): ``crossfall - sign(kappa) min(rate |kappa|, cap)``.
    """
    rate = th[TH_SUPER_RATE]
    if rate == 0.0:
        return th[TH_BANK]
    e = abs(rate * kappa)
    cap = th[TH_SUPER_CAP]
    if e > cap:
        e = cap
    if rate * kappa > 0.0:
        return th[TH_BANK] - e
    return th[TH_BANK] + e


@njit(cache=True, nogil=True)
def model_rhs(e1d, e2, e2d, laf, lar, delta, vx, ax, pdd, pddd, veh, tf, tr, tabf, tabr, th):
    """Augmented bicycle right-hand side in error coordinates (SPEC §1, eqs. 1, 5, 13).

    Returns ``(e1_ddot, e2_ddot, dlag_f, dlag_r, alpha_f, alpha_r, F_yf, F_yr)``: the
    kinematic slip angles [rad] and the axle forces [N] (after every force effect).
    """
    m, Iz, lf, lr = veh[V_M], veh[V_IZ], veh[V_LF], veh[V_LR]
    vy = e1d - vx * e2
    r = e2d + pdd
    # eq. (13) + steering offset and steering-ratio error
    af, ar = bicycle_slip_angles(vy, r, delta * (1.0 + th[TH_STEER_RATIO]) + th[TH_STEER_OFFSET], vx, lf, lr)
    gain_f = th[TH_SCALE_F] * (1.0 - th[TH_SPEED_COEF] * vx * vx)
    gain_r = th[TH_SCALE_R] * (1.0 - th[TH_SPEED_COEF] * vx * vx)
    sigma = th[TH_RELAX]
    if sigma > RELAX_MIN:
        # first-order slip lag, time constant sigma / vx
        k = vx / sigma
        dlaf = k * (af - laf)
        dlar = k * (ar - lar)
        Fyf = tire_force(laf, tf, tabf) * gain_f
        Fyr = tire_force(lar, tr, tabr) * gain_r
    else:
        dlaf = 0.0
        dlar = 0.0
        Fyf = tire_force(af, tf, tabf) * gain_f
        Fyr = tire_force(ar, tr, tabr) * gain_r
    lt = th[TH_LOAD_TRANSFER]
    if lt != 0.0:
        # relative lateral load transfer r = |a_y| h_cg / (g track); force drops by lt r^2 / 2
        rf = abs((Fyf + Fyr) / m) * veh[V_HCG] / (_G * veh[V_TRACK])
        fac = 1.0 - 0.5 * lt * rf * rf
        Fyf *= fac
        Fyr *= fac
    f_ext = th[TH_WIND] - m * _G * math.sin(road_bank(th, pdd / vx))
    e1dd = (Fyf + Fyr + f_ext) / m - vx * pdd + ax * e2  # eq. (1)
    e2dd = (lf * Fyf - lr * Fyr) / Iz - pddd  # eq. (5)
    return e1dd, e2dd, dlaf, dlar, af, ar, Fyf, Fyr


@njit(cache=True, nogil=True)
def substep_count(dt, h_max, sigma, v_max):
    """RK4 sub-steps for an interval ``dt`` [s]: steps of at most ``h_max`` [s], more when a slip
    lag (relaxation length ``sigma`` [m] at speeds up to ``v_max`` [m/s]) is faster; at least one."""
    n_sub = int(math.ceil(dt / h_max - 1e-9))
    if sigma > RELAX_MIN:
        n_fast = int(math.ceil(dt * v_max / sigma / 1.5))
        if n_fast > n_sub:
            n_sub = n_fast
    return n_sub if n_sub >= 1 else 1


@njit(cache=True, nogil=True)
def fill_nan_after(out, k, n):
    """Mark rows ``k + 1 .. n - 1`` of a simulation output as NaN (the state blew up at row ``k``)."""
    for kk in range(k + 1, n):
        for q in range(out.shape[1]):
            out[kk, q] = math.nan


@njit(cache=True, nogil=True)
def window_buffers(win_sim, win_end, meas_ptr, w):
    """Window ``w``'s rows and measurements and its work arrays (shared by the window kernels of this
    module and :mod:`._body_model`): ``(j0, j1, m0, m1, traj (rows, N_OUT), base (nm,), pert (nm,))``."""
    j0 = win_sim[w]
    j1 = win_end[w]
    m0 = meas_ptr[w]
    m1 = meas_ptr[w + 1]
    return j0, j1, m0, m1, np.empty((j1 - j0 + 1, N_OUT)), np.empty(m1 - m0), np.empty(m1 - m0)


@njit(cache=True, nogil=True)
def tire_outputs(out, k, af, ar, Fyf, Fyr, laf, lar, sigma):
    """Row ``k``'s slip, axle-force and lagged-slip columns (``OUT_ALPHA_F`` .. ``OUT_LAG_R``)."""
    out[k, OUT_ALPHA_F] = af
    out[k, OUT_ALPHA_R] = ar
    out[k, OUT_FYF] = Fyf
    out[k, OUT_FYR] = Fyr
    out[k, OUT_LAG_F] = laf if sigma > RELAX_MIN else af
    out[k, OUT_LAG_R] = lar if sigma > RELAX_MIN else ar


@njit(cache=True, nogil=True)
def interval_inputs(j, dt, h_max, sigma, vx, dslope, u):
    """RK4 plan of the row interval ``j`` (length ``dt``): ``(n_sub, h, d_delta, d_vx, d_u)``, the sub-step
    count and length, and the changes of the steering, the speed and a third input ``u`` that is linear
    between rows (``psi_dot_des`` for the camera model, ``ax`` for the body-frame model) over the interval."""
    n_sub = substep_count(dt, h_max, sigma, max(vx[j], vx[j + 1]))
    return n_sub, dt / n_sub, dslope[j] * dt, vx[j + 1] - vx[j], u[j + 1] - u[j]


@njit(cache=True, nogil=True)
def stage_values(x, j, dx, f1, f2):
    """An input that is linear over row interval ``j`` (change ``dx``) at the fractions ``f1`` and ``f2`` of it."""
    return x[j] + f1 * dx, x[j] + f2 * dx


@njit(cache=True, nogil=True)
def substep_fractions(i, n_sub):
    """Start, middle and end of RK4 sub-step ``i`` of ``n_sub`` as fractions of the row interval."""
    return i / n_sub, (i + 0.5) / n_sub, (i + 1.0) / n_sub


@njit(cache=True, nogil=True)
def rk4_update(x, c, k1, k2, k3, k4):
    """Classical RK4 combination ``x + c (k1 + 2 k2 + 2 k3 + k4)`` with ``c = h / 6``."""
    return x + c * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


@njit(cache=True, nogil=True)
def fd_column(out, col, meas_w, pert, base, m0, m1, h):
    """Column ``col`` of a weighted finite-difference sensitivity: ``meas_w (pert - base) / h``."""
    for mi in range(m0, m1):
        out[mi, col] = meas_w[mi] * (pert[mi - m0] - base[mi - m0]) / h


@njit(cache=True, nogil=True)
def gauss_newton_step(jac, meas_val, meas_w, base, m0, m1, n_state):
    """Gauss-Newton step of a window's initial state on the weighted residual ``meas_w (y - base)``
    (normal equations, regularised by 1e-10 of their trace)."""
    A = np.zeros((n_state, n_state))
    g = np.zeros(n_state)
    for mi in range(m0, m1):
        r = meas_w[mi] * (meas_val[mi] - base[mi - m0])
        for a in range(n_state):
            g[a] += jac[mi, a] * r
            for b in range(n_state):
                A[a, b] += jac[mi, a] * jac[mi, b]
    tr_a = 0.0
    for a in range(n_state):
        tr_a += A[a, a]
    for a in range(n_state):
        A[a, a] += 1e-10 * tr_a + 1e-300
    return np.linalg.solve(A, g)


@njit(cache=True, nogil=True)
def step_is_small(dx, tol):
    """No component of the step exceeds its tolerance."""
    for a in range(dx.shape[0]):
        if abs(dx[a]) > tol[a]:
            return False
    return True


@njit(cache=True, nogil=True)
def step_shrink(dx, max_step):
    """Factor that limits every component of the step to ``max_step`` (1 if none exceeds it)."""
    shrink = 1.0
    for a in range(dx.shape[0]):
        if abs(dx[a]) * shrink > max_step[a]:
            shrink = max_step[a] / abs(dx[a])
    return shrink


@njit(cache=True, nogil=True)
def store_residuals(resid, meas_val, meas_w, base, m0, m1, ok):
    """The window's weighted residual ``meas_w (y - base)``, or 1e3 everywhere when its simulation diverged."""
    if ok and m1 > m0:
        for mi in range(m0, m1):
            resid[mi] = meas_w[mi] * (meas_val[mi] - base[mi - m0])
    else:
        for mi in range(m0, m1):
            resid[mi] = 1e3  # a diverged simulation: huge but finite residual


@njit(cache=True, nogil=True)
def simulate_rows(x0, j0, j1, t, delta, dslope, vx, pdd, veh, tf, tr, tabf, tabr, th, h_max, out):
    """Simulate rows ``j0..j1`` (inclusive) from the error state ``x0`` (4,) at row ``j0``.

    Between rows ``j`` and ``j + 1`` the steering is ``delta[j] + dslope[j] (t - t[j])``
    (:func:`.data.steering_slope`), speed and desired yaw rate are linear in time (so
    ``ax`` and ``psi_ddot_des`` are their slopes),
    and RK4 sub-steps are at most ``h_max`` [s] (shorter when the slip lag is fast).
    Fills ``out[k, OUT_*]`` for row ``j0 + k``; the lag states start at the kinematic slip.
    Returns False if the state became non-finite (rows after that are NaN).
    """
    e1, e1d, e2, e2d = x0[0], x0[1], x0[2], x0[3]
    sigma = th[TH_RELAX]
    # lag states start in steady state
    v0 = vx[j0]
    vy0 = e1d - v0 * e2
    r0 = e2d + pdd[j0]
    laf, lar = bicycle_slip_angles(vy0, r0, delta[j0] * (1.0 + th[TH_STEER_RATIO]) + th[TH_STEER_OFFSET], v0, veh[V_LF],
                                   veh[V_LR])  # fmt: skip
    m = veh[V_M]
    n = j1 - j0 + 1
    for k in range(n):
        j = j0 + k
        last = k == n - 1
        if last:
            dt, ax, pddd = 0.0, 0.0, 0.0
        else:
            dt = t[j + 1] - t[j]
            ax = (vx[j + 1] - vx[j]) / dt
            pddd = (pdd[j + 1] - pdd[j]) / dt
        # the row's outputs; also the first RK4 stage of the step that follows
        a1, b1, c1, d1, af, ar, Fyf, Fyr = model_rhs(
            e1d, e2, e2d, laf, lar, delta[j], vx[j], ax, pdd[j], pddd, veh, tf, tr, tabf, tabr, th
        )
        out[k, OUT_E1] = e1
        out[k, OUT_E1D] = e1d
        out[k, OUT_E2] = e2
        out[k, OUT_E2D] = e2d
        out[k, OUT_YAW] = e2d + pdd[j]
        out[k, OUT_AY] = (Fyf + Fyr + th[TH_WIND]) / m
        tire_outputs(out, k, af, ar, Fyf, Fyr, laf, lar, sigma)
        if last:
            break
        n_sub, h, dd, dv, dp = interval_inputs(j, dt, h_max, sigma, vx, dslope, pdd)
        for i in range(n_sub):
            f0, f1, f2 = substep_fractions(i, n_sub)
            dm, db = stage_values(delta, j, dd, f1, f2)
            vm, vb = stage_values(vx, j, dv, f1, f2)
            pm, pb = stage_values(pdd, j, dp, f1, f2)
            hh = 0.5 * h
            if i > 0:
                a1, b1, c1, d1, _, _, _, _ = model_rhs(
                    e1d, e2, e2d, laf, lar, delta[j] + f0 * dd, vx[j] + f0 * dv, ax, pdd[j] + f0 * dp, pddd,
                    veh, tf, tr, tabf, tabr, th,
                )  # fmt: skip
            v2, w2 = e1d + hh * a1, e2d + hh * b1
            a2, b2, c2, d2, _, _, _, _ = model_rhs(
                v2, e2 + hh * e2d, w2, laf + hh * c1, lar + hh * d1, dm, vm, ax, pm, pddd, veh, tf, tr, tabf, tabr, th
            )
            v3, w3 = e1d + hh * a2, e2d + hh * b2
            a3, b3, c3, d3, _, _, _, _ = model_rhs(
                v3, e2 + hh * w2, w3, laf + hh * c2, lar + hh * d2, dm, vm, ax, pm, pddd, veh, tf, tr, tabf, tabr, th
            )
            v4, w4 = e1d + h * a3, e2d + h * b3
            a4, b4, c4, d4, _, _, _, _ = model_rhs(
                v4, e2 + h * w3, w4, laf + h * c3, lar + h * d3, db, vb, ax, pb, pddd, veh, tf, tr, tabf, tabr, th
            )
            c = h / 6.0
            e1 = rk4_update(e1, c, e1d, v2, v3, v4)
            e1d = rk4_update(e1d, c, a1, a2, a3, a4)
            e2 = rk4_update(e2, c, e2d, w2, w3, w4)
            e2d = rk4_update(e2d, c, b1, b2, b3, b4)
            laf = rk4_update(laf, c, c1, c2, c3, c4)
            lar = rk4_update(lar, c, d1, d2, d3, d4)
        if not (math.isfinite(e1) and math.isfinite(e1d) and math.isfinite(e2) and math.isfinite(e2d)):
            fill_nan_after(out, k, n)
            return False
    return True


@njit(cache=True, nogil=True)
def _hermite(t0, t1, y0, y1, d0, d1, tq):
    """Cubic Hermite interpolation of ``y`` (slopes ``d``) at ``tq`` in ``[t0, t1]``."""
    h = t1 - t0
    s = (tq - t0) / h
    s2 = s * s
    s3 = s2 * s
    return (2 * s3 - 3 * s2 + 1) * y0 + (s3 - 2 * s2 + s) * h * d0 + (-2 * s3 + 3 * s2) * y1 + (s3 - s2) * h * d1


@njit(cache=True, nogil=True)
def predict_measurements(traj, j0, t, th, veh, meas_row, meas_chan, m0, m1, out):
    """Model predictions of measurements ``m0..m1-1`` into ``out[0..m1-m0-1]``.

    ``traj`` is a trajectory (:func:`simulate_rows`) starting at row ``j0``.
    Camera channels are read at ``t - latency`` (cubic Hermite between rows, using the
    state derivatives); ``e2`` gets the heading bias. A camera ``veh[V_CAMERA_X]`` ahead of
    the CG sees ``e1 + x sin(e2)`` (the path's own bend over ``x`` is added onto the logged
    ``e1`` by :func:`.data.prepare`). IMU channels are read at ``t``.
    """
    tau = th[TH_LATENCY]
    xc = veh[V_CAMERA_X]
    n = traj.shape[0]
    # the heading-bias drift is measured about the middle of the log's time span, t_mid
    t_mid = 0.5 * (t[0] + t[t.shape[0] - 1])
    for mi in range(m0, m1):
        o = mi - m0
        j = meas_row[mi]
        ch = meas_chan[mi]
        k = j - j0
        if ch == CH_YAW:
            out[o] = traj[k, OUT_YAW]
            continue
        if ch == CH_AY:
            out[o] = traj[k, OUT_AY]
            continue
        if tau > 0.0:
            tq = t[j] - tau
            kk = k
            while kk > 0 and t[j0 + kk] > tq:
                kk -= 1
            if kk >= n - 1:
                kk = n - 2
            ta, tb = t[j0 + kk], t[j0 + kk + 1]
            if tq < ta:
                tq = ta
            if ch == CH_E1:
                y0, y1, d0, d1 = traj[kk, OUT_E1], traj[kk + 1, OUT_E1], traj[kk, OUT_E1D], traj[kk + 1, OUT_E1D]
                val = _hermite(ta, tb, y0, y1, d0, d1, tq)
                if xc != 0.0:
                    y0, y1, d0, d1 = traj[kk, OUT_E2], traj[kk + 1, OUT_E2], traj[kk, OUT_E2D], traj[kk + 1, OUT_E2D]
                    val += xc * math.sin(_hermite(ta, tb, y0, y1, d0, d1, tq))
            else:
                y0, y1, d0, d1 = traj[kk, OUT_E2], traj[kk + 1, OUT_E2], traj[kk, OUT_E2D], traj[kk + 1, OUT_E2D]
                val = _hermite(ta, tb, y0, y1, d0, d1, tq)
        else:
            val = traj[k, OUT_E1] if ch == CH_E1 else traj[k, OUT_E2]
            if ch == CH_E1 and xc != 0.0:
                val += xc * math.sin(traj[k, OUT_E2])
        if ch == CH_E2:
            val += th[TH_E2_BIAS] + th[TH_E2_DRIFT] * (t[j] - t_mid)
        out[o] = val


@njit(cache=True, parallel=True)
def window_residuals(
    th, x0_guess, win_sim, win_end, meas_ptr, meas_row, meas_chan, meas_val, meas_w,
    t, delta, dslope, vx, pdd, veh, tf, tr, tabf, tabr, h_max, fd, max_step, tol, n_iter,
    resid, x0_out, jac, mode,
):  # fmt: skip
    """Weighted multiple-shooting residuals ``meas_w * (y - y_model)`` for every measurement.

    For each window ``w`` (rows ``win_sim[w]..win_end[w]``, measurements
    ``meas_ptr[w]..meas_ptr[w+1]-1``) the initial error state is fitted by Gauss-Newton
    from ``x0_guess[w]`` (each step shrunk so that no component exceeds ``max_step``)
    with a finite-difference Jacobian (steps ``fd``; ``e1`` does not enter the dynamics,
    so its column is exact). ``mode``:

    - 0: ``n_iter`` steps, Jacobian at the guess (``1 + 3 + n_iter`` simulations);
    - 1: ``n_iter`` steps with the given ``jac`` (``1 + n_iter`` simulations), a
      fixed-Jacobian Gauss-Newton (the score statistic's secants);
    - 2: converge: fresh Jacobian on the first two steps and while steps are large, at most ``n_iter``
      steps, stop when every step component is below ``tol``.

    Fills ``resid`` (M,), the fitted initial states ``x0_out`` (W, 4) and the weighted
    Jacobian of the predictions w.r.t. the initial state ``jac`` (M, 4) (used for the
    null distribution). A window whose simulation blows up gets residuals of 1e3.
    """
    n_win = win_sim.shape[0]
    for w in prange(n_win):
        j0, j1, m0, m1, traj, base, pert = window_buffers(win_sim, win_end, meas_ptr, w)
        x = x0_guess[w].copy()
        ok = True
        far = True
        for it in range(n_iter + 1):
            good = simulate_rows(x, j0, j1, t, delta, dslope, vx, pdd, veh, tf, tr, tabf, tabr, th, h_max, traj)
            predict_measurements(traj, j0, t, th, veh, meas_row, meas_chan, m0, m1, base)
            if not good:
                ok = False
                break
            if it == n_iter:
                break
            # mode 2 refreshes the Jacobian on the first two steps and while the steps are large: the model is
            # nearly linear in its initial state, so later steps with the Jacobian of an almost converged state
            # land on the same optimum (to second order) at a quarter of the cost
            if (it == 0 and mode == 0) or (mode == 2 and (it < 2 or far)):
                for mi in range(m0, m1):
                    jac[mi, 0] = meas_w[mi] if meas_chan[mi] == CH_E1 else 0.0
                for q in range(1, 4):
                    xp = x.copy()
                    xp[q] += fd[q]
                    simulate_rows(xp, j0, j1, t, delta, dslope, vx, pdd, veh, tf, tr, tabf, tabr, th, h_max, traj)
                    predict_measurements(traj, j0, t, th, veh, meas_row, meas_chan, m0, m1, pert)
                    fd_column(jac, q, meas_w, pert, base, m0, m1, fd[q])
            dx = gauss_newton_step(jac, meas_val, meas_w, base, m0, m1, 4)
            if mode == 2 and step_is_small(dx, tol):
                break  # the residual at x is converged (the step changes it to second order only)
            # limit the step to a physically plausible change (the model is far from linear beyond)
            shrink = step_shrink(dx, max_step)
            far = False
            for a in range(4):
                if abs(dx[a]) > 1e3 * tol[a]:
                    far = True
            for a in range(4):
                x[a] += shrink * dx[a]
        for a in range(4):
            x0_out[w, a] = x[a]
        store_residuals(resid, meas_val, meas_w, base, m0, m1, ok)


@njit(cache=True, parallel=True)
def steering_sensitivity(
    th, x0, win_sim, win_end, meas_ptr, meas_row, meas_chan, meas_w, blk_ptr, blk_rows,
    t, delta, dslope, vx, pdd, veh, tf, tr, tabf, tabr, h_max, h, out,
):  # fmt: skip
    """Weighted sensitivity of every window's predictions to a steering error held over a block of rows.

    For window ``w`` and block ``b`` (blocks ``blk_ptr[w]..blk_ptr[w+1]-1``, each the rows
    ``blk_rows[b, BLK_FIRST] .. blk_rows[b, BLK_STOP] - 1``, i.e. the intervals that start on them), the
    road-wheel angle is raised by ``h`` [rad] over the block's intervals and the window is
    simulated from its fitted state ``x0[w]`` (the initial state held). Fills
    ``out[m, b - blk_ptr[w]]`` = ``meas_w[m] d y_model[m] / d e_b`` for the window's
    measurements ``m`` (``out`` has as many columns as the largest block count).
    Used by :mod:`.noise` for the errors-in-variables model of the steering between rows.
    """
    n_win = win_sim.shape[0]
    for w in prange(n_win):
        j0, j1, m0, m1, traj, base, pert = window_buffers(win_sim, win_end, meas_ptr, w)
        dl = delta.copy()
        xw = x0[w].copy()
        simulate_rows(xw, j0, j1, t, dl, dslope, vx, pdd, veh, tf, tr, tabf, tabr, th, h_max, traj)
        predict_measurements(traj, j0, t, th, veh, meas_row, meas_chan, m0, m1, base)
        for b in range(blk_ptr[w], blk_ptr[w + 1]):
            ra = blk_rows[b, BLK_FIRST]
            rb = blk_rows[b, BLK_STOP]
            for j in range(ra, rb):
                dl[j] += h
            simulate_rows(xw, j0, j1, t, dl, dslope, vx, pdd, veh, tf, tr, tabf, tabr, th, h_max, traj)
            predict_measurements(traj, j0, t, th, veh, meas_row, meas_chan, m0, m1, pert)
            for j in range(ra, rb):
                dl[j] = delta[j]
            fd_column(out, b - blk_ptr[w], meas_w, pert, base, m0, m1, h)


#: the files whose compiled code (and frozen constants) this module's compiled functions reach: an edit to any
#: of them invalidates this module's numba cache (:func:`tire_learning_env._jit_cache.key_on_family`)
MODEL_FAMILY = (Path(_kernels.__file__), Path(__file__))
key_on_family(globals(), MODEL_FAMILY)
