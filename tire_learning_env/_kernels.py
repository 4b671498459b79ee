"""Compiled (numba) building blocks of the physics loop.

Every function here is a pure function of floats and arrays, compiled with
``numba.njit(cache=True)`` and callable from Python as well. They are the single
implementation of

- the truth bicycle model's right-hand side and RK4 step (:func:`bicycle_rk4_step`),
- the lane camera's frame/latency/noise logic (:func:`camera_tick`),
- the lane-keeping driver (:func:`driver_steer`),
- the road-table lookup (:func:`road_lookup`),

and :func:`advance_bicycle` strings them together for a whole chunk of ticks, which is
what makes the environments fast. :class:`~tire_learning_env.simulation.Simulator`
runs the same sequence in Python for any other plant; a test checks both give the
same log.

Array layouts are named by the ``V_*``, ``T_*``, ``X_*``, ``CAM_*`` and ``DRV_*`` indices.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# vehicle vector
V_M, V_IZ, V_LF, V_LR, V_CF, V_CR, V_HCG, V_TRACK, V_FZF, V_FZR = range(10)
N_VEHICLE = 10
# tire vector: kind and coefficients (linear: k; pacejka: B, C, D, E; table: a_min, a_step)
TIRE_LINEAR, TIRE_PACEJKA, TIRE_TABLE = 0.0, 1.0, 2.0
N_TIRE = 5
# effects vector (PlantEffects)
(
    X_RELAX,
    X_STEER_OFFSET,
    X_BANK,
    X_WIND_F,
    X_WIND_ARM,
    X_SCALE_F,
    X_SCALE_R,
    X_LOAD_TRANSFER,
) = range(8)
N_EFFECTS = 8
# camera parameter vector and state vector
CAM_RATE, CAM_LATENCY, CAM_E1_BIAS, CAM_E2_BIAS = range(4)
CAMS_NEXT, CAMS_LATEST_E1, CAMS_LATEST_E2, CAMS_LATEST_TIME = range(4)
# camera counters (int64): noise index, pending head, pending count
CAMC_NOISE, CAMC_HEAD, CAMC_COUNT = range(3)
# driver parameter vector: gain, lookahead time, integral gain, max steering, L, K_us, lr, lf m/(2 Cr L)
DRV_GAIN, DRV_TLA, DRV_KI, DRV_MAX, DRV_L, DRV_KUS, DRV_LR, DRV_E2COEF = range(8)
N_DRIVER = 8
#: Layout of the steering a_y guard (:func:`guard_steering`): limit [m/s^2] (inf: off), lowest and
#: highest steering-to-a_y gain [m/s^2/rad], the last IMU a_y [m/s^2].
GUARD_LIMIT, GUARD_GAIN_LOW, GUARD_GAIN_HIGH, GUARD_AY = range(4)
N_GUARD = 4
# one row of a simulation log
LOG_COLUMNS = (
    "t", "delta", "vx", "ax", "kappa", "psi_dot_des", "psi_ddot_des", "e1", "e2", "yaw_rate", "ay",
    "true_e1", "true_e1_dot", "true_e2", "true_e2_dot", "alpha_f", "alpha_r", "Fyf", "Fyr", "s",
)  # fmt: skip
N_LOG = len(LOG_COLUMNS)
_GRAVITY = 9.81
_EPS = 1e-9


@njit(cache=True)
def tire_force(alpha: float, tire: np.ndarray, table: np.ndarray) -> float:
    """Axle lateral force [N] of a tire vector (linear, Pacejka or tabulated)."""
    kind = tire[0]
    if kind == TIRE_LINEAR:
        return tire[1] * alpha
    if kind == TIRE_PACEJKA:
        B, C, D, E = tire[1], tire[2], tire[3], tire[4]
        x = B * alpha
        return D * math.sin(C * math.atan(x - E * (x - math.atan(x))))
    # tabulated: linear interpolation on a uniform slip grid, clamped at the ends
    u = (alpha - tire[1]) / tire[2]
    n = table.shape[0]
    if u <= 0.0:
        return table[0]
    if u >= n - 1:
        return table[n - 1]
    i = int(u)
    f = u - i
    return table[i] + f * (table[i + 1] - table[i])


@njit(cache=True)
def bicycle_rhs(e1d, e2, e2d, laf, lar, delta, vx, ax, pdd, pddd, veh, tf, tr, tabf, tabr, eff):
    """Right-hand side of the truth bicycle model in error coordinates (SPEC §1, eqs. 1, 5, 13).

    Returns ``(e1_ddot, e2_ddot, dlag_f, dlag_r, alpha_f, alpha_r, F_yf, F_yr)``.
    """
    m, Iz, lf, lr = veh[V_M], veh[V_IZ], veh[V_LF], veh[V_LR]
    vy = e1d - vx * e2
    r = e2d + pdd
    af = delta + eff[X_STEER_OFFSET] - (vy + lf * r) / vx  # eq. (13)
    ar = (lr * r - vy) / vx
    sigma = eff[X_RELAX]
    if sigma > 0.0:
        k = vx / sigma
        dlaf = k * (af - laf)
        dlar = k * (ar - lar)
        Fyf = tire_force(laf, tf, tabf) * eff[X_SCALE_F]
        Fyr = tire_force(lar, tr, tabr) * eff[X_SCALE_R]
    else:
        dlaf = 0.0
        dlar = 0.0
        Fyf = tire_force(af, tf, tabf) * eff[X_SCALE_F]
        Fyr = tire_force(ar, tr, tabr) * eff[X_SCALE_R]
    lt = eff[X_LOAD_TRANSFER]
    if lt > 0.0:
        # quasi-static lateral load transfer lowers the axle force by (dFz/Fz)^2/2
        fzf, fzr = veh[V_FZF], veh[V_FZR]
        dfz = m * abs((Fyf + Fyr) / m) * veh[V_HCG] / veh[V_TRACK]
        rf = dfz / (fzf + fzr)
        Fyf *= 1.0 - 0.5 * lt * rf * rf
        Fyr *= 1.0 - 0.5 * lt * rf * rf
    f_ext = eff[X_WIND_F] - m * _GRAVITY * math.sin(eff[X_BANK])
    e1dd = (Fyf + Fyr + f_ext) / m - vx * pdd + ax * e2
    e2dd = (lf * Fyf - lr * Fyr + eff[X_WIND_ARM] * eff[X_WIND_F]) / Iz - pddd
    return e1dd, e2dd, dlaf, dlar, af, ar, Fyf, Fyr


@njit(cache=True)
def bicycle_rk4_step(state, delta, dt, p0, p1, p2, q0, q1, q2, vx, ax, veh, tf, tr, tabf, tabr, eff):
    """One classical RK4 step of the truth bicycle model, in place on ``state`` (6,).

    ``p0..p2`` / ``q0..q2``: desired yaw rate / acceleration at the start, middle and end.
    Returns the truth at the start of the step: ``alpha_f, alpha_r, F_yf, F_yr, yaw_rate, ay``.
    """
    e1, e1d, e2, e2d, laf, lar = state[0], state[1], state[2], state[3], state[4], state[5]
    h = 0.5 * dt
    vm = vx + h * ax
    a1, b1, c1, d1, af, ar, Fyf, Fyr = bicycle_rhs(e1d, e2, e2d, laf, lar, delta, vx, ax, p0, q0, veh, tf, tr, tabf, tabr, eff)
    v2, w2 = e1d + h * a1, e2d + h * b1
    a2, b2, c2, d2, _, _, _, _ = bicycle_rhs(v2, e2 + h * e2d, w2, laf + h * c1, lar + h * d1, delta, vm, ax, p1, q1, veh, tf, tr, tabf, tabr, eff)
    v3, w3 = e1d + h * a2, e2d + h * b2
    a3, b3, c3, d3, _, _, _, _ = bicycle_rhs(v3, e2 + h * w2, w3, laf + h * c2, lar + h * d2, delta, vm, ax, p1, q1, veh, tf, tr, tabf, tabr, eff)
    v4, w4 = e1d + dt * a3, e2d + dt * b3
    a4, b4, c4, d4, _, _, _, _ = bicycle_rhs(v4, e2 + dt * w3, w4, laf + dt * c3, lar + dt * d3, delta, vx + dt * ax, ax, p2, q2, veh, tf, tr, tabf, tabr, eff)
    c = dt / 6.0
    state[0] = e1 + c * (e1d + 2.0 * v2 + 2.0 * v3 + v4)
    state[1] = e1d + c * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
    state[2] = e2 + c * (e2d + 2.0 * w2 + 2.0 * w3 + w4)
    state[3] = e2d + c * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
    state[4] = laf + c * (c1 + 2.0 * c2 + 2.0 * c3 + c4)
    state[5] = lar + c * (d1 + 2.0 * d2 + 2.0 * d3 + d4)
    return af, ar, Fyf, Fyr, e2d + p0, (Fyf + Fyr + eff[X_WIND_F]) / veh[V_M]


@njit(cache=True)
def road_lookup(s, kappa, dkappa, ds):
    """``(kappa, dkappa/ds)`` at ``s`` by linear interpolation in a table with spacing ``ds``."""
    x = s / ds
    if x < 0.0:
        x = 0.0
    i = int(x)
    n = kappa.shape[0]
    if i >= n - 1:
        i = n - 2
        x = float(i + 1)
    f = x - i
    return kappa[i] + f * (kappa[i + 1] - kappa[i]), dkappa[i] + f * (dkappa[i + 1] - dkappa[i])


@njit(cache=True)
def camera_tick(t, e1, e2, cam, cstate, counters, pending, noise, drop):
    """Advance the camera to time ``t`` with true errors ``e1``, ``e2``.

    Takes a frame when one is due (noise ``noise[counters[CAMC_NOISE]]``, dropped if
    ``drop[...]``), queues it for delivery ``latency`` later, and delivers what is due.
    Returns ``(delivered, e1_frame, e2_frame)``; a dropped frame is delivered as NaN.
    """
    if t >= cstate[CAMS_NEXT] - _EPS:
        i = counters[CAMC_NOISE]
        counters[CAMC_NOISE] = i + 1
        cap = pending.shape[0]
        slot = (counters[CAMC_HEAD] + counters[CAMC_COUNT]) % cap
        pending[slot, 0] = t + cam[CAM_LATENCY]
        pending[slot, 1] = t
        if drop[i]:
            pending[slot, 2] = math.nan
            pending[slot, 3] = math.nan
        else:
            pending[slot, 2] = e1 + cam[CAM_E1_BIAS] + noise[i, 0]
            pending[slot, 3] = e2 + cam[CAM_E2_BIAS] + noise[i, 1]
        counters[CAMC_COUNT] += 1
        period = 1.0 / cam[CAM_RATE]
        cstate[CAMS_NEXT] += period
        while cstate[CAMS_NEXT] <= t + _EPS:
            cstate[CAMS_NEXT] += period
    delivered = False
    d1 = math.nan
    d2 = math.nan
    cap = pending.shape[0]
    while counters[CAMC_COUNT] > 0 and t >= pending[counters[CAMC_HEAD], 0] - _EPS:
        h = counters[CAMC_HEAD]
        delivered = True
        d1 = pending[h, 2]
        d2 = pending[h, 3]
        if d1 == d1:
            cstate[CAMS_LATEST_E1] = d1
            cstate[CAMS_LATEST_E2] = d2
            cstate[CAMS_LATEST_TIME] = pending[h, 1]
        counters[CAMC_HEAD] = (h + 1) % cap
        counters[CAMC_COUNT] -= 1
    return delivered, d1, d2


@njit(cache=True)
def driver_steer(e1, e2, kappa, vx, dt, drv, dstate):
    """Lane-keeping steering [rad] (see :mod:`tire_learning_env.driver`); ``dstate[0]`` is the integral."""
    L = drv[DRV_L]
    e2_per_kappa = -drv[DRV_LR] + drv[DRV_E2COEF] * vx * vx
    g_ff = L + drv[DRV_KUS] * vx * vx + drv[DRV_GAIN] * vx * drv[DRV_TLA] * e2_per_kappa
    fb = 0.0
    if e1 == e1 and e2 == e2:
        dstate[0] += e1 * dt
        fb = drv[DRV_GAIN] * (e1 + vx * drv[DRV_TLA] * e2) + drv[DRV_KI] * dstate[0]
    delta = g_ff * kappa - fb
    m = drv[DRV_MAX]
    if delta > m:
        return m
    if delta < -m:
        return -m
    return delta


@njit(cache=True, inline="always")
def guard_steering(delta, delta_prev, guard):
    """Steering [rad] after the IMU a_y guard.

    The change from ``delta_prev`` is clamped so that the last measured a_y plus the change
    times any gain in ``[gain_low, gain_high]`` stays within the limit (an a_y beyond it is
    steered back). It clamps the total steering, driver included: the limit is hard.
    ``guard[GUARD_LIMIT]`` inf: no guard.
    """
    limit = guard[GUARD_LIMIT]
    if not limit < math.inf:
        return delta
    a = guard[GUARD_AY]
    g_lo = guard[GUARD_GAIN_LOW]
    g_hi = guard[GUARD_GAIN_HIGH]
    room_up = limit - a
    room_down = -limit - a
    hi = delta_prev + (room_up / g_hi if room_up >= 0.0 else room_up / g_lo)
    lo = delta_prev + (room_down / g_hi if room_down <= 0.0 else room_down / g_lo)
    if lo > hi:  # far beyond the limit (|a| > limit (g_hi + g_lo) / (g_hi - g_lo)): steer back the harder way
        return hi if a > 0.0 else lo
    if delta > hi:
        return hi
    if delta < lo:
        return lo
    return delta


@njit(cache=True, inline="always")
def record_tick(out, j, t, delta, vx, ax, kappa, p0, q0, delivered, f1, f2, r, ay, af, ar, Fyf, Fyr, s):
    """Fill row ``j`` of a tick log (:data:`LOG_COLUMNS`) except the true state (columns 11-14,
    written before the step); camera columns are NaN when no frame was delivered."""
    out[j, 0] = t
    out[j, 1] = delta
    out[j, 2] = vx
    out[j, 3] = ax
    out[j, 4] = kappa
    out[j, 5] = p0
    out[j, 6] = q0
    out[j, 7] = f1 if delivered else math.nan
    out[j, 8] = f2 if delivered else math.nan
    out[j, 9] = r
    out[j, 10] = ay
    out[j, 15] = af
    out[j, 16] = ar
    out[j, 17] = Fyf
    out[j, 18] = Fyr
    out[j, 19] = s


@njit(cache=True)
def advance_bicycle(
    n_ticks, dt, tick0, state, s0, vx, ax, veh, tf, tr, tabf, tabr, eff,
    road_k, road_dk, road_ds, cam, cstate, counters, pending, noise, drop,
    drv, dstate, guard, steering_offset, steering, last_delta, out,
):  # fmt: skip
    """Run ``n_ticks`` ticks of camera -> driver -> a_y guard -> RK4 plant; fill ``out`` (n_ticks, N_LOG).

    ``steering`` NaN means the driver steers (plus ``steering_offset``); otherwise it is
    the full road-wheel angle. ``guard`` is the steering a_y guard (:func:`guard_steering`;
    its last-a_y entry is updated). Returns ``(s, last_delta)`` at the end.
    """
    s = s0
    max_steer = drv[DRV_MAX]
    delta = last_delta
    vx_mid = vx + 0.5 * dt * ax
    vx_end = vx + dt * ax
    for j in range(n_ticks):
        t = (tick0 + j) * dt
        k0, dk0 = road_lookup(s, road_k, road_dk, road_ds)
        k1, dk1 = road_lookup(s + 0.5 * dt * vx, road_k, road_dk, road_ds)
        s_end = s + 0.5 * dt * (vx + vx_end)
        k2, dk2 = road_lookup(s_end, road_k, road_dk, road_ds)
        delivered, f1, f2 = camera_tick(t, state[0], state[2], cam, cstate, counters, pending, noise, drop)
        delta_prev = delta
        if steering != steering:
            delta = driver_steer(cstate[CAMS_LATEST_E1], cstate[CAMS_LATEST_E2], k0, vx, dt, drv, dstate) + steering_offset
        else:
            delta = steering
        delta = guard_steering(min(max(delta, -max_steer), max_steer), delta_prev, guard)
        if delta > max_steer:
            delta = max_steer
        elif delta < -max_steer:
            delta = -max_steer
        p0 = vx * k0
        q0 = vx * vx * dk0 + ax * k0
        out[j, 11] = state[0]
        out[j, 12] = state[1]
        out[j, 13] = state[2]
        out[j, 14] = state[3]
        af, ar, Fyf, Fyr, r, ay = bicycle_rk4_step(
            state, delta, dt, p0, vx_mid * k1, vx_end * k2,
            q0, vx_mid * vx_mid * dk1 + ax * k1, vx_end * vx_end * dk2 + ax * k2,
            vx, ax, veh, tf, tr, tabf, tabr, eff,
        )  # fmt: skip
        if not (math.isfinite(state[0]) and math.isfinite(state[1]) and math.isfinite(state[2]) and math.isfinite(state[3])):
            return s, delta, j  # caller raises with the time and state
        guard[GUARD_AY] = ay
        record_tick(out, j, t, delta, vx, ax, k0, p0, q0, delivered, f1, f2, r, ay, af, ar, Fyf, Fyr, s)
        s = s_end
    return s, delta, n_ticks
