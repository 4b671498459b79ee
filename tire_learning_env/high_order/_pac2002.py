"""Compiled (numba) port of CommonRoad's PAC2002 tire (``vehiclemodels/utils/tire_model.py``).

Source: commonroad-vehicle-models 3.0.2 (M. Althoff and G. Würsching, TUM Cyber-Physical
Systems Group). Copyright 2020 Technical University of Munich, Professorship of
Cyber-Physical Systems; BSD 3-Clause License, reproduced in ``LICENSE_commonroad.txt``
next to this file. :func:`pac_longitudinal`, :func:`pac_lateral`, :func:`pac_longitudinal_comb`
and :func:`pac_lateral_comb` port ``formula_longitudinal``, ``formula_lateral``,
``formula_longitudinal_comb`` and ``formula_lateral_comb`` line by line, including their quirks
(``S_vx`` added inside the sine; ``p_hy1``/``p_vy1`` multiplied by ``sign(camber)``). The
multi-body model that calls them is :mod:`._mb_kernels`.
"""

from __future__ import annotations

import math

from numba import njit

# --- tire vector (order of Pac2002Tire fields) --------------------------------------------
(
    TY_PCX1, TY_PDX1, TY_PDX3, TY_PEX1, TY_PKX1, TY_PHX1, TY_PVX1, TY_RBX1, TY_RBX2, TY_RCX1, TY_REX1, TY_RHX1,
    TY_PCY1, TY_PDY1, TY_PDY3, TY_PEY1, TY_PKY1, TY_PHY1, TY_PHY3, TY_PVY1, TY_PVY3,
    TY_RBY1, TY_RBY2, TY_RBY3, TY_RCY1, TY_REY1, TY_RHY1, TY_RVY1, TY_RVY3, TY_RVY4, TY_RVY5, TY_RVY6,
) = range(32)  # fmt: skip
N_TIRE = 32


@njit(cache=True, error_model="numpy")
def _sign(x):
    if x > 0:
        return 1.0
    elif x < 0:
        return -1.0
    return 0.0


@njit(cache=True, inline="always", error_model="numpy")
def _mf_angle(x, B, C, E):
    """The Magic Formula's angle ``C atan(B x - E (B x - atan(B x)))`` [rad] (every formula below)."""
    return C * math.atan(B * x - E * (B * x - math.atan(B * x)))


@njit(cache=True, inline="always", error_model="numpy")
def _pure_slip_coefficients(gamma, F_z, p_d1, p_d3, p_c1, p_e1, p_k1):
    """``(B, C, D, E, mu)`` of a pure-slip formula: friction ``mu = p_d1 (1 - p_d3 gamma^2)``,
    peak ``D = mu F_z`` [N], slip stiffness ``K = F_z p_k1``, ``B = K / (C D)``."""
    mu = p_d1 * (1 - p_d3 * gamma**2)
    C = p_c1
    D = mu * F_z
    E = p_e1
    K = F_z * p_k1
    B = K / (C * D)
    return B, C, D, E, mu


@njit(cache=True, error_model="numpy")
def pac_longitudinal(kappa, gamma, F_z, ty):
    """``formula_longitudinal``: pure-slip longitudinal force [N] (CommonRoad, ported)."""
    kappa = -kappa
    S_hx = ty[TY_PHX1]
    S_vx = F_z * ty[TY_PVX1]
    kappa_x = kappa + S_hx
    B_x, C_x, D_x, E_x, _ = _pure_slip_coefficients(gamma, F_z, ty[TY_PDX1], ty[TY_PDX3], ty[TY_PCX1], ty[TY_PEX1], ty[TY_PKX1])
    return D_x * math.sin(_mf_angle(kappa_x, B_x, C_x, E_x) + S_vx)


@njit(cache=True, error_model="numpy")
def pac_lateral(alpha, gamma, F_z, ty):
    """``formula_lateral``: pure-slip lateral force [N] and friction ``mu_y`` (CommonRoad, ported)."""
    sg = _sign(gamma)
    S_hy = sg * (ty[TY_PHY1] + ty[TY_PHY3] * math.fabs(gamma))
    S_vy = sg * F_z * (ty[TY_PVY1] + ty[TY_PVY3] * math.fabs(gamma))
    alpha_y = alpha + S_hy
    B_y, C_y, D_y, E_y, mu_y = _pure_slip_coefficients(gamma, F_z, ty[TY_PDY1], ty[TY_PDY3], ty[TY_PCY1], ty[TY_PEY1], ty[TY_PKY1])
    F_y = D_y * math.sin(_mf_angle(alpha_y, B_y, C_y, E_y)) + S_vy
    return F_y, mu_y


@njit(cache=True, error_model="numpy")
def pac_longitudinal_comb(kappa, alpha, F0_x, ty):
    """``formula_longitudinal_comb``: combined-slip longitudinal force [N] (CommonRoad, ported)."""
    S_hxalpha = ty[TY_RHX1]
    alpha_s = alpha + S_hxalpha
    B_xalpha = ty[TY_RBX1] * math.cos(math.atan(ty[TY_RBX2] * kappa))
    C_xalpha = ty[TY_RCX1]
    E_xalpha = ty[TY_REX1]
    D_xalpha = F0_x / (math.cos(_mf_angle(S_hxalpha, B_xalpha, C_xalpha, E_xalpha)))
    return D_xalpha * math.cos(_mf_angle(alpha_s, B_xalpha, C_xalpha, E_xalpha))


@njit(cache=True, error_model="numpy")
def pac_lateral_comb(kappa, alpha, gamma, mu_y, F_z, F0_y, ty):
    """``formula_lateral_comb``: combined-slip lateral force [N] (CommonRoad, ported)."""
    S_hykappa = ty[TY_RHY1]
    kappa_s = kappa + S_hykappa
    B_ykappa = ty[TY_RBY1] * math.cos(math.atan(ty[TY_RBY2] * (alpha - ty[TY_RBY3])))
    C_ykappa = ty[TY_RCY1]
    E_ykappa = ty[TY_REY1]
    D_ykappa = F0_y / (math.cos(_mf_angle(S_hykappa, B_ykappa, C_ykappa, E_ykappa)))
    D_vykappa = mu_y * F_z * (ty[TY_RVY1] + ty[TY_RVY3] * gamma) * math.cos(math.atan(ty[TY_RVY4] * alpha))
    S_vykappa = D_vykappa * math.sin(ty[TY_RVY5] * math.atan(ty[TY_RVY6] * kappa))
    return D_ykappa * math.cos(_mf_angle(kappa_s, B_ykappa, C_ykappa, E_ykappa)) + S_vykappa


@njit(cache=True, error_model="numpy")
def tire_lateral_force(alpha, kappa, gamma, F_z, ty):
    """Combined-slip lateral force of one tire [N] as the multi-body model computes it."""
    F0_y, mu_y = pac_lateral(alpha, gamma, F_z, ty)
    return pac_lateral_comb(kappa, alpha, gamma, mu_y, F_z, F0_y, ty)
