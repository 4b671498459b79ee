"""Physics loop of the truth ego car in highway-env scenes (compiled, plus a Python twin).

The ego car's truth state is the error state of SPEC §1 relative to its *target lane*
(a highway-env lane object), integrated with the shared RK4 kernel
(:func:`tire_learning_env._kernels.bicycle_rk4_step`) at the physics rate. What differs
from :func:`tire_learning_env._kernels.advance_bicycle`:

- the curvature is a piecewise-linear profile ``(ks, kv)`` of the target lane around the
  car (built per chunk by :class:`~tire_learning_env.envs.highway.LaneReference`), with
  ``dkappa/ds`` the exact slope of each piece, so ``psi_ddot_des`` integrates to
  ``psi_dot_des``;
- the speed follows a prescribed longitudinal acceleration ``ax`` (highway-env's IDM
  decides it at the traffic rate): ``vx`` is integrated tick by tick;
- during a lane change the driver steers toward a minimum-jerk lateral path (in ``s``)
  that starts on the old lane centre and ends on the new one (the camera still reports
  ``e1`` relative to the target lane); feed-forward includes the path's curvature;
- the driver's curvature feed-forward is the mean curvature over ``preview_time * vx``
  metres centred on the car (highway-env roads have no transition curves);
- the loop stops early when the path coordinate reaches ``s_stop`` (the hand-over point to
  the next lane segment), so the caller can re-express the state in the next lane.

Row ``j`` of ``out`` has the :data:`~tire_learning_env._kernels.LOG_COLUMNS` layout and
holds everything at instant ``t_j``, as in the base simulator.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .._kernels import (
    CAMS_LATEST_E1,
    CAMS_LATEST_E2,
    DRV_MAX,
    GUARD_AY,
    bicycle_rk4_step,
    camera_tick,
    driver_steer,
    guard_steering,
    record_tick,
)

__all__ = [
    "advance_ego",
    "advance_ego_python",
    "knot_lookup",
    "lane_change_reference",
    "preview_curvature",
    "STOP_DONE",
    "STOP_HANDOVER",
    "STOP_BLOWUP",
]

STOP_DONE, STOP_HANDOVER, STOP_BLOWUP = 0, 1, 2


@njit(cache=True)
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
    lo, hi = 0, n - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if ks[mid] <= s:
            lo = mid
        else:
            hi = mid
    slope = (kv[hi] - kv[lo]) / (ks[hi] - ks[lo])
    return kv[lo] + slope * (s - ks[lo]), slope


@njit(cache=True)
def _knot_integral(s, ks, kv, cum):
    """``integral_{ks[0]}^{s} kappa`` [rad] (``cum[i]`` = the integral up to knot ``i``)."""
    n = ks.shape[0]
    if s <= ks[0]:
        return kv[0] * (s - ks[0])
    if s >= ks[n - 1]:
        return cum[n - 1] + kv[n - 1] * (s - ks[n - 1])
    lo, hi = 0, n - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if ks[mid] <= s:
            lo = mid
        else:
            hi = mid
    x = s - ks[lo]
    slope = (kv[hi] - kv[lo]) / (ks[hi] - ks[lo])
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
def _driver_inputs(s, e1_meas, e2_meas, kappa, lc_offset, lc_s0, lc_len):
    """Measured errors relative to the lane-change path, and the feed-forward curvature."""
    r0, r1, r2 = lane_change_reference(s, lc_offset, lc_s0, lc_len)
    return e1_meas - r0, e2_meas - r1, kappa + r2


@njit(cache=True)
def advance_ego(
    n_ticks, dt, tick0, state, s0, vx0, ax, veh, tf, tr, tabf, tabr, eff,
    ks, kv, kcum, s_stop, preview_time, cam, cstate, counters, pending, noise, drop,
    drv, dstate, guard, steering_offset, steering, last_delta, lc_offset, lc_s0, lc_len, out,
):  # fmt: skip
    """Run up to ``n_ticks`` ticks of camera -> driver -> a_y guard -> RK4 plant; fill ``out`` rows.

    Stops before a tick that starts at ``s >= s_stop`` (hand-over to the next lane). The
    driver's curvature feed-forward is the mean over ``preview_time * vx`` metres centred on ``s``.
    ``steering`` NaN means the driver steers (plus ``steering_offset``), otherwise it is
    the full road-wheel angle [rad].

    Returns
    -------
    s, vx, delta, done, status
        Path coordinate [m], speed [m/s] and steering [rad] after the last tick done,
        number of ticks done, and ``STOP_DONE`` / ``STOP_HANDOVER`` / ``STOP_BLOWUP``.
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
        k0, dk0 = knot_lookup(s, ks, kv)
        k1, dk1 = knot_lookup(s + 0.5 * dt * vx + 0.125 * dt * dt * ax, ks, kv)
        s_end = s + 0.5 * dt * (vx + vx_end)
        k2, dk2 = knot_lookup(s_end, ks, kv)
        delivered, f1, f2 = camera_tick(t, state[0], state[2], cam, cstate, counters, pending, noise, drop)
        delta_prev = delta
        if steering != steering:
            kp = preview_curvature(s, preview_time * vx, ks, kv, kcum)
            e1d, e2d, kff = _driver_inputs(s, cstate[CAMS_LATEST_E1], cstate[CAMS_LATEST_E2], kp, lc_offset, lc_s0, lc_len)
            delta = driver_steer(e1d, e2d, kff, vx, dt, drv, dstate) + steering_offset
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
        if not (
            math.isfinite(state[0]) and math.isfinite(state[1]) and math.isfinite(state[2]) and math.isfinite(state[3])
        ):
            return s, vx, delta, j, STOP_BLOWUP
        guard[GUARD_AY] = ay
        record_tick(out, j, t, delta, vx, ax, k0, p0, q0, delivered, f1, f2, r, ay, af, ar, Fyf, Fyr, s)
        s = s_end
        vx = vx_end
    return s, vx, delta, n_ticks, STOP_DONE


