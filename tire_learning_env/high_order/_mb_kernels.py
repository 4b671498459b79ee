"""Compiled (numba) port of CommonRoad's multi-body vehicle model and its PAC2002 tire.

Source: commonroad-vehicle-models 3.0.2 (M. Althoff and G. Würsching, TUM Cyber-Physical
Systems Group). Copyright 2020 Technical University of Munich, Professorship of
Cyber-Physical Systems; BSD 3-Clause License, reproduced in ``LICENSE_commonroad.txt``
next to this file. The port:

- :func:`pac_longitudinal`, :func:`pac_lateral`, :func:`pac_longitudinal_comb`,
  :func:`pac_lateral_comb` port ``vehiclemodels/utils/tire_model.py`` (``formula_longitudinal``,
  ``formula_lateral``, ``formula_longitudinal_comb``, ``formula_lateral_comb``) line by line,
  including its quirks (``S_vx`` added inside the sine; ``p_hy1``/``p_vy1`` multiplied by
  ``sign(camber)``);
- :func:`mb_rhs` ports ``vehiclemodels/vehicle_dynamics_mb.py`` (``vehicle_dynamics_mb``,
  with ``steering_constraints``, ``acceleration_constraints`` and, below 0.1 m/s,
  ``vehicle_dynamics_ks_cog``), operation for operation so that a test can compare it
  with the original to ~1e-12 relative.

The only addition inside :func:`mb_rhs` is optional: the tire forces may be evaluated at
*lagged* slip angles (tire relaxation) instead of the kinematic ones.
:func:`plant_rhs` and :func:`plant_rk4_step` wrap it with the extra states of the truth
plant (four relaxation lags and the PI speed controller's integral); :func:`path_errors`
gives the lane-camera errors of a pose relative to a tabulated path.

State layout: ``S_*`` indices 0-28 are CommonRoad's ``x1..x29`` (0-based), then
``S_LAG_LF..S_LAG_RR`` (lagged slip angles, CommonRoad sign) and ``S_SPEED_INT``; the port
indexes the state and its derivative by these names only (``x[S_VY]`` for CommonRoad's ``x[10]``).
Per-wheel blocks of ``aux``: ``AUX_* + W_LF..W_RR``; camera errors: ``ERR_*``
(:class:`~tire_learning_env.dynamics.StateIndex`'s order).
Parameter vector: ``MB_*`` indices (:func:`~tire_learning_env.high_order.plant.parameter_vector`),
tire vector: ``TY_*`` indices (the order of :class:`~.params.Pac2002Tire`'s fields; the tire
functions and their layout live in :mod:`._pac2002` and are re-exported here).

The compiled functions here call :mod:`._pac2002`'s: the two files form one numba cache family,
:data:`MB_FAMILY`, and this module stamps its cache with the digest of both
(:func:`tire_learning_env._jit_cache.key_on_family`), so an edit to the tire functions recompiles
the model that calls them (numba alone would only check this file).
"""

from __future__ import annotations

import math
from pathlib import Path

from numba import njit

from .._jit_cache import key_on_family
from ._pac2002 import pac_lateral, pac_lateral_comb, pac_longitudinal, pac_longitudinal_comb

#: The source files of the compiled multi-body model, callees first.
MB_FAMILY = tuple(Path(__file__).with_name(name) for name in ("_pac2002.py", "_mb_kernels.py"))

# --- state indices (CommonRoad x1..x29 -> 0..28) ---------------------------------------
(
    S_X, S_Y, S_DELTA, S_VX, S_PSI, S_R, S_ROLL, S_ROLL_RATE, S_PITCH, S_PITCH_RATE, S_VY, S_Z, S_VZ,
    S_ROLL_F, S_ROLL_RATE_F, S_VY_F, S_Z_F, S_VZ_F,
    S_ROLL_R, S_ROLL_RATE_R, S_VY_R, S_Z_R, S_VZ_R,
    S_OMEGA_LF, S_OMEGA_RF, S_OMEGA_LR, S_OMEGA_RR, S_DY_F, S_DY_R,
) = range(29)  # fmt: skip
N_MB = 29
S_LAG_LF, S_LAG_RF, S_LAG_LR, S_LAG_RR, S_SPEED_INT = range(29, 34)
N_STATE = 34
STATE_NAMES = (
    "x", "y", "delta", "vx", "psi", "yaw_rate", "roll", "roll_rate", "pitch", "pitch_rate", "vy", "z", "vz",
    "roll_f", "roll_rate_f", "vy_f", "z_f", "vz_f", "roll_r", "roll_rate_r", "vy_r", "z_r", "vz_r",
    "omega_lf", "omega_rf", "omega_lr", "omega_rr", "delta_y_f", "delta_y_r",
    "lag_alpha_lf", "lag_alpha_rf", "lag_alpha_lr", "lag_alpha_rr", "speed_integral",
)  # fmt: skip

