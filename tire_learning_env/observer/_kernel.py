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

Compiled with ``error_model="numpy"``: a float division by zero gives inf/NaN instead of raising
``ZeroDivisionError`` (the loop guards its divisors: speeds floored at ``V_FLOOR``, time steps
checked positive, 2x2 determinants floored), so numba drops the zero test and its branch from
every division; the results are the same bit for bit (the stiffness of a 30 min, 100 Hz log and
of Study 1 identical), a fixed-weight pass 3-12 % faster (CPU per row).

The family, callees first: :mod:`._kernel_types` (layouts, named tuples, work arrays),
:mod:`._kernel_predict` (basis, forces, prediction), :mod:`._kernel_update` (corrections,
health) and this module (delayed frames, the loop; it re-exports the others' names). Each
keys numba's cache on the source of all four (:mod:`tire_learning_env._jit_cache`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .._jit_cache import key_on_family
from ._kernel_predict import forces, predict, slip_angles
from ._kernel_types import (Accumulator, Gains, Model, Outputs, Settings, State, bound_table, make_work,
                            KERNEL_FAMILY, VY, R, E1, E2, CH_E1, CH_E2, CH_AY, CH_R, N_CHANNELS, GROUP_CAMERA,
                            GROUP_IMU, HEALTH_OK, HEALTH_SETTLING, HEALTH_NO_DATA, HEALTH_INCONSISTENT,
                            HEALTH_DIVERGED, HEALTH_RECOVERING, MODE_CAUSAL, MODE_FIXED, HS_CODE, HS_LAST_MEAS,
                            HS_TRIP_T, HS_SUM, HS_DOF, HS_COUNT, HS_HEAD, HS_LAST_CKPT, HS_N_CKPT, HS_CKPT_HEAD,
                            HS_TRIPS, HS_STARTED, HS_T0, HS_PREV_T, HS_PREV_KAPPA, HS_KAPPA_RATE, N_HS, HM_COUNT,
                            HM_HEAD, V_FLOOR)  # fmt: skip
from ._kernel_update import _health_push, _health_tick, update

#: The layouts and named tuples of :mod:`._kernel_types` and the kernels (the estimator imports them from here).
__all__ = ["Accumulator", "Gains", "Model", "Outputs", "Settings", "State", "bound_table", "make_work",
           "KERNEL_FAMILY", "VY", "R", "E1", "E2", "CH_E1", "CH_E2", "CH_AY", "CH_R", "N_CHANNELS",
           "GROUP_CAMERA", "GROUP_IMU", "HEALTH_OK", "HEALTH_SETTLING", "HEALTH_NO_DATA",
           "HEALTH_INCONSISTENT", "HEALTH_DIVERGED", "HEALTH_RECOVERING", "MODE_CAUSAL", "MODE_FIXED",
           "HS_CODE", "HS_LAST_MEAS", "HS_TRIP_T", "HS_SUM", "HS_DOF", "HS_COUNT", "HS_HEAD", "HS_LAST_CKPT",
           "HS_N_CKPT", "HS_CKPT_HEAD", "HS_TRIPS", "HS_STARTED", "HS_T0", "HS_PREV_T", "HS_PREV_KAPPA",
           "HS_KAPPA_RATE", "N_HS", "HM_COUNT", "HM_HEAD", "V_FLOOR", "slip_angles", "forces", "predict",
           "update", "delayed_camera", "run_rows"]  # fmt: skip


# -- delayed camera frames --------------------------------------------------------------------
# History slots are addressed by a running row counter (hist_meta[HM_HEAD] = rows pushed so
# far, across calls), stored at ``slot % H``; the row being processed is ``HEAD - 1``.
@njit(cache=True, error_model="numpy")
def _store_state(st, slot):
    i = slot % st.hist_t.shape[0]
    for a in range(st.x.shape[0]):
        st.hist_x[i, a] = st.x[a]
        for b in range(st.w.shape[0]):
            st.hist_ups[i, a, b] = st.ups[a, b]
        for b in range(st.x.shape[0]):
            st.hist_sig[i, a, b] = st.sig[a, b]


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
def _restore_state(st, slot):
    i = slot % st.hist_t.shape[0]
    for a in range(st.x.shape[0]):
        st.x[a] = st.hist_x[i, a]
        for b in range(st.w.shape[0]):
            st.ups[a, b] = st.hist_ups[i, a, b]
        for b in range(st.x.shape[0]):
            st.sig[a, b] = st.hist_sig[i, a, b]


@njit(cache=True, error_model="numpy")
def _stored_imu(st, slot, zrow):
    i = slot % st.hist_t.shape[0]
    zrow[CH_E1] = np.nan
    zrow[CH_E2] = np.nan
    zrow[CH_AY] = st.hist_u[i, 4]
    zrow[CH_R] = st.hist_u[i, 5]


@njit(cache=True, error_model="numpy", inline="always")
def release_e1(st, release):
    """Add ``release`` [m^2] to the variance of ``e1`` before a frame whose ``e1`` is re-expressed in
    another lane line (:mod:`.reexpression`): the offset left by the removed step is learnt from the
    frames, not taken for motion (``e1`` enters no other state's dynamics)."""
    if release > 0.0:
        st.sig[E1, E1] += release


@njit(cache=True, error_model="numpy")
def delayed_camera(st, zk, M, G, S, adapt, accumulate, acc, score, k, wk, zrow, release):
    """Correct with a frame that shows the instant ``t_now - latency`` (out-of-sequence update).

    Rewinds to the stored prior of the newest row at or before that instant, replays that
    row's IMU correction, predicts to the instant, adds ``release`` to the variance of ``e1``
    there (a re-expressed frame, :func:`release_e1`), corrects there (learning as usual), and
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
    release_e1(st, release)
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
@njit(cache=True, error_model="numpy", inline="always")
def _std4(st, nw, std, k):
    """``std[k, i] = sqrt(sig_ii + ups_i P_w ups_i^T)`` for the four camera states, from the upper
    triangle of ``P_w``.

    The same sums as the one-state loop of :func:`run_rows` (each state's row sum from 0 in ``b``
    order, its ``a`` terms added where ``ups[i, a] != 0``), bit for bit, but the four states'
    sums run side by side: four independent chains of additions instead of one, which the
    processor overlaps (the one-state loop was bound by the latency of its single chain: a
    recorded pass over a 30 min, 100 Hz log spent 6 of its 21 us per row there).
    """
    v0 = st.sig[0, 0]
    v1 = st.sig[1, 1]
    v2 = st.sig[2, 2]
    v3 = st.sig[3, 3]
    for a in range(nw):
        u0 = st.ups[0, a]
        u1 = st.ups[1, a]
        u2 = st.ups[2, a]
        u3 = st.ups[3, a]
        if u0 == 0.0 and u1 == 0.0 and u2 == 0.0 and u3 == 0.0:
            continue
        r0 = 0.0
        r1 = 0.0
        r2 = 0.0
        r3 = 0.0
        for b in range(a + 1, nw):
            p = st.pw[a, b]
            r0 += p * st.ups[0, b]
            r1 += p * st.ups[1, b]
            r2 += p * st.ups[2, b]
            r3 += p * st.ups[3, b]
        paa = st.pw[a, a]
        if u0 != 0.0:
            v0 += u0 * (paa * u0 + 2.0 * r0)
        if u1 != 0.0:
            v1 += u1 * (paa * u1 + 2.0 * r1)
        if u2 != 0.0:
            v2 += u2 * (paa * u2 + 2.0 * r2)
        if u3 != 0.0:
            v3 += u3 * (paa * u3 + 2.0 * r3)
    std[k, 0] = math.sqrt(max(v0, 0.0))
    std[k, 1] = math.sqrt(max(v1, 0.0))
    std[k, 2] = math.sqrt(max(v2, 0.0))
    std[k, 3] = math.sqrt(max(v3, 0.0))


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
def _next_frame(z, k):
    """First row at or after ``k`` with a camera channel (``len(z)`` if none)."""
    n = z.shape[0]
    while k < n and not (z[k, CH_E1] == z[k, CH_E1] or z[k, CH_E2] == z[k, CH_E2]):
        k += 1
    return k


@njit(cache=True, error_model="numpy", nogil=True)  # nogil: the offline fit runs pieces of a pass on threads (passes._pass)
def run_rows(t, delta, vx, ax, kappa, z, release, M, G, S, st, acc, out, wk, predict_last):
    """Process all rows (module docstring); state, health and accumulators are updated in place.

    ``release[k]`` [m^2] is added to the variance of ``e1`` at the instant the frame of row ``k``
    shows, before its correction (:func:`release_e1`; zero on rows without a re-expression).

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
                nis, dof, n0, n1 = delayed_camera(st, zk, M, G, S, adapt_now, accumulate, acc, out.score, k, wk, zrow,
                                                  release[k])  # fmt: skip
            else:
                release_e1(st, release[k])
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
                if nx == 4:
                    _std4(st, nw, out.std, k)
                else:
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
                    release_e1(st, release[nf])
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


# numba's cache of these functions is stale when any file of the family changed (_jit_cache)
key_on_family(globals(), KERNEL_FAMILY)
