"""Layouts, constants and the named tuples of the compiled estimator (:mod:`._kernel`, which
documents the equations): the argument groups of the kernels and the work arrays.

The four files of the compiled family, :data:`KERNEL_FAMILY`, call each other's compiled
functions; each stamps its numba cache with the digest of all four
(:func:`tire_learning_env._jit_cache.key_on_family`), so an edit to any one of them
recompiles all (numba alone would only check the caller's own file).
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

#: The source files of the compiled estimator, callees first (``_kernels.py``: eq. 13, :func:`bicycle_slip_angles`).
KERNEL_FAMILY = (Path(__file__).parents[1] / "_kernels.py",) + tuple(
    Path(__file__).with_name(name) for name in ("_kernel_types.py", "_kernel_predict.py", "_kernel_update.py", "_kernel.py"))  # fmt: skip


# state layout (body states first, so an IMU-only estimator uses the prefix)
VY, R, E1, E2 = 0, 1, 2, 3
# measurement channels
CH_E1, CH_E2, CH_AY, CH_R = 0, 1, 2, 3
N_CHANNELS = 4
GROUP_CAMERA, GROUP_IMU = 0, 1
# health codes (trace.health)
HEALTH_OK, HEALTH_SETTLING, HEALTH_NO_DATA, HEALTH_INCONSISTENT, HEALTH_DIVERGED, HEALTH_RECOVERING = range(6)
# modes
MODE_CAUSAL, MODE_FIXED = 0, 1
# health state vector layout
(HS_CODE, HS_LAST_MEAS, HS_TRIP_T, HS_SUM, HS_DOF, HS_COUNT, HS_HEAD, HS_LAST_CKPT, HS_N_CKPT,
 HS_CKPT_HEAD, HS_TRIPS, HS_STARTED, HS_T0, HS_PREV_T, HS_PREV_KAPPA, HS_KAPPA_RATE) = range(16)  # fmt: skip
N_HS = 16  # the last three: the previous row's time and curvature, and the curvature rate (not health)
# history meta: number of rows stored, head
HM_COUNT, HM_HEAD = 0, 1
V_FLOOR = 3.0  # [m/s]: speed floor of the slip angles (singular at standstill)
# (the health codes' names: :data:`.trace.HEALTH_NAMES`)


class Model(NamedTuple):
    """Vehicle and basis constants of a run (all SI)."""

    veh: np.ndarray  # [m, Iz, lf, lr, 2 Cf, 2 Cr, camera_x]
    lo: np.ndarray  # (2, N) soft-clip lower bounds [rad]
    hi: np.ndarray  # (2, N) upper bounds [rad]
    off: np.ndarray  # (2, N) offsets subtracted from the activations [rad]
    lam: float  # sharpness [1/rad]
    gamma: np.ndarray  # (2,) scales [N/rad]
    n_bias: int  # sensor offsets appended to w: 0, or 2 (a_y [m/s^2], yaw rate [rad/s])
    wlo: np.ndarray  # (nw,) weight box
    whi: np.ndarray  # (nw,)
    nx: int  # 2 (IMU) or 4 (camera, fused)
    q_force: np.ndarray  # (2,) force-error intensity front/rear [N^2 s]
    h_max: float  # largest integration sub-step [s]
    ub: np.ndarray  # (2, NB) distinct activation bounds of each axle [rad] (shared by neighbouring members)
    nub: np.ndarray  # (2,) int64: how many of ``ub`` are used per axle
    ilo: np.ndarray  # (2, N) int64: index of each member's lower bound in ``ub``
    ihi: np.ndarray  # (2, N) int64: ... of its upper bound


class Gains(NamedTuple):
    """Certified correction gains per speed cell."""

    edges: np.ndarray  # (n_cells + 1,) speed cell edges [m/s]
    L_cam: np.ndarray  # (n_cells, nx, 2) gain of the camera channels
    L_imu: np.ndarray  # (n_cells, nx, 2) gain of the IMU channels


class Settings(NamedTuple):
    """Run settings."""

    r_var: np.ndarray  # (4,) measurement noise variance of e1, e2, a_y, r
    use_cam: bool
    use_imu: bool
    latency: float  # camera latency [s]
    mode: int  # MODE_CAUSAL or MODE_FIXED
    adapt: bool  # causal mode: learn the weights
    q_w: float  # weight random-walk intensity [1/s] (variance per second)
    p_max: float  # cap of each weight variance
    settle_until: float  # no adaptation before this time [s]
    gap_limit: float  # health: longest time without a measurement [s]
    nis_factor: float  # health: window NIS may exceed the chi-square bound by this factor
    rollback_s: float  # weights restored from a checkpoint at least this old [s]
    gate: float  # fixed mode: updates with NIS above this are left out of the fit
    accumulate_from: float  # fixed mode: accumulate from this time [s]
    x0: np.ndarray  # (nx,) state after a divergence reset
    sig0: np.ndarray  # (nx, nx) its covariance
    dt_last: float  # prediction step after the last row [s]
    store_weights: bool
    store_scores: bool
    compute_std: bool
    kalman: bool  # correct with the Kalman gain Sigma H^T S^-1 instead of the certified gain
    record: bool  # store the per-row outputs (off: only the state and the accumulators are updated)
    shift_frames: bool  # fixed mode, camera only: delayed frames applied at their instant in one forward
    # sweep (the same corrections as the rewind-and-replay of the causal mode, without the replay)
    steering_ramp: bool  # steering ramps linearly to the next row's (first-order hold) instead of being held


class State(NamedTuple):
    """Mutable estimator state (updated in place)."""

    x: np.ndarray  # (nx,)
    w: np.ndarray  # (nw,)
    ups: np.ndarray  # (nx, nw) sensitivity dx/dw
    sig: np.ndarray  # (nx, nx) state-error covariance at exact weights
    pw: np.ndarray  # (nw, nw) weight covariance
    hs: np.ndarray  # (N_HS,) health state
    hring: np.ndarray  # (W, 2) NIS and dof of the last W updates
    ck_t: np.ndarray  # (C,) checkpoint times
    ck_w: np.ndarray  # (C, nw)
    ck_pw: np.ndarray  # (C, nw, nw)
    hist_t: np.ndarray  # (H,) history for delayed frames
    hist_x: np.ndarray  # (H, nx)
    hist_ups: np.ndarray  # (H, nx, nw)
    hist_sig: np.ndarray  # (H, nx, nx)
    hist_u: np.ndarray  # (H, 8) delta, vx, ax, kappa, z_ay, z_r, kappa rate, steering rate
    hist_meta: np.ndarray  # (2,) int64: count, head


class Accumulator(NamedTuple):
    """Normal equations of the prediction-error fit (fixed mode)."""

    hess: np.ndarray  # (nw, nw) sum Psi^T S^-1 Psi
    grad: np.ndarray  # (nw,) sum Psi^T S^-1 nu
    stats: np.ndarray  # (4,) sum nu^T S^-1 nu, updates, dof, sum log det S
    innov: np.ndarray  # (n rows, 2) the camera innovations (e1, e2) of the fit, by frame row; (0, 2): not kept


class Outputs(NamedTuple):
    x: np.ndarray  # (n, nx) posterior state
    slip: np.ndarray  # (n, 2)
    fnl: np.ndarray  # (n, 2) nonlinear (learned) axle force [N]
    force: np.ndarray  # (n, 2) total axle force [N]
    w: np.ndarray  # (n, nw) or (0, nw) when not stored
    std: np.ndarray  # (n, nx) or (0, nx)
    nu: np.ndarray  # (n, 4) innovations (NaN without measurement)
    nis: np.ndarray  # (n,) NIS of the row's updates (NaN without)
    health: np.ndarray  # (n,) int8
    score: np.ndarray  # (n, nw) or (0, nw)


class _Work(NamedTuple):
    phi: np.ndarray  # (nw,)
    dphi: np.ndarray
    k1: np.ndarray  # (nx,)
    k2: np.ndarray
    k3: np.ndarray
    k4: np.ndarray
    y: np.ndarray
    J: np.ndarray  # (nx, nx)
    Phi: np.ndarray
    Gm: np.ndarray
    T1: np.ndarray  # (nx, nx)
    U: np.ndarray  # (nx, nw)
    H: np.ndarray  # (2, nx)
    Dw: np.ndarray  # (2, nw)
    Psi: np.ndarray  # (2, nw)
    PsiP: np.ndarray  # (2, nw)
    Kw: np.ndarray  # (nw, 2)
    dw: np.ndarray  # (nw,)
    Lk: np.ndarray  # (nx, 2) Kalman gain
    spm: np.ndarray  # (NB,) softplus(-lam (a - u)) per distinct bound u
    spp: np.ndarray  # (NB,) softplus(lam (a - u))
    ht: np.ndarray  # (NB,) tanh(lam (a - u) / 2)


def make_work(nx: int, nw: int, nb: int = 64) -> _Work:
    """Scratch arrays of the kernels for ``nx`` states, ``nw`` weights and ``nb`` distinct activation
    bounds per axle (contents undefined; every kernel writes before it reads)."""
    e = np.empty
    return _Work(e(nw), e(nw), e(nx), e(nx), e(nx), e(nx), e(nx), e((nx, nx)), e((nx, nx)), e((nx, nx)),
                 e((nx, nx)), e((nx, nw)), e((2, nx)), e((2, nw)), e((2, nw)), e((2, nw)), e((nw, 2)), e(nw), e((nx, 2)),
                 e(nb), e(nb), e(nb))  # fmt: skip


def bound_table(lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(ub, nub, ilo, ihi)`` of :class:`Model`: the distinct bounds of each axle's members
    (neighbouring members share a bound, so each softplus is evaluated once per bound)."""
    lower = np.asarray(lower, dtype=float)
    upper = np.asarray(upper, dtype=float)
    n_ax, N = lower.shape
    tables = [np.unique(np.r_[lower[i], upper[i]]) for i in range(n_ax)]
    NB = max(len(u) for u in tables)
    ub = np.zeros((n_ax, NB))
    nub = np.zeros(n_ax, dtype=np.int64)
    ilo = np.zeros((n_ax, N), dtype=np.int64)
    ihi = np.zeros((n_ax, N), dtype=np.int64)
    for i, u in enumerate(tables):
        ub[i, : len(u)] = u
        nub[i] = len(u)
        ilo[i] = np.searchsorted(u, lower[i])
        ihi[i] = np.searchsorted(u, upper[i])
    return ub, nub, ilo, ihi