# --- parameter vector -------------------------------------------------------------------
(
    MB_M, MB_MS, MB_MUF, MB_MUR, MB_A, MB_B, MB_IPHI, MB_IY, MB_IZ, MB_IXZ,
    MB_KSF, MB_KSDF, MB_KSR, MB_KSDR, MB_TF, MB_TR, MB_KRAS, MB_KTSF, MB_KTSR, MB_KRAD, MB_KZT,
    MB_HRAF, MB_HRAR, MB_HS, MB_IUF, MB_IUR, MB_IYW, MB_KLT, MB_RW, MB_TSB, MB_TSE,
    MB_DF, MB_DR, MB_EF, MB_ER,
    MB_SMIN, MB_SMAX, MB_SVMIN, MB_SVMAX, MB_VMIN, MB_VMAX, MB_VSW, MB_AMAX,
    OPT_RELAX, OPT_TSTEER, OPT_KP, OPT_KI,
) = range(47)  # fmt: skip
N_PAR = 47

# --- lane-camera error state written by plant_tick (dynamics.StateIndex's order) -----------
ERR_E1, ERR_E1_DOT, ERR_E2, ERR_E2_DOT = range(4)

# --- auxiliary outputs of mb_rhs: blocks of N_WHEELS, a wheel at offset W_* in each -------
W_LF, W_RF, W_LR, W_RR = range(4)
N_WHEELS = 4
AUX_ALPHA = 0  # kinematic slip angles, CommonRoad sign [rad] (4)
AUX_UW = 4  # wheel longitudinal speeds [m/s] (4)
AUX_FX = 8  # longitudinal tire forces, wheel frame [N] (4)
AUX_FY = 12  # lateral tire forces, wheel frame [N] (4)
AUX_FZ = 16  # vertical tire forces [N] (4)
AUX_KAPPA = 20  # longitudinal slips [-] (4)
AUX_GAMMA = 24  # camber angles [rad] (4)
N_AUX = 28

_G = 9.81  # CommonRoad's gravity [m/s^2]


@njit(cache=True, error_model="numpy")
def _steering_constraints(steering_angle, steering_velocity, p):
    if (steering_angle <= p[MB_SMIN] and steering_velocity <= 0) or (steering_angle >= p[MB_SMAX] and steering_velocity >= 0):
        steering_velocity = 0.0
    elif steering_velocity <= p[MB_SVMIN]:
        steering_velocity = p[MB_SVMIN]
    elif steering_velocity >= p[MB_SVMAX]:
        steering_velocity = p[MB_SVMAX]
    return steering_velocity


@njit(cache=True, error_model="numpy")
def _acceleration_constraints(velocity, acceleration, p):
    if velocity > p[MB_VSW]:
        posLimit = p[MB_AMAX] * p[MB_VSW] / velocity
    else:
        posLimit = p[MB_AMAX]
    if (velocity <= p[MB_VMIN] and acceleration <= 0) or (velocity >= p[MB_VMAX] and acceleration >= 0):
        acceleration = 0.0
    elif acceleration <= -p[MB_AMAX]:
        acceleration = -p[MB_AMAX]
    elif acceleration >= posLimit:
        acceleration = posLimit
    return acceleration


@njit(cache=True, inline="always", error_model="numpy")
def _zero_if_negative(u):
    """``u * 0`` when ``u < 0`` (CommonRoad's ``u *= 0``: a negative wheel speed becomes -0.0), else ``u``."""
    if u < 0.0:
        return u * 0
    return u


@njit(cache=True, inline="always", error_model="numpy")
def _unsprung_roll_moment(F_SL, F_SR, T, F_RA, h_ra, R_w, phi_u, F_zL, F_zR, K_lt, F_yL, F_yR, F_lat, z_u):
    """Roll moment sum [N m] on one axle's unsprung mass (``sumL_uf`` / ``sumL_ur`` of CommonRoad):
    suspension forces ``F_SL``, ``F_SR`` on track ``T``, compliant-joint force ``F_RA`` at height
    ``h_ra``, tire loads and lateral forces, the axle's lateral force ``F_lat`` in the body frame
    at the unsprung roll angle ``phi_u`` and vertical position ``z_u``."""
    return (
        0.5 * F_SR * T
        - 0.5 * F_SL * T
        - F_RA * (h_ra - R_w)
        + F_zL * (R_w * math.sin(phi_u) + 0.5 * T * math.cos(phi_u) - K_lt * F_yL)
        - F_zR * (-R_w * math.sin(phi_u) + 0.5 * T * math.cos(phi_u) + K_lt * F_yR)
        - F_lat * (R_w - z_u)
    )


