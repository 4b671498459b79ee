"""Compiled (numba) body-frame bicycle model for IMU-only logs and its multiple-shooting residuals.

The IMU counterpart of :mod:`._model` (same ``theta`` layout, same output columns where
the meaning is shared, same Gauss-Newton window fit). State ``x = [vy, r]``: lateral
velocity of the centre of gravity in the body frame [m/s] and yaw rate [rad/s]
(:mod:`tire_learning_env.imu.model`, exact for a time-varying ``vx``). Known inputs per
row: logged road-wheel steering ``delta`` [rad], speed ``vx`` [m/s] and longitudinal
acceleration ``ax`` [m/s^2] (specific force, smoothed; it only enters the longitudinal
load transfer)::

    delta_eff = delta(t - tau) (1 + q (delta / 0.1 rad)^2) + offset - c_s F_yf    (steering effects)
    alpha_f   = delta_eff - (vy + lf r) / vx,        alpha_r = (lr r - vy) / vx    (body-frame eq. 13)
    F_yi      = g_i F_i(alpha_i [lagged by relaxation]) (1 - k_i (a_y / g)^2)
    g_f       = s_f (1 - c_v vx^2) (1 - ax h / (g lr)),   g_r = s_r (1 - c_v vx^2) (1 + ax h / (g lf))
    m (vy_dot + vx r) = F_yf cos(delta_eff) + F_yr - m g sin(bank)
    s_Iz Iz r_dot     = lf F_yf cos(delta_eff) - lr F_yr

Measurements (channels ``CH_YAW``, ``CH_AY`` of :mod:`._model`)::

    yaw_rate = r + b_r
    a_y      = (1 + s_a) (F_yf cos(delta_eff) + F_yr) / m + b_a + x_a r_dot      (specific force: no bank)

(``s_a``: a body-fixed accelerometer that rolls with the body by ``phi = k a_y`` reads
``a_y + g sin(phi)``, to first order a scale error ``s_a = g k``; or a calibration error.)

Every effect is absent at :data:`._model.THETA_NOMINAL`. ``h`` is an *effective* CG
height: the axle forces are taken proportional to the axle loads (``F_z / F_z0``), so a
less than proportional load sensitivity shows as a smaller ``h``.
"""

from __future__ import annotations

import math
from enum import IntEnum
from pathlib import Path

import numpy as np
from numba import njit, prange

from .. import _kernels
from .._jit_cache import key_on_family
from .._kernels import V_IZ, V_LF, V_LR, V_M, bicycle_slip_angles, tire_force
from ._model import (
    CH_YAW,
    OUT_AY,
    OUT_YAW,
    RELAX_MIN,
    TH_ACC_OFFSET,
    TH_AY_BIAS,
    TH_AY_SCALE,
    TH_BANK,
    TH_IZ_SCALE,
    TH_LAT_LT_F,
    TH_LAT_LT_R,
    TH_LONG_LT,
    TH_RELAX,
    TH_SCALE_F,
    TH_SCALE_R,
    TH_SPEED_COEF,
    TH_STEER_COMP,
    TH_STEER_DELAY,
    TH_STEER_OFFSET,
    TH_STEER_QUICK,
    TH_YAW_BIAS,
    fd_column,
    fill_nan_after,
    gauss_newton_step,
    interval_inputs,
    rk4_update,
    stage_values,
    step_is_small,
    step_shrink,
    store_residuals,
    substep_fractions,
    tire_outputs,
    window_buffers,
)


class BodyState(IntEnum):
    """Components of the body-frame state ``x`` (a window's initial state ``x0``, its steps ``dx``)."""

    VY = 0  # lateral velocity at the CG [m/s]
    R = 1  # yaw rate [rad/s]


N_STATE = len(BodyState)
# per-row outputs of simulate_body_rows: columns 4..11 mean what they mean in _model (OUT_*)
OUT_VY = 0  # lateral velocity [m/s]
OUT_R = 1  # yaw rate (state, without the sensor bias) [rad/s]
OUT_VYD = 2  # lateral velocity derivative [m/s^2]
OUT_RD = 3  # yaw acceleration [rad/s^2]

_G = 9.81
#: reference road-wheel angle of the steering-ratio nonlinearity [rad]
STEER_REF = 0.1
#: smallest axle-force gain (a load-transfer or speed factor never flips a force's sign) [-]
GAIN_MIN = 0.02
#: the window fit keeps |vy| <= VY_LIMIT vx and |r| <= R_LIMIT [-], [rad/s]
VY_LIMIT = 0.4
R_LIMIT = 3.0


