"""Compiled (numba) building blocks of the physics loop.

Every function here is a pure function of floats and arrays, compiled with
``numba.njit(cache=True)`` and callable from Python as well. They are the single
implementation of

- the truth bicycle model's right-hand side and RK4 step (:func:`bicycle_rk4_step`),
- the lane camera's frame/latency/noise logic (:func:`camera_tick`),
- the lane-keeping driver (:func:`driver_steer`),
- the road-table lookup (:func:`road_lookup`),

- the two curvature sources of the tick loop: a road table on a uniform grid
  (:func:`road_lookup`) and the piecewise-linear knots of a highway-env lane
  (:func:`knot_lookup`, :func:`preview_curvature`), plus a lane change's reference path
  (:func:`lane_change_reference`),

and :func:`advance_ticks`, the one compiled tick loop, strings them together for a whole
chunk of ticks, which is what makes the environments fast (the base simulator passes its
road table, the highway ego its lane knots, a lane-change path and a stop point).
:func:`tire_learning_env.simulation.advance_ticks_python` runs the same sequence in Python
for any other plant; tests check both give the same log.

Array layouts are named by the ``V_*``, ``T_*``, ``X_*``, ``CAM_*``, ``DRV_*`` and ``LOG_*`` indices.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# truth plant state vector: the error state [e1, e1_dot, e2, e2_dot] (dynamics.StateIndex), then
# the front/rear tire relaxation lags (slip) [rad]
S_E1, S_E1_DOT, S_E2, S_E2_DOT, S_LAG_F, S_LAG_R = range(6)
N_PLANT_STATE = 6
# vehicle vector
V_M, V_IZ, V_LF, V_LR, V_CF, V_CR, V_HCG, V_TRACK, V_FZF, V_FZR, V_CAMERA_X = range(11)
N_VEHICLE = 11
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
CAM_RATE, CAM_LATENCY, CAM_E1_BIAS, CAM_E2_BIAS, CAM_X = range(5)
CAMS_NEXT, CAMS_LATEST_E1, CAMS_LATEST_E2, CAMS_LATEST_TIME = range(4)
# camera queue of taken frames, a row each: delivery time, time taken [s], e1 [m], e2 [rad] (NaN: dropped)
PEND_DUE, PEND_TAKEN, PEND_E1, PEND_E2 = range(4)
# camera counters (int64): noise index, pending head, pending count
CAMC_NOISE, CAMC_HEAD, CAMC_COUNT = range(3)
# driver parameter vector: gain, lookahead time, integral gain, max steering, L, K_us, lr, lf m/(2 Cr L)
DRV_GAIN, DRV_TLA, DRV_KI, DRV_MAX, DRV_L, DRV_KUS, DRV_LR, DRV_E2COEF = range(8)
N_DRIVER = 8
# driver state vector (``dstate``): the integral of e1 [m s]
DS_INTEGRAL = 0
N_DRIVER_STATE = 1
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
(
    LOG_T, LOG_DELTA, LOG_VX, LOG_AX, LOG_KAPPA, LOG_PSI_DOT_DES, LOG_PSI_DDOT_DES, LOG_E1, LOG_E2,
    LOG_YAW_RATE, LOG_AY, LOG_TRUE_E1, LOG_TRUE_E1_DOT, LOG_TRUE_E2, LOG_TRUE_E2_DOT,
    LOG_ALPHA_F, LOG_ALPHA_R, LOG_FYF, LOG_FYR, LOG_S,
) = range(N_LOG)  # fmt: skip
#: Column of each :data:`LOG_COLUMNS` name.
LOG_INDEX = {name: i for i, name in enumerate(LOG_COLUMNS)}
# curvature source of the tick loop (advance_ticks): a road table or lane knots
CURVATURE_TABLE, CURVATURE_KNOTS = 0, 1
# why the tick loop returned: all ticks done, hand-over point reached, state not finite
STOP_DONE, STOP_HANDOVER, STOP_BLOWUP = 0, 1, 2
_GRAVITY = 9.81
_EPS = 1e-9


#: No lane change under way: ``(offset [m], s_start [m], length [m])`` of :func:`lane_change_reference`.
NO_LANE_CHANGE = (0.0, 0.0, 1.0)


@njit(cache=True)
def bicycle_slip_angles(vy, r, delta, vx, lf, lr):
    """Front and rear slip angles [rad] of the bicycle model, eq. (13) in body form::

        alpha_f = delta - (vy + lf r) / vx,      alpha_r = -(vy - lr r) / vx

    ``vy`` [m/s], ``r`` [rad/s] at the centre of gravity, ``delta`` [rad] the front wheel
    angle of the caller's model (its steering offsets and ratio errors included), ``vx``
    [m/s] (not floored here: :func:`tire_learning_env.observer._kernel.slip_angles` floors
    it for the estimators), ``lf``, ``lr`` [m]. The package's one implementation of eq. (13):
    truth plants, estimators, baselines, discrepancy models and scoring call it (pure Python
    callers call ``bicycle_slip_angles.py_func``, which also takes numpy arrays).
    """
    return delta - (vy + lf * r) / vx, (lr * r - vy) / vx


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
    af, ar = bicycle_slip_angles(vy, r, delta + eff[X_STEER_OFFSET], vx, lf, lr)  # eq. (13)
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
    """One classical RK4 step of the truth bicycle model, in place on ``state`` (6,) (``S_*`` layout).

    ``p0..p2`` / ``q0..q2``: desired yaw rate / acceleration at the start, middle and end.
    Returns the truth at the start of the step: ``alpha_f, alpha_r, F_yf, F_yr, yaw_rate, ay``.
    """
    e1, e1d, e2, e2d = state[S_E1], state[S_E1_DOT], state[S_E2], state[S_E2_DOT]
    laf, lar = state[S_LAG_F], state[S_LAG_R]
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
    state[S_E1] = e1 + c * (e1d + 2.0 * v2 + 2.0 * v3 + v4)
    state[S_E1_DOT] = e1d + c * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
    state[S_E2] = e2 + c * (e2d + 2.0 * w2 + 2.0 * w3 + w4)
    state[S_E2_DOT] = e2d + c * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
    state[S_LAG_F] = laf + c * (c1 + 2.0 * c2 + 2.0 * c3 + c4)
    state[S_LAG_R] = lar + c * (d1 + 2.0 * d2 + 2.0 * d3 + d4)
    return af, ar, Fyf, Fyr, e2d + p0, (Fyf + Fyr + eff[X_WIND_F]) / veh[V_M]


@njit(cache=True, inline="always")
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
def camera_tick(t, e1, e2, kappa, cam, cstate, counters, pending, noise, drop):
    """Advance the camera to time ``t`` with true errors ``e1``, ``e2`` of the CG on a path of curvature ``kappa``.

    Takes a frame when one is due (noise ``noise[counters[CAMC_NOISE]]``, dropped if
    ``drop[...]``), queues it for delivery ``latency`` later, and delivers what is due. A camera
    ``x = cam[CAM_X]`` ahead of the CG (``VehicleParams.camera_x``) shows ``e1 + x sin(e2) - kappa x^2 / 2``.
    Returns ``(delivered, e1_frame, e2_frame)``; a dropped frame is delivered as NaN.
    """
    if t >= cstate[CAMS_NEXT] - _EPS:
        if cam[CAM_X] != 0.0:
            e1 = e1 + cam[CAM_X] * math.sin(e2) - 0.5 * kappa * cam[CAM_X] * cam[CAM_X]
        i = counters[CAMC_NOISE]
        counters[CAMC_NOISE] = i + 1
        cap = pending.shape[0]
        slot = (counters[CAMC_HEAD] + counters[CAMC_COUNT]) % cap
        pending[slot, PEND_DUE] = t + cam[CAM_LATENCY]
        pending[slot, PEND_TAKEN] = t
        if drop[i]:
            pending[slot, PEND_E1] = math.nan
            pending[slot, PEND_E2] = math.nan
        else:
            pending[slot, PEND_E1] = e1 + cam[CAM_E1_BIAS] + noise[i, 0]
            pending[slot, PEND_E2] = e2 + cam[CAM_E2_BIAS] + noise[i, 1]
        counters[CAMC_COUNT] += 1
        period = 1.0 / cam[CAM_RATE]
        cstate[CAMS_NEXT] += period
        while cstate[CAMS_NEXT] <= t + _EPS:
            cstate[CAMS_NEXT] += period
    delivered = False
    d1 = math.nan
    d2 = math.nan
    cap = pending.shape[0]
    while counters[CAMC_COUNT] > 0 and t >= pending[counters[CAMC_HEAD], PEND_DUE] - _EPS:
        h = counters[CAMC_HEAD]
        delivered = True
        d1 = pending[h, PEND_E1]
        d2 = pending[h, PEND_E2]
        if d1 == d1:
            cstate[CAMS_LATEST_E1] = d1
            cstate[CAMS_LATEST_E2] = d2
            cstate[CAMS_LATEST_TIME] = pending[h, PEND_TAKEN]
        counters[CAMC_HEAD] = (h + 1) % cap
        counters[CAMC_COUNT] -= 1
    return delivered, d1, d2


@njit(cache=True)
def driver_steer(e1, e2, kappa, vx, dt, drv, dstate):
    """Lane-keeping steering [rad] (see :mod:`tire_learning_env.driver`); ``dstate[DS_INTEGRAL]`` is the integral."""
    L = drv[DRV_L]
    e2_per_kappa = -drv[DRV_LR] + drv[DRV_E2COEF] * vx * vx
    g_ff = L + drv[DRV_KUS] * vx * vx + drv[DRV_GAIN] * vx * drv[DRV_TLA] * e2_per_kappa
    fb = 0.0
    if e1 == e1 and e2 == e2:
        dstate[DS_INTEGRAL] += e1 * dt
        fb = drv[DRV_GAIN] * (e1 + vx * drv[DRV_TLA] * e2) + drv[DRV_KI] * dstate[DS_INTEGRAL]
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
def record_true_state(out, j, state):
    """Write the true error state ``state[:4]`` (before the step) into row ``j`` of a tick log."""
    out[j, LOG_TRUE_E1] = state[S_E1]
    out[j, LOG_TRUE_E1_DOT] = state[S_E1_DOT]
    out[j, LOG_TRUE_E2] = state[S_E2]
    out[j, LOG_TRUE_E2_DOT] = state[S_E2_DOT]


@njit(cache=True, inline="always")
def record_tick(out, j, t, delta, vx, ax, kappa, p0, q0, delivered, f1, f2, r, ay, af, ar, Fyf, Fyr, s):
    """Fill row ``j`` of a tick log (:data:`LOG_COLUMNS`) except the true state (written before
    the step, :func:`record_true_state`); camera columns are NaN when no frame was delivered.
    The one row writer of the compiled and the Python tick loops (every value a float).

    One named store per column, not a loop over a tuple of columns: with the loop form (and the
    three inlined knot searches, :func:`advance_ticks` Notes) the road-table ticks ran 2-5 %
    slower (issue 20, ``benchmarks/results/env_step_ab_issue20.json``).
    """
    out[j, LOG_T] = t
    out[j, LOG_DELTA] = delta
    out[j, LOG_VX] = vx
    out[j, LOG_AX] = ax
    out[j, LOG_KAPPA] = kappa
    out[j, LOG_PSI_DOT_DES] = p0
    out[j, LOG_PSI_DDOT_DES] = q0
    out[j, LOG_E1] = f1 if delivered else math.nan
    out[j, LOG_E2] = f2 if delivered else math.nan
    out[j, LOG_YAW_RATE] = r
    out[j, LOG_AY] = ay
    out[j, LOG_ALPHA_F] = af
    out[j, LOG_ALPHA_R] = ar
    out[j, LOG_FYF] = Fyf
    out[j, LOG_FYR] = Fyr
    out[j, LOG_S] = s


@njit(cache=True, inline="always")
def _knot_segment(s, ks):
    """Index ``i`` of the knot segment ``ks[i] <= s < ks[i + 1]`` (bisection; ``ks[0] < s < ks[-1]``)."""
    lo, hi = 0, ks.shape[0] - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if ks[mid] <= s:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True, inline="always")
def knot_lookup(s, ks, kv):
    """``(kappa, dkappa/ds)`` at ``s`` [m] of the piecewise-linear curvature through knots ``(ks, kv)``.

    ``dkappa/ds`` is the slope of the segment containing ``s`` (so ``psi_ddot_des``
    integrates exactly to ``psi_dot_des``). Constant beyond the end knots.
    """
    n = ks.shape[0]
    if s <= ks[0]:
        return kv[0], 0.0
    if s >= ks[n - 1]:
        return kv[n - 1], 0.0
    lo = _knot_segment(s, ks)
    slope = (kv[lo + 1] - kv[lo]) / (ks[lo + 1] - ks[lo])
    return kv[lo] + slope * (s - ks[lo]), slope


@njit(cache=True)
def _knot_integral(s, ks, kv, cum):
    """``integral_{ks[0]}^{s} kappa`` [rad] (``cum[i]`` = the integral up to knot ``i``)."""
    n = ks.shape[0]
    if s <= ks[0]:
        return kv[0] * (s - ks[0])
    if s >= ks[n - 1]:
        return cum[n - 1] + kv[n - 1] * (s - ks[n - 1])
    lo = _knot_segment(s, ks)
    x = s - ks[lo]
    slope = (kv[lo + 1] - kv[lo]) / (ks[lo + 1] - ks[lo])
    return cum[lo] + kv[lo] * x + 0.5 * slope * x * x


@njit(cache=True)
def preview_curvature(s, preview, ks, kv, cum):
    """Mean curvature [1/m] over ``[s - preview/2, s + preview/2]`` (exact); ``kappa(s)`` if ``preview <= 0``.

    highway-env joins straights and arcs without transition curves; a feed-forward of the
    current curvature would step the steering at every join, so the driver eases in over
    ``preview`` metres centred on the join, as a clothoid of that length would make it.
    """
    if preview <= 0.0:
        return knot_lookup(s, ks, kv)[0]
    h = 0.5 * preview
    return (_knot_integral(s + h, ks, kv, cum) - _knot_integral(s - h, ks, kv, cum)) / preview


@njit(cache=True)
def lane_change_reference(s, offset, s_start, length):
    """Minimum-jerk lateral path of a lane change in the target lane's frame.

    ``e1_ref(s) = offset (1 - m(u))``, ``u = (s - s_start) / length`` clipped to [0, 1],
    ``m = 10 u^3 - 15 u^4 + 6 u^5``: the path leaves the old lane centre (``e1 = offset``)
    along the lane direction and joins the new one (``e1 = 0``) tangentially after
    ``length`` metres. Returns ``(e1_ref [m], de1_ref/ds [-], d2e1_ref/ds2 [1/m])``; zero
    when ``offset == 0`` or after the manoeuvre. A path in space (not in time), so braking
    during the manoeuvre does not sharpen it.
    """
    if offset == 0.0 or length <= 0.0:
        return 0.0, 0.0, 0.0
    u = (s - s_start) / length
    if u >= 1.0:
        return 0.0, 0.0, 0.0
    if u <= 0.0:
        return offset, 0.0, 0.0
    u2 = u * u
    u3 = u2 * u
    m = u3 * (10.0 - 15.0 * u + 6.0 * u2)
    dm = 30.0 * u2 * (1.0 - 2.0 * u + u2)
    ddm = 60.0 * u * (1.0 - 3.0 * u + 2.0 * u2)
    return offset * (1.0 - m), -offset * dm / length, -offset * ddm / (length * length)


@njit(cache=True)
def lane_change_driver_inputs(s, e1_meas, e2_meas, kappa, lc_offset, lc_s0, lc_len):
    """Measured errors relative to the lane-change path (:func:`lane_change_reference`), and the
    feed-forward curvature plus the path's curvature: ``(e1 - e1_ref, e2 - de1_ref/ds, kappa + d2e1_ref/ds2)``."""
    r0, r1, r2 = lane_change_reference(s, lc_offset, lc_s0, lc_len)
    return e1_meas - r0, e2_meas - r1, kappa + r2