def advance_ego_python(
    n_ticks, dt, tick0, plant, s0, vx0, ax, ks, kv, kcum, s_stop, preview_time, camera, driver,
    steering_offset, steering, last_delta, lc_offset, lc_s0, lc_len, out,
):  # fmt: skip
    """The same tick sequence as :func:`advance_ego` for any plant with a ``step`` method.

    ``plant`` follows :class:`~tire_learning_env.simulation.Plant`; ``camera`` is a
    :class:`~tire_learning_env.sensors.Camera` and ``driver`` a
    :class:`~tire_learning_env.driver.LaneKeepingDriver`. Same returns as :func:`advance_ego`.
    """
    s, vx, delta = s0, vx0, last_delta
    max_steer = driver.params.max_steering
    for j in range(n_ticks):
        if s >= s_stop:
            return s, vx, delta, j, STOP_HANDOVER
        t = (tick0 + j) * dt
        vx_mid, vx_end = vx + 0.5 * dt * ax, vx + dt * ax
        k0, dk0 = knot_lookup(s, ks, kv)
        k1, dk1 = knot_lookup(s + 0.5 * dt * vx + 0.125 * dt * dt * ax, ks, kv)
        s_end = s + 0.5 * dt * (vx + vx_end)
        k2, dk2 = knot_lookup(s_end, ks, kv)
        state = plant.state
        frame = camera.tick(t, state[0], state[2])
        delta_prev = delta
        if steering != steering:
            e1m, e2m = camera.latest
            kp = preview_curvature(s, preview_time * vx, ks, kv, kcum)
            e1d, e2d, kff = _driver_inputs(s, e1m, e2m, kp, lc_offset, lc_s0, lc_len)
            delta = driver.steer(e1d, e2d, kff, vx, dt) + steering_offset
        else:
            delta = steering
        delta = guard_steering(min(max(delta, -max_steer), max_steer), delta_prev, driver.guard)
        delta = min(max(delta, -max_steer), max_steer)
        p0, q0 = vx * k0, vx * vx * dk0 + ax * k0
        out[j, 11:15] = state[:4]
        try:
            af, ar, Fyf, Fyr, r, ay = plant.step(
                delta,
                dt,
                (p0, vx_mid * k1, vx_end * k2),
                (q0, vx_mid * vx_mid * dk1 + ax * k1, vx_end * vx_end * dk2 + ax * k2),
                vx,
                ax,
            )
        except FloatingPointError:
            return s, vx, delta, j, STOP_BLOWUP
        if not np.all(np.isfinite(plant.state[:4])):
            return s, vx, delta, j, STOP_BLOWUP
        driver.guard[GUARD_AY] = ay
        e1f, e2f = frame if frame is not None else (math.nan, math.nan)
        out[j, :11] = (t, delta, vx, ax, k0, p0, q0, e1f, e2f, r, ay)
        out[j, 15:] = (af, ar, Fyf, Fyr, s)
        s, vx = s_end, vx_end
    return s, vx, delta, n_ticks, STOP_DONE