@njit(cache=True, nogil=True)
def logged_steer(tq, j, t, delta, dslope):
    """Logged steering at time ``tq`` (``delta[j] + dslope[j] (tq - t[j])`` of the row before ``tq``).

    ``j`` is where the search starts (the current row). Clamped at both ends of the log.
    """
    n = t.shape[0]
    if tq <= t[0]:
        return delta[0]
    while j > 0 and t[j] > tq:
        j -= 1
    while j < n - 1 and t[j + 1] <= tq:
        j += 1
    if j >= n - 1:
        return delta[n - 1]
    return delta[j] + dslope[j] * (tq - t[j])


@njit(cache=True, nogil=True)
def _front_force(a_kin, d0, cs, gain, tf, tabf):
    """Front axle force [N] and effective steering [rad] with steering compliance ``cs`` [rad/N].

    Solves ``F = gain F_f(a_kin + d0 - cs F)`` by Newton (``a_kin`` = slip without the steering).
    """
    F = gain * tire_force(a_kin + d0, tf, tabf)
    if cs == 0.0:
        return F, d0
    for _ in range(4):
        a = a_kin + d0 - cs * F
        fa = gain * tire_force(a, tf, tabf)
        slope = gain * (tire_force(a + 1e-5, tf, tabf) - tire_force(a - 1e-5, tf, tabf)) / 2e-5
        step = (F - fa) / (1.0 + cs * slope)
        F -= step
        if abs(step) < 1e-6:
            break
    return F, d0 - cs * F


@njit(cache=True, nogil=True)
def body_rhs(vy, r, laf, lar, dlog, vx, axl, veh, tf, tr, tabf, tabr, th):
    """Augmented body-frame right-hand side (module docstring).

    Returns ``(vy_dot, r_dot, dlag_f, dlag_r, alpha_f, alpha_r, F_yf, F_yr, a_y)``: kinematic
    slip angles [rad], axle forces [N] after every force effect, and the specific force
    ``a_y`` at the CG [m/s^2] without sensor effects.
    """
    m, lf, lr = veh[V_M], veh[V_LF], veh[V_LR]
    Iz = veh[V_IZ] * th[TH_IZ_SCALE]
    q = th[TH_STEER_QUICK]
    dr = dlog / STEER_REF
    d0 = dlog * (1.0 + q * dr * dr) + th[TH_STEER_OFFSET]
    gv = 1.0 - th[TH_SPEED_COEF] * vx * vx
    h = th[TH_LONG_LT]
    gain_f = th[TH_SCALE_F] * gv * (1.0 - axl * h / (_G * lr))
    gain_r = th[TH_SCALE_R] * gv * (1.0 + axl * h / (_G * lf))
    if gain_f < GAIN_MIN:
        gain_f = GAIN_MIN
    if gain_r < GAIN_MIN:
        gain_r = GAIN_MIN
    kin_f, ar = bicycle_slip_angles(vy, r, 0.0, vx, lf, lr)  # eq. (13) without the steering (added with its effects)
    cs = th[TH_STEER_COMP]
    sigma = th[TH_RELAX]
    if sigma > RELAX_MIN:
        # first-order slip lag, time constant sigma / vx; compliance acts on the current force
        Fyf = tire_force(laf, tf, tabf) * gain_f
        Fyr = tire_force(lar, tr, tabr) * gain_r
        deff = d0 - cs * Fyf
        af = deff + kin_f
        k = vx / sigma
        dlaf = k * (af - laf)
        dlar = k * (ar - lar)
    else:
        dlaf = 0.0
        dlar = 0.0
        Fyf, deff = _front_force(kin_f, d0, cs, gain_f, tf, tabf)
        af = deff + kin_f
        Fyr = tire_force(ar, tr, tabr) * gain_r
    cd = math.cos(deff)
    kf, kr = th[TH_LAT_LT_F], th[TH_LAT_LT_R]
    if kf != 0.0 or kr != 0.0:
        # lateral load transfer: axle forces drop by k (a_y / g)^2 (a_y before the drop)
        u = (Fyf * cd + Fyr) / (m * _G)
        u2 = u * u
        ff = 1.0 - kf * u2
        fr = 1.0 - kr * u2
        Fyf *= ff if ff > GAIN_MIN else GAIN_MIN
        Fyr *= fr if fr > GAIN_MIN else GAIN_MIN
    ay = (Fyf * cd + Fyr) / m
    vyd = ay - _G * math.sin(th[TH_BANK]) - vx * r
    rd = (lf * Fyf * cd - lr * Fyr) / Iz
    return vyd, rd, dlaf, dlar, af, ar, Fyf, Fyr, ay