@njit(cache=True, inline="always")
def curvature_at(s, source, curve_a, curve_b, curve_ds):
    """``(kappa, dkappa/ds)`` at ``s`` [m] from a road table (``source == CURVATURE_TABLE``:
    ``curve_a, curve_b`` = kappa, dkappa on a grid of ``curve_ds``) or lane knots
    (``CURVATURE_KNOTS``: ``curve_a, curve_b`` = knot positions and curvatures)."""
    if source == CURVATURE_TABLE:
        return road_lookup(s, curve_a, curve_b, curve_ds)
    return knot_lookup(s, curve_a, curve_b)


@njit(cache=True)
def _knot_lookups(s0, s1, s2, ks, kv):
    """:func:`knot_lookup` at the start, middle and end of a tick: ``k0, dk0, k1, dk1, k2, dk2``.

    A call of its own from :func:`advance_ticks`, so the knot search is not inlined three times
    into the loop body, where it slowed the road-table ticks too (:func:`advance_ticks` Notes).
    """
    k0, dk0 = knot_lookup(s0, ks, kv)
    k1, dk1 = knot_lookup(s1, ks, kv)
    k2, dk2 = knot_lookup(s2, ks, kv)
    return k0, dk0, k1, dk1, k2, dk2


@njit(cache=True)
def advance_ticks(
    n_ticks, dt, tick0, state, s0, vx0, ax,
    veh, tf, tr, tabf, tabr, eff,                           # plant: BicyclePlant.kernel_params()
    curve_source, curve_a, curve_b, curve_ds, curve_cum,    # curvature source (curvature_at)
    s_stop, preview_time,
    cam, cstate, counters, pending, noise, drop,            # camera: Camera.kernel_args()
    drv, dstate, guard,                                     # driver: LaneKeepingDriver.kernel_args()
    steering_offset, steering, last_delta,
    lc_offset, lc_s0, lc_len,                               # lane-change path (NO_LANE_CHANGE: none)
    out,
):  # fmt: skip
    """Run up to ``n_ticks`` ticks of camera -> driver -> a_y guard -> RK4 plant; fill ``out`` rows.

    The one compiled tick loop (the base simulator and the highway ego car). The arguments are
    flat, in named groups a caller passes by unpacking the group's tuple in place (``*group``),
    e.g. ``*plant.kernel_params()`` or ``*NO_LANE_CHANGE``: see the Notes for why.

    Parameters
    ----------
    n_ticks, dt, tick0
        Ticks to run, tick [s], index of the first tick (``t_j = (tick0 + j) dt``).
    state : ndarray (N_PLANT_STATE,)
        Plant state (``S_*`` layout), advanced in place.
    s0, vx0, ax
        Path coordinate [m], speed [m/s] at the first tick and the longitudinal acceleration
        [m/s^2] held over the chunk (``vx`` is integrated tick by tick; constant when ``ax = 0``).
    veh, tf, tr, tabf, tabr, eff
        Plant group: the plant's compiled parameters, vehicle (``V_*``), front and rear tire
        vectors, front and rear force tables and effects (``X_*``), in the order of
        ``BicyclePlant.kernel_params()``.
    curve_source, curve_a, curve_b, curve_ds, curve_cum
        Curvature group: ``CURVATURE_TABLE`` with ``curve_a, curve_b`` = kappa [1/m] and
        dkappa/ds [1/m^2] on a grid of ``curve_ds`` [m] (``curve_cum`` unused), or
        ``CURVATURE_KNOTS`` with ``curve_a, curve_b`` = knot positions [m] and curvatures
        [1/m] and ``curve_cum`` their running integral [rad] (``curve_ds`` unused); see
        :func:`curvature_at`.
    s_stop : float
        Stop before a tick that starts at ``s >= s_stop`` [m] (a lane hand-over; inf: never).
    preview_time : float
        The driver's curvature feed-forward is the mean over ``preview_time * vx`` metres
        centred on ``s`` (knots only; 0: the curvature at ``s``).
    cam, cstate, counters, pending, noise, drop
        Camera group: parameters (``CAM_*``), state (``CAMS_*``), counters (``CAMC_*``),
        queue of taken frames (``PEND_*``), frame noise and dropouts, in the order of
        ``Camera.kernel_args()``; updated in place.
    drv, dstate, guard
        Driver group: gains (``DRV_*``), integral state (``DS_*``) and a_y guard
        (``GUARD_*``), in the order of ``LaneKeepingDriver.kernel_args()``; the integral and
        the guard's last a_y are updated.
    steering_offset, steering, last_delta
        ``steering`` NaN: the driver steers, plus ``steering_offset``; otherwise the full
        road-wheel angle [rad]. ``last_delta``: the steering of the previous tick [rad].
    lc_offset, lc_s0, lc_len
        Lane-change group: offset [m], start [m] and length [m] of the lane-change path the
        driver follows (:func:`lane_change_reference`; ``NO_LANE_CHANGE``: the lane centre).
    out : ndarray (n_ticks, N_LOG)
        Tick log rows (:data:`LOG_COLUMNS`), row ``j`` at instant ``t_j``.

    Returns
    -------
    s, vx, delta, done, status
        Path coordinate [m], speed [m/s] and steering [rad] after the last tick done, the
        number of ticks done, and ``STOP_DONE`` / ``STOP_HANDOVER`` / ``STOP_BLOWUP``.

    Notes
    -----
    Flat arguments, not tuples: numba unboxes a group packed in a tuple slower than the same
    values passed one by one (named tuples slower still). With the groups as plain tuples a call
    cost about 1 us more CPU time to dispatch (4.9 vs 4.0 us, arguments built once; 6.3 vs 5.7 us
    with the arguments built per call as the simulator does), of about 220 us per Cornering env
    step of 50 ticks on the machine measured (issue 20 follow-up,
    ``benchmarks/results/kernel_call_overhead_issue20.json``). The RK4 midpoint curvature is
    looked up at ``s + vx dt/2 + ax dt^2/8`` (the exact midpoint under constant ``ax``). The
    Python loop of the base simulator with a speed profile omits the ``ax dt^2/8`` term
    (:func:`~tire_learning_env.simulation.advance_ticks_python`, ``midpoint_ax_factor``); with
    ``ax = 0`` the two agree to the bit.

    The three curvature lookups of a tick share one branch on ``curve_source`` (the table's
    inlined, the knots' one call, :func:`_knot_lookups`) instead of three :func:`curvature_at`
    calls. With the knot search inlined three times and :func:`record_tick` a loop over a tuple
    of columns, the road-table ticks ran 2-5 % slower than with both changes (the same process,
    alternating calls of 60 000 ticks; issue 20, ``benchmarks/results/env_step_ab_issue20.json``).
    """
    s = s0
    vx = vx0
    delta = last_delta
    max_steer = drv[DRV_MAX]
    for j in range(n_ticks):
        if s >= s_stop:
            return s, vx, delta, j, STOP_HANDOVER
        t = (tick0 + j) * dt
        vx_mid = vx + 0.5 * dt * ax
        vx_end = vx + dt * ax
        s_mid = s + 0.5 * dt * vx + 0.125 * dt * dt * ax
        s_end = s + 0.5 * dt * (vx + vx_end)
        # curvature_at at the three RK4 stages, with one branch per tick (see the Notes)
        if curve_source == CURVATURE_TABLE:
            k0, dk0 = road_lookup(s, curve_a, curve_b, curve_ds)
            k1, dk1 = road_lookup(s_mid, curve_a, curve_b, curve_ds)
            k2, dk2 = road_lookup(s_end, curve_a, curve_b, curve_ds)
        else:
            k0, dk0, k1, dk1, k2, dk2 = _knot_lookups(s, s_mid, s_end, curve_a, curve_b)
        delivered, f1, f2 = camera_tick(t, state[S_E1], state[S_E2], k0, cam, cstate, counters, pending, noise, drop)
        delta_prev = delta
        if steering != steering:
            kp = k0
            if curve_source == CURVATURE_KNOTS:
                kp = preview_curvature(s, preview_time * vx, curve_a, curve_b, curve_cum)
            e1m = cstate[CAMS_LATEST_E1]
            e2m = cstate[CAMS_LATEST_E2]
            if lc_offset != 0.0:
                e1m, e2m, kp = lane_change_driver_inputs(s, e1m, e2m, kp, lc_offset, lc_s0, lc_len)
            delta = driver_steer(e1m, e2m, kp, vx, dt, drv, dstate) + steering_offset
        else:
            delta = steering
        delta = guard_steering(min(max(delta, -max_steer), max_steer), delta_prev, guard)
        if delta > max_steer:
            delta = max_steer
        elif delta < -max_steer:
            delta = -max_steer
        p0 = vx * k0
        q0 = vx * vx * dk0 + ax * k0
        record_true_state(out, j, state)
        af, ar, Fyf, Fyr, r, ay = bicycle_rk4_step(
            state, delta, dt, p0, vx_mid * k1, vx_end * k2,
            q0, vx_mid * vx_mid * dk1 + ax * k1, vx_end * vx_end * dk2 + ax * k2,
            vx, ax, veh, tf, tr, tabf, tabr, eff,
        )  # fmt: skip
        if not (
            math.isfinite(state[S_E1])
            and math.isfinite(state[S_E1_DOT])
            and math.isfinite(state[S_E2])
            and math.isfinite(state[S_E2_DOT])
        ):
            return s, vx, delta, j, STOP_BLOWUP
        guard[GUARD_AY] = ay
        record_tick(out, j, t, delta, vx, ax, k0, p0, q0, delivered, f1, f2, r, ay, af, ar, Fyf, Fyr, s)
        s = s_end
        vx = vx_end
    return s, vx, delta, n_ticks, STOP_DONE
