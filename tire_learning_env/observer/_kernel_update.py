"""Corrections and the health flag of the compiled estimator (:mod:`._kernel` documents the
equations): the measurement of a channel group, :func:`update` (causal RLS of the weights or
the fixed-mode normal equations, then the state correction with the certified or the Kalman
gain) and the health checks with checkpoint rollback.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .._jit_cache import key_on_family
from ._kernel_predict import forces, matmul_into
from ._kernel_types import (CH_AY, CH_E1, E1, E2, GROUP_CAMERA, HEALTH_DIVERGED, HEALTH_INCONSISTENT, HEALTH_NO_DATA,
                            HEALTH_OK, HEALTH_RECOVERING, HEALTH_SETTLING, HS_CKPT_HEAD, HS_CODE, HS_COUNT, HS_DOF,
                            HS_HEAD, HS_LAST_CKPT, HS_LAST_MEAS, HS_N_CKPT, HS_STARTED, HS_SUM, HS_T0, HS_TRIP_T,
                            HS_TRIPS, KERNEL_FAMILY, MODE_CAUSAL, R, V_FLOOR, VY)  # fmt: skip

_Z_CHI = 3.719  # standard normal quantile of 1 - 1e-4 (chi-square bound of the health test)


# -- corrections ------------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def _cell(edges, vx):
    n = edges.shape[0] - 1
    c = 0
    while c < n - 1 and vx >= edges[c + 1]:
        c += 1
    return c


@njit(cache=True, error_model="numpy")
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
        # e1 measured camera_x ahead of the CG (VehicleParams.camera_x; the path's bend over camera_x is taken off
        # the logged e1 before the passes, estimator.estimate): e1 + camera_x sin(e2)
        xc = M.veh[6]
        h0 = x[E1] + xc * math.sin(x[E2])
        h1 = x[E2]
        wk.H[0, E1] = 1.0
        wk.H[0, E2] = xc * math.cos(x[E2])
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


@njit(cache=True, error_model="numpy")
def _inv2(s00, s01, s11):
    det = s00 * s11 - s01 * s01
    if not det > 0.0:
        det = 1e-300
    return s11 / det, -s01 / det, s00 / det


@njit(cache=True, error_model="numpy")
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
        matmul_into(wk.Psi, st.pw, wk.PsiP, 2, nw, nw)
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
    matmul_into(wk.T1, st.sig, wk.Phi, nx, nx, nx)
    for i in range(nx):
        for j in range(nx):
            a_ = L[i, 0] * r0 * L[j, 0] + L[i, 1] * r1 * L[j, 1]
            for q in range(nx):
                a_ += wk.Phi[i, q] * wk.T1[j, q]
            st.sig[i, j] = a_
    return nis, dof, nu0_prior, nu1_prior


# -- health -----------------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def _chi2_upper(dof):
    """Wilson-Hilferty upper quantile (1 - 1e-4) of chi-square with ``dof`` degrees of freedom."""
    d = max(dof, 1.0)
    c = 2.0 / (9.0 * d)
    return d * (1.0 - c + _Z_CHI * math.sqrt(c)) ** 3


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
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


# numba's cache of these functions is stale when any file of the family changed (_jit_cache)
key_on_family(globals(), KERNEL_FAMILY)