@njit(cache=True, error_model="numpy")
def mb_rhs(x, u_steer_rate, u_accel, p, ty, use_lag, f, aux):
    """Right-hand side of CommonRoad's ``vehicle_dynamics_mb`` (29 states), ported.

    Parameters
    ----------
    x : ndarray, shape (>= 29,)
        State (CommonRoad layout); with ``use_lag`` also ``x[S_LAG_LF:S_LAG_RR+1]``.
    u_steer_rate, u_accel : float
        CommonRoad's inputs: steering velocity [rad/s] and acceleration [m/s^2].
    p, ty : ndarray
        Parameter (``MB_*``) and tire (``TY_*``) vectors.
    use_lag : bool
        Evaluate the tire forces at the lagged slip angles ``x[S_LAG_*]`` (relaxation)
        instead of the kinematic ones. ``False`` is CommonRoad's model exactly.
    f : ndarray, shape (>= 29,)
        Output: ``f[:29]`` = dx/dt.
    aux : ndarray, shape (N_AUX,)
        Output: per-wheel kinematic slip, wheel speed, forces, loads, slip ratio, camber.
    """
    g = _G
    a, b = p[MB_A], p[MB_B]
    T_f, T_r, R_w = p[MB_TF], p[MB_TR], p[MB_RW]
    u0 = _steering_constraints(x[S_DELTA], u_steer_rate, p)
    u1 = _acceleration_constraints(x[S_VX], u_accel, p)

    if abs(x[S_VX]) < 0.1:
        beta = 0.0
    else:
        beta = math.atan(x[S_VY] / x[S_VX])
    vel = math.sqrt(x[S_VX] ** 2 + x[S_VY] ** 2)

    # vertical tire forces
    F_z_LF = (x[S_Z_F] + R_w * (math.cos(x[S_ROLL_F]) - 1) - 0.5 * T_f * math.sin(x[S_ROLL_F])) * p[MB_KZT]
    F_z_RF = (x[S_Z_F] + R_w * (math.cos(x[S_ROLL_F]) - 1) + 0.5 * T_f * math.sin(x[S_ROLL_F])) * p[MB_KZT]
    F_z_LR = (x[S_Z_R] + R_w * (math.cos(x[S_ROLL_R]) - 1) - 0.5 * T_r * math.sin(x[S_ROLL_R])) * p[MB_KZT]
    F_z_RR = (x[S_Z_R] + R_w * (math.cos(x[S_ROLL_R]) - 1) + 0.5 * T_r * math.sin(x[S_ROLL_R])) * p[MB_KZT]

    # individual tire speeds
    u_w_lf = (x[S_VX] + 0.5 * T_f * x[S_R]) * math.cos(x[S_DELTA]) + (x[S_VY] + a * x[S_R]) * math.sin(x[S_DELTA])
    u_w_rf = (x[S_VX] - 0.5 * T_f * x[S_R]) * math.cos(x[S_DELTA]) + (x[S_VY] + a * x[S_R]) * math.sin(x[S_DELTA])
    u_w_lr = x[S_VX] + 0.5 * T_r * x[S_R]
    u_w_rr = x[S_VX] - 0.5 * T_r * x[S_R]
    u_w_lf = _zero_if_negative(u_w_lf)
    u_w_rf = _zero_if_negative(u_w_rf)
    u_w_lr = _zero_if_negative(u_w_lr)
    u_w_rr = _zero_if_negative(u_w_rr)

    # longitudinal slip and lateral slip angles (kinematic); both zero below 0.1 m/s
    if abs(x[S_VX]) < 0.1:
        s_lf = s_rf = s_lr = s_rr = 0.0
        alpha_LF = alpha_RF = alpha_LR = alpha_RR = 0.0
    else:
        s_lf = 1 - R_w * x[S_OMEGA_LF] / u_w_lf
        s_rf = 1 - R_w * x[S_OMEGA_RF] / u_w_rf
        s_lr = 1 - R_w * x[S_OMEGA_LR] / u_w_lr
        s_rr = 1 - R_w * x[S_OMEGA_RR] / u_w_rr
        alpha_LF = math.atan((x[S_VY] + a * x[S_R] - x[S_ROLL_RATE_F] * (R_w - x[S_Z_F])) / (x[S_VX] + 0.5 * T_f * x[S_R])) - x[S_DELTA]
        alpha_RF = math.atan((x[S_VY] + a * x[S_R] - x[S_ROLL_RATE_F] * (R_w - x[S_Z_F])) / (x[S_VX] - 0.5 * T_f * x[S_R])) - x[S_DELTA]
        alpha_LR = math.atan((x[S_VY] - b * x[S_R] - x[S_ROLL_RATE_R] * (R_w - x[S_Z_R])) / (x[S_VX] + 0.5 * T_r * x[S_R]))
        alpha_RR = math.atan((x[S_VY] - b * x[S_R] - x[S_ROLL_RATE_R] * (R_w - x[S_Z_R])) / (x[S_VX] - 0.5 * T_r * x[S_R]))
    aux[AUX_ALPHA + W_LF] = alpha_LF
    aux[AUX_ALPHA + W_RF] = alpha_RF
    aux[AUX_ALPHA + W_LR] = alpha_LR
    aux[AUX_ALPHA + W_RR] = alpha_RR
    if use_lag:  # tire relaxation: forces act on the lagged slip
        alpha_LF = x[S_LAG_LF]
        alpha_RF = x[S_LAG_RF]
        alpha_LR = x[S_LAG_LR]
        alpha_RR = x[S_LAG_RR]

    # auxiliary suspension movement
    h_s = p[MB_HS]
    z_SLF = (h_s - R_w + x[S_Z_F] - x[S_Z]) / math.cos(x[S_ROLL]) - h_s + R_w + a * x[S_PITCH] + 0.5 * (x[S_ROLL] - x[S_ROLL_F]) * T_f
    z_SRF = (h_s - R_w + x[S_Z_F] - x[S_Z]) / math.cos(x[S_ROLL]) - h_s + R_w + a * x[S_PITCH] - 0.5 * (x[S_ROLL] - x[S_ROLL_F]) * T_f
    z_SLR = (h_s - R_w + x[S_Z_R] - x[S_Z]) / math.cos(x[S_ROLL]) - h_s + R_w - b * x[S_PITCH] + 0.5 * (x[S_ROLL] - x[S_ROLL_R]) * T_r
    z_SRR = (h_s - R_w + x[S_Z_R] - x[S_Z]) / math.cos(x[S_ROLL]) - h_s + R_w - b * x[S_PITCH] - 0.5 * (x[S_ROLL] - x[S_ROLL_R]) * T_r

    dz_SLF = x[S_VZ_F] - x[S_VZ] + a * x[S_PITCH_RATE] + 0.5 * (x[S_ROLL_RATE] - x[S_ROLL_RATE_F]) * T_f
    dz_SRF = x[S_VZ_F] - x[S_VZ] + a * x[S_PITCH_RATE] - 0.5 * (x[S_ROLL_RATE] - x[S_ROLL_RATE_F]) * T_f
    dz_SLR = x[S_VZ_R] - x[S_VZ] - b * x[S_PITCH_RATE] + 0.5 * (x[S_ROLL_RATE] - x[S_ROLL_RATE_R]) * T_r
    dz_SRR = x[S_VZ_R] - x[S_VZ] - b * x[S_PITCH_RATE] - 0.5 * (x[S_ROLL_RATE] - x[S_ROLL_RATE_R]) * T_r

    # camber angles
    gamma_LF = x[S_ROLL] + p[MB_DF] * z_SLF + p[MB_EF] * (z_SLF) ** 2
    gamma_RF = x[S_ROLL] - p[MB_DF] * z_SRF - p[MB_EF] * (z_SRF) ** 2
    gamma_LR = x[S_ROLL] + p[MB_DR] * z_SLR + p[MB_ER] * (z_SLR) ** 2
    gamma_RR = x[S_ROLL] - p[MB_DR] * z_SRR - p[MB_ER] * (z_SRR) ** 2

    # pure-slip forces
    F0_x_LF = pac_longitudinal(s_lf, gamma_LF, F_z_LF, ty)
    F0_x_RF = pac_longitudinal(s_rf, gamma_RF, F_z_RF, ty)
    F0_x_LR = pac_longitudinal(s_lr, gamma_LR, F_z_LR, ty)
    F0_x_RR = pac_longitudinal(s_rr, gamma_RR, F_z_RR, ty)
    F0_y_LF, mu_y_LF = pac_lateral(alpha_LF, gamma_LF, F_z_LF, ty)
    F0_y_RF, mu_y_RF = pac_lateral(alpha_RF, gamma_RF, F_z_RF, ty)
    F0_y_LR, mu_y_LR = pac_lateral(alpha_LR, gamma_LR, F_z_LR, ty)
    F0_y_RR, mu_y_RR = pac_lateral(alpha_RR, gamma_RR, F_z_RR, ty)

    # combined-slip forces
    F_x_LF = pac_longitudinal_comb(s_lf, alpha_LF, F0_x_LF, ty)
    F_x_RF = pac_longitudinal_comb(s_rf, alpha_RF, F0_x_RF, ty)
    F_x_LR = pac_longitudinal_comb(s_lr, alpha_LR, F0_x_LR, ty)
    F_x_RR = pac_longitudinal_comb(s_rr, alpha_RR, F0_x_RR, ty)
    F_y_LF = pac_lateral_comb(s_lf, alpha_LF, gamma_LF, mu_y_LF, F_z_LF, F0_y_LF, ty)
    F_y_RF = pac_lateral_comb(s_rf, alpha_RF, gamma_RF, mu_y_RF, F_z_RF, F0_y_RF, ty)
    F_y_LR = pac_lateral_comb(s_lr, alpha_LR, gamma_LR, mu_y_LR, F_z_LR, F0_y_LR, ty)
    F_y_RR = pac_lateral_comb(s_rr, alpha_RR, gamma_RR, mu_y_RR, F_z_RR, F0_y_RR, ty)

    # auxiliary movements for compliant joint equations
    delta_z_f = h_s - R_w + x[S_Z_F] - x[S_Z]
    delta_z_r = h_s - R_w + x[S_Z_R] - x[S_Z]
    delta_phi_f = x[S_ROLL] - x[S_ROLL_F]
    delta_phi_r = x[S_ROLL] - x[S_ROLL_R]
    dot_delta_phi_f = x[S_ROLL_RATE] - x[S_ROLL_RATE_F]
    dot_delta_phi_r = x[S_ROLL_RATE] - x[S_ROLL_RATE_R]
    dot_delta_z_f = x[S_VZ_F] - x[S_VZ]
    dot_delta_z_r = x[S_VZ_R] - x[S_VZ]
    dot_delta_y_f = x[S_VY] + a * x[S_R] - x[S_VY_F]
    dot_delta_y_r = x[S_VY] - b * x[S_R] - x[S_VY_R]
    h_raf, h_rar = p[MB_HRAF], p[MB_HRAR]
    delta_f = delta_z_f * math.sin(x[S_ROLL]) - x[S_DY_F] * math.cos(x[S_ROLL]) - (h_raf - R_w) * math.sin(delta_phi_f)
    delta_r = delta_z_r * math.sin(x[S_ROLL]) - x[S_DY_R] * math.cos(x[S_ROLL]) - (h_rar - R_w) * math.sin(delta_phi_r)
    dot_delta_f = (
        (delta_z_f * math.cos(x[S_ROLL]) + x[S_DY_F] * math.sin(x[S_ROLL])) * x[S_ROLL_RATE]
        + dot_delta_z_f * math.sin(x[S_ROLL])
        - dot_delta_y_f * math.cos(x[S_ROLL])
        - (h_raf - R_w) * math.cos(delta_phi_f) * dot_delta_phi_f
    )
    dot_delta_r = (
        (delta_z_r * math.cos(x[S_ROLL]) + x[S_DY_R] * math.sin(x[S_ROLL])) * x[S_ROLL_RATE]
        + dot_delta_z_r * math.sin(x[S_ROLL])
        - dot_delta_y_r * math.cos(x[S_ROLL])
        - (h_rar - R_w) * math.cos(delta_phi_r) * dot_delta_phi_r
    )

    # compliant joint forces
    F_RAF = delta_f * p[MB_KRAS] + dot_delta_f * p[MB_KRAD]
    F_RAR = delta_r * p[MB_KRAS] + dot_delta_r * p[MB_KRAD]

    # suspension forces (bump stop, squat/lift neglected)
    m_s = p[MB_MS]
    L = a + b
    F_SLF = m_s * g * b / (2 * (a + b)) - z_SLF * p[MB_KSF] - dz_SLF * p[MB_KSDF] + (x[S_ROLL] - x[S_ROLL_F]) * p[MB_KTSF] / T_f
    F_SRF = m_s * g * b / (2 * (a + b)) - z_SRF * p[MB_KSF] - dz_SRF * p[MB_KSDF] - (x[S_ROLL] - x[S_ROLL_F]) * p[MB_KTSF] / T_f
    F_SLR = m_s * g * a / (2 * (a + b)) - z_SLR * p[MB_KSR] - dz_SLR * p[MB_KSDR] + (x[S_ROLL] - x[S_ROLL_R]) * p[MB_KTSR] / T_r
    F_SRR = m_s * g * a / (2 * (a + b)) - z_SRR * p[MB_KSR] - dz_SRR * p[MB_KSDR] - (x[S_ROLL] - x[S_ROLL_R]) * p[MB_KTSR] / T_r

    # sprung mass sums
    c2, s2 = math.cos(x[S_DELTA]), math.sin(x[S_DELTA])
    sumX = F_x_LR + F_x_RR + (F_x_LF + F_x_RF) * c2 - (F_y_LF + F_y_RF) * s2
    sumN = (
        (F_y_LF + F_y_RF) * a * c2
        + (F_x_LF + F_x_RF) * a * s2
        + (F_y_RF - F_y_LF) * 0.5 * T_f * s2
        + (F_x_LF - F_x_RF) * 0.5 * T_f * c2
        + (F_x_LR - F_x_RR) * 0.5 * T_r
        - (F_y_LR + F_y_RR) * b
    )
    sumY_s = (F_RAF + F_RAR) * math.cos(x[S_ROLL]) + (F_SLF + F_SLR + F_SRF + F_SRR) * math.sin(x[S_ROLL])
    sumL = (
        0.5 * F_SLF * T_f
        + 0.5 * F_SLR * T_r
        - 0.5 * F_SRF * T_f
        - 0.5 * F_SRR * T_r
        - F_RAF / math.cos(x[S_ROLL]) * (h_s - x[S_Z] - R_w + x[S_Z_F] - (h_raf - R_w) * math.cos(x[S_ROLL_F]))
        - F_RAR / math.cos(x[S_ROLL]) * (h_s - x[S_Z] - R_w + x[S_Z_R] - (h_rar - R_w) * math.cos(x[S_ROLL_R]))
    )
    sumZ_s = (F_SLF + F_SLR + F_SRF + F_SRR) * math.cos(x[S_ROLL]) - (F_RAF + F_RAR) * math.sin(x[S_ROLL])
    sumM_s = a * (F_SLF + F_SRF) - b * (F_SLR + F_SRR) + (
        (F_x_LF + F_x_RF) * c2 - (F_y_LF + F_y_RF) * s2 + F_x_LR + F_x_RR
    ) * (h_s - x[S_Z])

    # unsprung mass sums
    K_lt = p[MB_KLT]
    sumL_uf = _unsprung_roll_moment(F_SLF, F_SRF, T_f, F_RAF, h_raf, R_w, x[S_ROLL_F], F_z_LF, F_z_RF, K_lt, F_y_LF, F_y_RF,
                                    (F_y_LF + F_y_RF) * c2 + (F_x_LF + F_x_RF) * s2, x[S_Z_F])  # fmt: skip
    sumL_ur = _unsprung_roll_moment(F_SLR, F_SRR, T_r, F_RAR, h_rar, R_w, x[S_ROLL_R], F_z_LR, F_z_RR, K_lt, F_y_LR, F_y_RR,
                                    F_y_LR + F_y_RR, x[S_Z_R])  # fmt: skip
    sumZ_uf = F_z_LF + F_z_RF + F_RAF * math.sin(x[S_ROLL]) - (F_SLF + F_SRF) * math.cos(x[S_ROLL])
    sumZ_ur = F_z_LR + F_z_RR + F_RAR * math.sin(x[S_ROLL]) - (F_SLR + F_SRR) * math.cos(x[S_ROLL])
    sumY_uf = (F_y_LF + F_y_RF) * c2 + (F_x_LF + F_x_RF) * s2 - F_RAF * math.cos(x[S_ROLL]) - (F_SLF + F_SRF) * math.sin(x[S_ROLL])
    sumY_ur = (F_y_LR + F_y_RR) - F_RAR * math.cos(x[S_ROLL]) - (F_SLR + F_SRR) * math.sin(x[S_ROLL])

    I_z, I_xz, I_phi = p[MB_IZ], p[MB_IXZ], p[MB_IPHI]
    if abs(x[S_VX]) < 0.1:
        # kinematic single-track model at the centre of mass (vehicle_dynamics_ks_cog)
        lwb = L
        beta_ks = math.atan(math.tan(x[S_DELTA]) * b / lwb)
        f[S_X] = x[S_VX] * math.cos(beta_ks + x[S_PSI])
        f[S_Y] = x[S_VX] * math.sin(beta_ks + x[S_PSI])
        f[S_DELTA] = u0
        f[S_VX] = u1
        f[S_PSI] = x[S_VX] * math.cos(beta_ks) * math.tan(x[S_DELTA]) / lwb
        d_beta = (b * u0) / (lwb * math.cos(x[S_DELTA]) ** 2 * (1 + (math.tan(x[S_DELTA]) ** 2 * b / lwb) ** 2))
        f[S_R] = 1 / lwb * (
            u1 * math.cos(x[S_ROLL]) * math.tan(x[S_DELTA])
            - x[S_VX] * math.sin(x[S_ROLL]) * d_beta * math.tan(x[S_DELTA])
            + x[S_VX] * math.cos(x[S_ROLL]) * u0 / math.cos(x[S_DELTA]) ** 2
        )
    else:
        f[S_X] = math.cos(beta + x[S_PSI]) * vel
        f[S_Y] = math.sin(beta + x[S_PSI]) * vel
        f[S_DELTA] = u0
        f[S_VX] = 1 / p[MB_M] * sumX + x[S_R] * x[S_VY]
        f[S_PSI] = x[S_R]
        f[S_R] = 1 / (I_z - (I_xz) ** 2 / I_phi) * (sumN + I_xz / I_phi * sumL)

    # remaining sprung mass dynamics
    f[S_ROLL] = x[S_ROLL_RATE]
    f[S_ROLL_RATE] = 1 / (I_phi - (I_xz) ** 2 / I_z) * (I_xz / I_z * sumN + sumL)
    f[S_PITCH] = x[S_PITCH_RATE]
    f[S_PITCH_RATE] = 1 / p[MB_IY] * sumM_s
    f[S_VY] = 1 / m_s * sumY_s - x[S_R] * x[S_VX]
    f[S_Z] = x[S_VZ]
    f[S_VZ] = g - 1 / m_s * sumZ_s
    # unsprung mass dynamics (front)
    f[S_ROLL_F] = x[S_ROLL_RATE_F]
    f[S_ROLL_RATE_F] = 1 / p[MB_IUF] * sumL_uf
    f[S_VY_F] = 1 / p[MB_MUF] * sumY_uf - x[S_R] * x[S_VX]
    f[S_Z_F] = x[S_VZ_F]
    f[S_VZ_F] = g - 1 / p[MB_MUF] * sumZ_uf
    # unsprung mass dynamics (rear)
    f[S_ROLL_R] = x[S_ROLL_RATE_R]
    f[S_ROLL_RATE_R] = 1 / p[MB_IUR] * sumL_ur
    f[S_VY_R] = 1 / p[MB_MUR] * sumY_ur - x[S_R] * x[S_VX]
    f[S_Z_R] = x[S_VZ_R]
    f[S_VZ_R] = g - 1 / p[MB_MUR] * sumZ_ur

    # acceleration input to brake and engine torque
    if u1 > 0:
        T_B = 0.0
        T_E = p[MB_M] * R_w * u1
    else:
        T_B = p[MB_M] * R_w * u1
        T_E = 0.0
    T_sb, T_se, I_y_w = p[MB_TSB], p[MB_TSE], p[MB_IYW]
    f[S_OMEGA_LF] = 1 / I_y_w * (-R_w * F_x_LF + 0.5 * T_sb * T_B + 0.5 * T_se * T_E)
    f[S_OMEGA_RF] = 1 / I_y_w * (-R_w * F_x_RF + 0.5 * T_sb * T_B + 0.5 * T_se * T_E)
    f[S_OMEGA_LR] = 1 / I_y_w * (-R_w * F_x_LR + 0.5 * (1 - T_sb) * T_B + 0.5 * (1 - T_se) * T_E)
    f[S_OMEGA_RR] = 1 / I_y_w * (-R_w * F_x_RR + 0.5 * (1 - T_sb) * T_B + 0.5 * (1 - T_se) * T_E)
    # negative wheel spin forbidden (CommonRoad also clamps the state; the integrator does)
    for i in range(S_OMEGA_LF, S_OMEGA_RR + 1):
        if x[i] < 0.0:
            f[i] = 0.0
    # compliant joint equations
    f[S_DY_F] = dot_delta_y_f
    f[S_DY_R] = dot_delta_y_r

    aux[AUX_UW + W_LF] = u_w_lf
    aux[AUX_UW + W_RF] = u_w_rf
    aux[AUX_UW + W_LR] = u_w_lr
    aux[AUX_UW + W_RR] = u_w_rr
    aux[AUX_FX + W_LF] = F_x_LF
    aux[AUX_FX + W_RF] = F_x_RF
    aux[AUX_FX + W_LR] = F_x_LR
    aux[AUX_FX + W_RR] = F_x_RR
    aux[AUX_FY + W_LF] = F_y_LF
    aux[AUX_FY + W_RF] = F_y_RF
    aux[AUX_FY + W_LR] = F_y_LR
    aux[AUX_FY + W_RR] = F_y_RR
    aux[AUX_FZ + W_LF] = F_z_LF
    aux[AUX_FZ + W_RF] = F_z_RF
    aux[AUX_FZ + W_LR] = F_z_LR
    aux[AUX_FZ + W_RR] = F_z_RR
    aux[AUX_KAPPA + W_LF] = s_lf
    aux[AUX_KAPPA + W_RF] = s_rf
    aux[AUX_KAPPA + W_LR] = s_lr
    aux[AUX_KAPPA + W_RR] = s_rr
    aux[AUX_GAMMA + W_LF] = gamma_LF
    aux[AUX_GAMMA + W_RF] = gamma_RF
    aux[AUX_GAMMA + W_LR] = gamma_LR
    aux[AUX_GAMMA + W_RR] = gamma_RR


