"""Prediction of the compiled estimator (:mod:`._kernel` documents the equations): the soft-clip
basis on plain arrays, slips and axle forces (eqs. 13, 14, 29, 30), the right-hand side and
its Jacobian, and :func:`predict`: RK4 sub-steps of the state with the sensitivity
``Upsilon`` and the covariance ``Sigma`` carried by the second-order transition.
"""

from __future__ import annotations

import math

from numba import njit

from .._jit_cache import key_on_family
from .._kernels import bicycle_slip_angles
from ._kernel_types import E1, E2, KERNEL_FAMILY, MODE_CAUSAL, R, V_FLOOR, VY


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
def axle_basis(a, axle, M, w, phi, dphi, wk):
    """Activations ``gamma sigma`` (eq. 30) into ``phi[axle N : (axle+1) N]``, their slopes into
    ``dphi``; returns ``(f, df/da)`` of the learned part of the axle force."""
    return _basis_arrays(a, axle, M.lam, M.gamma[axle], M.ub, M.nub, M.ilo, M.ihi, M.off, w, phi, dphi, wk.spm,
                         wk.spp, wk.ht)  # fmt: skip


@njit(cache=True, error_model="numpy")
def slip_angles(vy, r, delta, vx, lf, lr):
    """Front and rear slip angles [rad] (eq. 13, :func:`~tire_learning_env._kernels.bicycle_slip_angles`)
    with ``vx`` floored at ``V_FLOOR`` (the estimators' slips stay finite at standstill)."""
    return bicycle_slip_angles(vy, r, delta, vx if vx > V_FLOOR else V_FLOOR, lf, lr)


@njit(cache=True, error_model="numpy")
def forces(vy, r, delta, vx, w, M, wk):
    """``(alpha_f, alpha_r, F_f, F_r, f_f, f_r, k_f, k_r)``: slips, total and learned axle
    forces [N] and total slopes [N/rad]; fills ``phi``/``dphi`` (eqs. 13, 14, 29)."""
    af, ar = slip_angles(vy, r, delta, vx, M.veh[2], M.veh[3])
    ff, kf = axle_basis(af, 0, M, w, wk.phi, wk.dphi, wk)
    fr, kr = axle_basis(ar, 1, M, w, wk.phi, wk.dphi, wk)
    return af, ar, M.veh[4] * af + ff, M.veh[5] * ar + fr, ff, fr, M.veh[4] + kf, M.veh[5] + kr


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy", inline="always")
def matmul_into(A, B, out, n_rows, n_inner, n_cols):
    """``out[:n_rows, :n_cols] = A[:n_rows, :n_inner] @ B[:n_inner, :n_cols]``, each entry summed from 0 in
    ``q`` order (the order the covariance and gain products were written in; inlined, so bit-identical)."""
    for i in range(n_rows):
        for j in range(n_cols):
            acc = 0.0
            for q in range(n_inner):
                acc += A[i, q] * B[q, j]
            out[i, j] = acc


@njit(cache=True, error_model="numpy", inline="always")
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


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
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
        matmul_into(Phi, sig, T1, nx, nx, nx)
        matmul_into(T1, Phi.T, sig, nx, nx, nx)  # Phi.T: a transposed view, B[q, j] = Phi[j, q]
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


# numba's cache of these functions is stale when any file of the family changed (_jit_cache)
key_on_family(globals(), KERNEL_FAMILY)