@njit(cache=True, nogil=True)
def simulate_body_rows(x0, j0, j1, t, delta, dslope, vx, ax, veh, tf, tr, tabf, tabr, th, h_max, out):
    """Simulate rows ``j0..j1`` (inclusive) from ``x0 = [vy, r]`` at row ``j0``.

    Steering between rows: ``delta[j] + dslope[j] (t - t[j])`` read ``th[TH_STEER_DELAY]``
    seconds earlier; speed and ``ax`` linear between rows; RK4 sub-steps of at most
    ``h_max`` [s] (shorter when the slip lag is fast). Fills ``out[k, :]`` for row
    ``j0 + k`` (``OUT_VY, OUT_R, OUT_VYD, OUT_RD`` and the shared ``OUT_*`` columns, with
    ``OUT_YAW`` / ``OUT_AY`` the predicted *measurements*). Lag states start at the
    kinematic slip. Returns False if the state became non-finite (later rows NaN).
    """
    vy, r = x0[BodyState.VY], x0[BodyState.R]
    sigma = th[TH_RELAX]
    tau = th[TH_STEER_DELAY]
    lf, lr = veh[V_LF], veh[V_LR]
    v0 = vx[j0]
    d_start = logged_steer(t[j0] - tau, j0, t, delta, dslope) if tau != 0.0 else delta[j0]
    q = th[TH_STEER_QUICK]
    dr = d_start / STEER_REF
    laf, lar = bicycle_slip_angles(vy, r, d_start * (1.0 + q * dr * dr) + th[TH_STEER_OFFSET], v0, lf, lr)
    b_r, b_a, x_a, s_a = th[TH_YAW_BIAS], th[TH_AY_BIAS], th[TH_ACC_OFFSET], th[TH_AY_SCALE]
    n = j1 - j0 + 1
    for k in range(n):
        j = j0 + k
        last = k == n - 1
        dt = 0.0 if last else t[j + 1] - t[j]
        dlog = delta[j] if tau == 0.0 else logged_steer(t[j] - tau, j, t, delta, dslope)
        a1, b1, c1, d1, af, ar, Fyf, Fyr, ay = body_rhs(vy, r, laf, lar, dlog, vx[j], ax[j], veh, tf, tr, tabf, tabr, th)
        tire_outputs(out, k, af, ar, Fyf, Fyr, laf, lar, sigma)
        out[k, OUT_VY] = vy
        out[k, OUT_R] = r
        out[k, OUT_VYD] = a1
        out[k, OUT_RD] = b1
        out[k, OUT_YAW] = r + b_r
        out[k, OUT_AY] = ay * (1.0 + s_a) + b_a + x_a * b1
        if last:
            break
        n_sub, h, dd, dv, da = interval_inputs(j, dt, h_max, sigma, vx, dslope, ax)
        for i in range(n_sub):
            f0, f1, f2 = substep_fractions(i, n_sub)
            if tau == 0.0:
                d_0 = delta[j] + f0 * dd
                dm, db = stage_values(delta, j, dd, f1, f2)
            else:
                d_0 = logged_steer(t[j] + f0 * dt - tau, j, t, delta, dslope)
                dm = logged_steer(t[j] + f1 * dt - tau, j, t, delta, dslope)
                db = logged_steer(t[j] + f2 * dt - tau, j, t, delta, dslope)
            vm, vb = stage_values(vx, j, dv, f1, f2)
            am, ab = stage_values(ax, j, da, f1, f2)
            hh = 0.5 * h
            if i > 0:
                a1, b1, c1, d1, _, _, _, _, _ = body_rhs(
                    vy, r, laf, lar, d_0, vx[j] + f0 * dv, ax[j] + f0 * da, veh, tf, tr, tabf, tabr, th
                )
            a2, b2, c2, d2, _, _, _, _, _ = body_rhs(
                vy + hh * a1, r + hh * b1, laf + hh * c1, lar + hh * d1, dm, vm, am, veh, tf, tr, tabf, tabr, th
            )
            a3, b3, c3, d3, _, _, _, _, _ = body_rhs(
                vy + hh * a2, r + hh * b2, laf + hh * c2, lar + hh * d2, dm, vm, am, veh, tf, tr, tabf, tabr, th
            )
            a4, b4, c4, d4, _, _, _, _, _ = body_rhs(
                vy + h * a3, r + h * b3, laf + h * c3, lar + h * d3, db, vb, ab, veh, tf, tr, tabf, tabr, th
            )
            c = h / 6.0
            vy = rk4_update(vy, c, a1, a2, a3, a4)
            r = rk4_update(r, c, b1, b2, b3, b4)
            laf = rk4_update(laf, c, c1, c2, c3, c4)
            lar = rk4_update(lar, c, d1, d2, d3, d4)
        if not (math.isfinite(vy) and math.isfinite(r) and abs(vy) < 1e3 and abs(r) < 1e2):
            fill_nan_after(out, k, n)
            return False
    return True


@njit(cache=True, nogil=True)
def predict_body_measurements(traj, j0, meas_row, meas_chan, m0, m1, out):
    """Model predictions of measurements ``m0..m1-1`` (IMU channels read at their row)."""
    for mi in range(m0, m1):
        k = meas_row[mi] - j0
        out[mi - m0] = traj[k, OUT_YAW] if meas_chan[mi] == CH_YAW else traj[k, OUT_AY]