@njit(cache=True, error_model="numpy")
def plant_rhs(x, delta_cmd, v_ref, a_ff, p, ty, f, aux):
    """Truth-plant right-hand side: :func:`mb_rhs` + steering servo + relaxation lags + PI speed.

    Steering: with ``p[OPT_TSTEER] > 0`` the steering velocity is
    ``(delta_cmd - delta) / T`` (then CommonRoad's rate/angle limits); otherwise 0 and the
    caller holds ``x[S_DELTA] = delta_cmd``. Speed: acceleration input
    ``a_ff + kp (v_ref - vx) + ki integral(v_ref - vx)``. Relaxation (``sigma > 0``):
    ``dalpha'/dt = |u_w| / sigma (alpha - alpha')`` per wheel.
    """
    tst = p[OPT_TSTEER]
    u0 = (delta_cmd - x[S_DELTA]) / tst if tst > 0.0 else 0.0
    ev = v_ref - x[S_VX]
    u1 = a_ff + p[OPT_KP] * ev + p[OPT_KI] * x[S_SPEED_INT]
    sigma = p[OPT_RELAX]
    mb_rhs(x, u0, u1, p, ty, sigma > 0.0, f, aux)
    for i in range(N_WHEELS):
        if sigma > 0.0:
            f[S_LAG_LF + i] = abs(aux[AUX_UW + i]) / sigma * (aux[AUX_ALPHA + i] - x[S_LAG_LF + i])
        else:
            f[S_LAG_LF + i] = 0.0
    f[S_SPEED_INT] = ev


