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


@njit(cache=True)
def _sign(x):
    if x > 0:
        return 1.0
    elif x < 0:
        return -1.0
    return 0.0


@njit(cache=True)
def pac_longitudinal(kappa, gamma, F_z, ty):
    """``formula_longitudinal``: pure-slip longitudinal force [N] (CommonRoad, ported)."""
    kappa = -kappa
    S_hx = ty[TY_PHX1]
    S_vx = F_z * ty[TY_PVX1]
    kappa_x = kappa + S_hx
    mu_x = ty[TY_PDX1] * (1 - ty[TY_PDX3] * gamma**2)
    C_x = ty[TY_PCX1]
    D_x = mu_x * F_z
    E_x = ty[TY_PEX1]
    K_x = F_z * ty[TY_PKX1]
    B_x = K_x / (C_x * D_x)
    return D_x * math.sin(C_x * math.atan(B_x * kappa_x - E_x * (B_x * kappa_x - math.atan(B_x * kappa_x))) + S_vx)


@njit(cache=True)
def pac_lateral(alpha, gamma, F_z, ty):
    """``formula_lateral``: pure-slip lateral force [N] and friction ``mu_y`` (CommonRoad, ported)."""
    sg = _sign(gamma)
    S_hy = sg * (ty[TY_PHY1] + ty[TY_PHY3] * math.fabs(gamma))
    S_vy = sg * F_z * (ty[TY_PVY1] + ty[TY_PVY3] * math.fabs(gamma))
    alpha_y = alpha + S_hy
    mu_y = ty[TY_PDY1] * (1 - ty[TY_PDY3] * gamma**2)
    C_y = ty[TY_PCY1]
    D_y = mu_y * F_z
    E_y = ty[TY_PEY1]
    K_y = F_z * ty[TY_PKY1]
    B_y = K_y / (C_y * D_y)
    F_y = D_y * math.sin(C_y * math.atan(B_y * alpha_y - E_y * (B_y * alpha_y - math.atan(B_y * alpha_y)))) + S_vy
    return F_y, mu_y


@njit(cache=True)
def pac_longitudinal_comb(kappa, alpha, F0_x, ty):
    """``formula_longitudinal_comb``: combined-slip longitudinal force [N] (CommonRoad, ported)."""
    S_hxalpha = ty[TY_RHX1]
    alpha_s = alpha + S_hxalpha
    B_xalpha = ty[TY_RBX1] * math.cos(math.atan(ty[TY_RBX2] * kappa))
    C_xalpha = ty[TY_RCX1]
    E_xalpha = ty[TY_REX1]
    D_xalpha = F0_x / (
        math.cos(C_xalpha * math.atan(B_xalpha * S_hxalpha - E_xalpha * (B_xalpha * S_hxalpha - math.atan(B_xalpha * S_hxalpha))))
    )
    return D_xalpha * math.cos(
        C_xalpha * math.atan(B_xalpha * alpha_s - E_xalpha * (B_xalpha * alpha_s - math.atan(B_xalpha * alpha_s)))
    )


@njit(cache=True)
def pac_lateral_comb(kappa, alpha, gamma, mu_y, F_z, F0_y, ty):
    """``formula_lateral_comb``: combined-slip lateral force [N] (CommonRoad, ported)."""
    S_hykappa = ty[TY_RHY1]
    kappa_s = kappa + S_hykappa
    B_ykappa = ty[TY_RBY1] * math.cos(math.atan(ty[TY_RBY2] * (alpha - ty[TY_RBY3])))
    C_ykappa = ty[TY_RCY1]
    E_ykappa = ty[TY_REY1]
    D_ykappa = F0_y / (
        math.cos(C_ykappa * math.atan(B_ykappa * S_hykappa - E_ykappa * (B_ykappa * S_hykappa - math.atan(B_ykappa * S_hykappa))))
    )
    D_vykappa = mu_y * F_z * (ty[TY_RVY1] + ty[TY_RVY3] * gamma) * math.cos(math.atan(ty[TY_RVY4] * alpha))
    S_vykappa = D_vykappa * math.sin(ty[TY_RVY5] * math.atan(ty[TY_RVY6] * kappa))
    return D_ykappa * math.cos(
        C_ykappa * math.atan(B_ykappa * kappa_s - E_ykappa * (B_ykappa * kappa_s - math.atan(B_ykappa * kappa_s)))
    ) + S_vykappa


@njit(cache=True)
def tire_lateral_force(alpha, kappa, gamma, F_z, ty):
    """Combined-slip lateral force of one tire [N] as the multi-body model computes it."""
    F0_y, mu_y = pac_lateral(alpha, gamma, F_z, ty)
    return pac_lateral_comb(kappa, alpha, gamma, mu_y, F_z, F0_y, ty)