@njit(cache=True, nogil=True)
def _weighted_cost(base, meas_val, meas_w, m0, m1):
    c = 0.0
    for mi in range(m0, m1):
        r = meas_w[mi] * (meas_val[mi] - base[mi - m0])
        c += r * r
    return c


@njit(cache=True, parallel=True)
def body_window_residuals(
    th, x0_guess, win_sim, win_end, meas_ptr, meas_row, meas_chan, meas_val, meas_w,
    t, delta, dslope, vx, ax, veh, tf, tr, tabf, tabr, h_max, fd, max_step, tol, n_iter,
    resid, x0_out, jac, mode,
):  # fmt: skip
    """Weighted multiple-shooting residuals of the body-frame model (see :func:`._model.window_residuals`).

    Same modes (0: Jacobian at the guess, 1: given Jacobian, 2: converge, with the
    Jacobian refreshed every third step) with the two-dimensional initial state
    ``[vy, r]`` at the window's first measured row (``jac`` is (M, 2)). Every Gauss-Newton
    step is a descent step (halved up to four times until the window's cost does not
    increase; none taken otherwise), so the result is a deterministic local minimum even
    where a saturating or learned tire makes the cost non-quadratic, and every iterate is
    kept physical (``|vy| <= VY_LIMIT vx``, ``|r| <= R_LIMIT``).
    """
    n_win = win_sim.shape[0]
    for w in prange(n_win):
        j0, j1, m0, m1, traj, base, pert = window_buffers(win_sim, win_end, meas_ptr, w)
        nm = m1 - m0
        trial = np.empty(nm)
        vlim = VY_LIMIT * vx[j0]
        x = x0_guess[w].copy()
        x[BodyState.VY] = min(max(x[BodyState.VY], -vlim), vlim)
        x[BodyState.R] = min(max(x[BodyState.R], -R_LIMIT), R_LIMIT)
        ok = simulate_body_rows(x, j0, j1, t, delta, dslope, vx, ax, veh, tf, tr, tabf, tabr, th, h_max, traj)
        predict_body_measurements(traj, j0, meas_row, meas_chan, m0, m1, base)
        cost = _weighted_cost(base, meas_val, meas_w, m0, m1) if ok else np.inf
        xt = x.copy()
        for it in range(n_iter):
            if not ok:
                break
            if (it == 0 and mode == 0) or (mode == 2 and it % 3 == 0):
                for q in range(N_STATE):
                    xp = x.copy()
                    xp[q] += fd[q]
                    simulate_body_rows(xp, j0, j1, t, delta, dslope, vx, ax, veh, tf, tr, tabf, tabr, th, h_max, traj)
                    predict_body_measurements(traj, j0, meas_row, meas_chan, m0, m1, pert)
                    fd_column(jac, q, meas_w, pert, base, m0, m1, fd[q])
            dx = gauss_newton_step(jac, meas_val, meas_w, base, m0, m1, N_STATE)
            if mode == 2 and step_is_small(dx, tol):
                break
            shrink = step_shrink(dx, max_step)
            accepted = False
            for _ in range(5):
                xt[BodyState.VY] = min(max(x[BodyState.VY] + shrink * dx[BodyState.VY], -vlim), vlim)
                xt[BodyState.R] = min(max(x[BodyState.R] + shrink * dx[BodyState.R], -R_LIMIT), R_LIMIT)
                good = simulate_body_rows(xt, j0, j1, t, delta, dslope, vx, ax, veh, tf, tr, tabf, tabr, th, h_max, traj)
                if good:
                    predict_body_measurements(traj, j0, meas_row, meas_chan, m0, m1, trial)
                    ct = _weighted_cost(trial, meas_val, meas_w, m0, m1)
                    if ct <= cost:
                        accepted = True
                        break
                shrink *= 0.5
            if not accepted:
                break  # no descent along the Gauss-Newton direction: x is a local minimum
            x[BodyState.VY], x[BodyState.R] = xt[BodyState.VY], xt[BodyState.R]
            cost = ct
            for mi in range(nm):
                base[mi] = trial[mi]
        for a in range(N_STATE):
            x0_out[w, a] = x[a]
        store_residuals(resid, meas_val, meas_w, base, m0, m1, ok)


#: the files whose compiled code (and frozen constants) this module's compiled functions reach: an edit to any
#: of them invalidates this module's numba cache (:func:`tire_learning_env._jit_cache.key_on_family`)
BODY_MODEL_FAMILY = (Path(_kernels.__file__), Path(__file__).with_name("_model.py"), Path(__file__))
key_on_family(globals(), BODY_MODEL_FAMILY)