# --- truth at one instant ------------------------------------------------------------------
# out vector of plant_rk4_step / truth_from_rhs
(
    TR_ALPHA_F, TR_ALPHA_R, TR_FYF, TR_FYR, TR_YAW_RATE, TR_AY, TR_VY, TR_VX, TR_DELTA,
) = range(9)  # fmt: skip
N_TRUTH = 9


@njit(cache=True, error_model="numpy")
def truth_from_rhs(x, f, aux, p, out):
    """Bicycle-level truth from a state and its derivative (SPEC §1 conventions).

    Axle forces in the body frame: front ``(F_y,LF + F_y,RF) cos(delta) + (F_x,LF + F_x,RF)
    sin(delta)``, rear ``F_y,LR + F_y,RR`` (positive to the left). Axle slips: eq. (13)
    with the body velocities, ``alpha_f = delta - (v_y + a r)/v_x``,
    ``alpha_r = (b r - v_y)/v_x``. ``ay``: lateral acceleration of the reference point
    (sprung-mass CG), ``dv_y/dt + r v_x``.
    """
    d = x[S_DELTA]
    vx, vy, r = x[S_VX], x[S_VY], x[S_R]
    c, s = math.cos(d), math.sin(d)
    out[TR_FYF] = (aux[AUX_FY + W_LF] + aux[AUX_FY + W_RF]) * c + (aux[AUX_FX + W_LF] + aux[AUX_FX + W_RF]) * s
    out[TR_FYR] = aux[AUX_FY + W_LR] + aux[AUX_FY + W_RR]
    out[TR_ALPHA_F] = d - (vy + p[MB_A] * r) / vx
    out[TR_ALPHA_R] = (p[MB_B] * r - vy) / vx
    out[TR_YAW_RATE] = r
    out[TR_AY] = f[S_VY] + r * vx
    out[TR_VY] = vy
    out[TR_VX] = vx
    out[TR_DELTA] = d


@njit(cache=True, error_model="numpy")
def plant_rk4_step(x, delta_cmd, dt, v_ref, a_ff, p, ty, work, aux, truth):
    """One classical RK4 step of the truth plant, in place on ``x`` (N_STATE,).

    ``work`` (6, N_STATE) is scratch. Fills ``truth`` (N_TRUTH,) and ``aux`` (N_AUX,) with
    the values at the *start* of the step. Returns ``False`` if the state became
    non-finite (the caller raises).
    """
    if not p[OPT_TSTEER] > 0.0:
        x[S_DELTA] = delta_cmd  # ideal steering: road-wheel angle held at the command
    k1 = work[0]
    k2 = work[1]
    k3 = work[2]
    k4 = work[3]
    y = work[4]
    n = x.shape[0]
    plant_rhs(x, delta_cmd, v_ref, a_ff, p, ty, k1, aux)
    truth_from_rhs(x, k1, aux, p, truth)
    aux2 = work[5]  # the later stages write their aux here, keeping the start-of-step one
    h = 0.5 * dt
    for i in range(n):
        y[i] = x[i] + h * k1[i]
    plant_rhs(y, delta_cmd, v_ref, a_ff, p, ty, k2, aux2)
    for i in range(n):
        y[i] = x[i] + h * k2[i]
    plant_rhs(y, delta_cmd, v_ref, a_ff, p, ty, k3, aux2)
    for i in range(n):
        y[i] = x[i] + dt * k3[i]
    plant_rhs(y, delta_cmd, v_ref, a_ff, p, ty, k4, aux2)
    c = dt / 6.0
    ok = True
    for i in range(n):
        x[i] = x[i] + c * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        if not math.isfinite(x[i]):
            ok = False
    for i in range(S_OMEGA_LF, S_OMEGA_RR + 1):  # negative wheel spin forbidden
        if x[i] < 0.0:
            x[i] = 0.0
    return ok


# --- path geometry -------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def _path_point(s, px, py, ph, pk, ds):
    """Position (cubic Hermite), heading and curvature (linear) of the path at ``s``."""
    u = s / ds
    n = px.shape[0]
    i = int(math.floor(u))
    if i < 0:
        i = 0
    if i > n - 2:
        i = n - 2
    t = u - i
    h0, h1 = ph[i], ph[i + 1]
    # cubic Hermite with tangents ds (cos h, sin h)
    t2 = t * t
    t3 = t2 * t
    a0 = 2 * t3 - 3 * t2 + 1
    a1 = t3 - 2 * t2 + t
    a2 = -2 * t3 + 3 * t2
    a3 = t3 - t2
    x = a0 * px[i] + a1 * ds * math.cos(h0) + a2 * px[i + 1] + a3 * ds * math.cos(h1)
    y = a0 * py[i] + a1 * ds * math.sin(h0) + a2 * py[i + 1] + a3 * ds * math.sin(h1)
    head = h0 + t * (h1 - h0)
    kap = pk[i] + t * (pk[i + 1] - pk[i])
    return x, y, head, kap


@njit(cache=True, error_model="numpy")
def path_errors(X, Y, psi, vx, vy, r, s_guess, px, py, ph, pk, ds):
    """Lane-camera errors of a pose relative to a tabulated path (exact Frenet kinematics).

    Projects ``(X, Y)`` on the path (Newton on the along-track residual from ``s_guess``)
    and returns ``(s, e1, e1_dot, e2, e2_dot)``: offset to the left of the path [m],
    ``e1_dot = v_x sin e2 + v_y cos e2``, heading error ``e2 = psi - theta(s)`` [rad],
    ``e2_dot = r - kappa(s) s_dot`` with ``s_dot = (v_x cos e2 - v_y sin e2) / (1 - kappa e1)``.
    """
    s = s_guess
    e1 = 0.0
    theta = 0.0
    kap = 0.0
    for _ in range(8):
        cx, cy, theta, kap = _path_point(s, px, py, ph, pk, ds)
        dx, dy = X - cx, Y - cy
        ct, st = math.cos(theta), math.sin(theta)
        along = dx * ct + dy * st
        e1 = -dx * st + dy * ct
        s = s + along / (1.0 - kap * e1)
        if abs(along) < 1e-10:
            break
    cx, cy, theta, kap = _path_point(s, px, py, ph, pk, ds)
    dx, dy = X - cx, Y - cy
    e1 = -dx * math.sin(theta) + dy * math.cos(theta)
    e2 = psi - theta
    ce, se = math.cos(e2), math.sin(e2)
    e1_dot = vx * se + vy * ce
    s_dot = (vx * ce - vy * se) / (1.0 - kap * e1)
    e2_dot = r - kap * s_dot
    return s, e1, e1_dot, e2, e2_dot


@njit(cache=True, error_model="numpy")
def plant_tick(x, err, delta_cmd, dt, v_ref, a_ff, p, ty, work, aux, truth, s_guess, px, py, ph, pk, ds):
    """One physics tick: :func:`plant_rk4_step`, then the camera errors of the new pose.

    ``err`` (4,) receives ``[e1, e1_dot, e2, e2_dot]`` at the end of the step. Returns
    ``(ok, s)``: ``ok`` is ``False`` if the state or the errors became non-finite; ``s``
    is the path distance of the projection [m].
    """
    ok = plant_rk4_step(x, delta_cmd, dt, v_ref, a_ff, p, ty, work, aux, truth)
    s, e1, e1d, e2, e2d = path_errors(x[S_X], x[S_Y], x[S_PSI], x[S_VX], x[S_VY], x[S_R], s_guess, px, py, ph, pk, ds)
    err[ERR_E1] = e1
    err[ERR_E1_DOT] = e1d
    err[ERR_E2] = e2
    err[ERR_E2_DOT] = e2d
    if not (math.isfinite(e1) and math.isfinite(e1d) and math.isfinite(e2) and math.isfinite(e2d)):
        ok = False
    return ok, s


key_on_family(globals(), MB_FAMILY)
