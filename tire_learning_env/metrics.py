"""Evaluation metrics shared by every study, estimator and baseline (``metrics.json``).

Keys (the same for every study):

- ``state_rmse`` {e1, e1_dot, e2, e2_dot}: after the burn-in (default 2 s).
- ``slip_rmse_deg`` {front, rear}: after the burn-in.
- ``force_nonlinear_nrmse`` {front, rear}: RMSE of ``f_hat`` against the true nonlinear
  part *relative to the nominal stiffness the estimator assumes*,
  ``F_true - 2 C_nominal alpha_true``, divided by ``max |F_true|``.
- ``tire_curve_nrmse`` {front, rear}: learned total axle curve vs the true one on a
  201-point grid over the excited slip range, divided by the largest ``|F_true|`` there.
- ``excited_slip_range_deg`` {front: [lo, hi], rear: [lo, hi]}: the 0.5 % and 99.5 %
  quantiles of the true slip after the burn-in (robust to single spikes).
- ``cornering_stiffness`` {front: {estimated, true, error_pct}, rear: ...}: per tire [N/rad]
  (``error_pct`` NaN when the true stiffness is not positive).
- ``lmi``: the gain certificate (:meth:`~.observer.gains.ObserverGains.summary`).
- ``runtime_s``: wall time of the estimator.
- ``convergence_time_s``: time after which the online tire-curve error stays below 5 %.
- ``tire_curve_nrmse_nominal``: the same score for the nominal linear curve (what you
  get without learning), as a reference.

Diagnostics (not in ``metrics.json``; ``benchmarks/bench_study2_error_budget.py``):
:func:`bicycle_implied_axle_forces` and :func:`oracle_cornering_stiffness` give the
stiffness a bicycle-model estimator with *perfect* states would report on a plant.
"""

from __future__ import annotations

import math
from typing import Callable, Mapping

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "compute_metrics", "excited_range", "curve_nrmse", "convergence_time", "bicycle_implied_axle_forces",
    "oracle_cornering_stiffness", "basis_regressors", "stiffness_error_pct", "centred_moving_average", "AXLES",
]  # fmt: skip

AXLES = ("front", "rear")
#: Columns of the error state ``[e1, e1_dot, e2, e2_dot]`` the metrics read (those of
#: ``dynamics.StateIndex``, a layer above this module; ``tests/test_metrics.py`` checks they agree).
STATE_E1_DOT, STATE_E2_DOT = 1, 3
CurveFn = Callable[[NDArray, str], NDArray]


def centred_moving_average(t: NDArray, y: NDArray, width: float) -> NDArray:
    """Centred moving average of ``y`` over ``t +/- width / 2`` (``t`` sorted; fewer samples at the ends).

    The one smoother of the package's signal checks (discrepancy band residuals and inputs, the
    IMU's yaw acceleration); it follows the time stamps, so jittered rows are averaged over the
    same time span.
    """
    cs = np.concatenate([[0.0], np.cumsum(y)])
    lo = np.searchsorted(t, t - 0.5 * width, side="left")
    hi = np.searchsorted(t, t + 0.5 * width, side="right")
    return (cs[hi] - cs[lo]) / (hi - lo)


def excited_range(slip: NDArray, q: float = 0.5) -> tuple[float, float]:
    """``(lo, hi)`` [rad]: the ``q`` % and ``100 - q`` % quantiles of ``slip``."""
    return float(np.percentile(slip, q)), float(np.percentile(slip, 100.0 - q))


def curve_nrmse(estimated: CurveFn, true: CurveFn, axle: str, lo: float, hi: float, n: int = 201) -> float:
    """RMS difference of two axle curves on ``[lo, hi]`` divided by the largest true ``|F|`` there."""
    grid = np.linspace(lo, hi, n)
    f_true = np.asarray(true(grid, axle), dtype=float)
    denom = np.max(np.abs(f_true))
    if not denom > 0:
        return float("nan")
    return float(np.sqrt(np.mean((np.asarray(estimated(grid, axle)) - f_true) ** 2)) / denom)


def convergence_time(
    t: NDArray, errors: NDArray, threshold: float = 0.05
) -> float | None:
    """First time after which every later error is below ``threshold`` (``None`` if never)."""
    errors = np.asarray(errors, dtype=float)
    above = np.flatnonzero(~(errors < threshold))
    if len(above) == 0:
        return float(t[0])
    last = above[-1]
    return float(t[last + 1]) if last + 1 < len(t) else None


def bicycle_implied_axle_forces(
    t: NDArray, state: NDArray, vx: NDArray, psi_dot_des: NDArray, psi_ddot_des: NDArray, vehicle
) -> NDArray:
    """Axle forces ``[F_yf, F_yr]`` [N] the bicycle model needs to move along ``state`` exactly.

    Inverts Newton's equations in error coordinates (SPEC §1, check under eqs. 1-8),

        e1_ddot = (F_yf + F_yr) / m - vx psi_dot_des
        e2_ddot = (lf F_yf - lr F_yr) / Iz - psi_ddot_des

    with ``e1_ddot``, ``e2_ddot`` the time derivatives of ``e1_dot``, ``e2_dot``
    (second-order central differences). On a plant that *is* this bicycle model the
    result equals its axle forces; on a higher-order plant it is the force a bicycle
    model must attribute to the tires to reproduce the motion (roll inertia, load
    transfer and suspension effects included).

    Parameters
    ----------
    t : (n,) time [s]
    state : (n, 4) ``[e1, e1_dot, e2, e2_dot]``
    vx, psi_dot_des, psi_ddot_des : (n,) speed [m/s], desired yaw rate [rad/s] and its rate [rad/s^2]
    vehicle : VehicleParams
        ``m``, ``Iz``, ``lf``, ``lr`` of the bicycle model.
    """
    t = np.asarray(t, dtype=float)
    state = np.asarray(state, dtype=float)
    e1_ddot = np.gradient(state[:, STATE_E1_DOT], t)
    e2_ddot = np.gradient(state[:, STATE_E2_DOT], t)
    lateral = vehicle.m * (e1_ddot + np.asarray(vx, dtype=float) * np.asarray(psi_dot_des, dtype=float))
    yaw = vehicle.Iz * (e2_ddot + np.asarray(psi_ddot_des, dtype=float))
    wheelbase = vehicle.lf + vehicle.lr
    return np.column_stack([(yaw + vehicle.lr * lateral) / wheelbase, (vehicle.lf * lateral - yaw) / wheelbase])


def basis_regressors(basis, slip: NDArray, axle: int) -> NDArray:
    """Regressors of the axle's nonlinear force, ``gamma_i sigma_ij(alpha^k)``, shape (n, N) (eq. 14).

    Row ``k`` times the axle's weights ``W_i`` is the learned nonlinear force at ``slip[k]``.

    Parameters
    ----------
    basis : SoftClipBasis
    slip : (n,) slip angles [rad]
    axle : 0 (front) or 1 (rear)
    """
    return basis.scale[axle] * basis.activations(np.asarray(slip, dtype=float), axle)


def oracle_cornering_stiffness(
    slip: NDArray, force: NDArray, basis, nominal_stiffness: tuple[float, float]
) -> tuple[float, float]:
    """Per-tire cornering stiffness of a least-squares fit of ``force`` against ``slip`` [N/rad].

    The fit uses the estimator's own curve representation (SPEC eq. 14: the nominal
    linear force plus ``basis``), unregularised and unbounded, and reports half the
    slope of the fitted axle curve at zero slip, as
    :meth:`~.observer.NeuroAdaptiveObserver.cornering_stiffness` does. Fed the true slip
    and :func:`bicycle_implied_axle_forces` of the true state, it is what a bicycle-model
    estimator with perfect states would report: the part of a stiffness error that
    comes from the plant's structure, not from estimation.

    Parameters
    ----------
    slip, force : (n, 2) slip angles [rad] and axle forces [N], front and rear
    basis : SoftClipBasis
    nominal_stiffness : per-tire (front, rear) [N/rad] of the linear part
    """
    slip = np.asarray(slip, dtype=float)
    force = np.asarray(force, dtype=float)
    out = []
    N = basis.n_per_axle
    for axle in (0, 1):
        a = slip[:, axle]
        X = basis_regressors(basis, a, axle)
        y = force[:, axle] - 2.0 * nominal_stiffness[axle] * a
        w = np.linalg.lstsq(X, y, rcond=None)[0]
        weights = np.zeros((2, N))
        weights[axle] = w
        slope = 2.0 * nominal_stiffness[axle] + float(basis.nonlinear_slope(0.0, weights.ravel(), axle))
        out.append(slope / 2.0)
    return out[0], out[1]


def stiffness_error_pct(estimated: float, true: float) -> float:
    """``100 (estimated / true - 1)`` [%]; NaN when ``true`` is not a positive finite stiffness."""
    true = float(true)
    if not (math.isfinite(true) and true > 0):
        return float("nan")
    return 100.0 * (float(estimated) / true - 1.0)


def _rmse(a: NDArray, b: NDArray) -> float:
    return float(np.sqrt(np.mean((np.asarray(a) - np.asarray(b)) ** 2)))


def compute_metrics(
    *,
    t: NDArray,
    xi_hat: NDArray,
    slip_hat: NDArray,
    force_nonlinear_hat: NDArray,
    truth: Mapping[str, NDArray],
    curve: CurveFn,
    true_curve: CurveFn,
    stiffness_hat: tuple[float, float],
    stiffness_true: tuple[float, float],
    nominal_stiffness: tuple[float, float],
    lmi: dict | None = None,
    runtime_s: float | None = None,
    burn_in: float = 2.0,
    curve_history: tuple[NDArray, Callable[[int], CurveFn]] | None = None,
) -> dict:
    """Score an estimate against ground truth with the keys of the module docstring.

    Parameters
    ----------
    t : (n,) time [s]
    xi_hat, slip_hat, force_nonlinear_hat : estimates, shapes (n, 4), (n, 2), (n, 2)
    truth : mapping with ``true_state`` (n, 4), ``true_slip`` (n, 2), ``true_force`` (n, 2)
    curve, true_curve : ``(alpha, axle) -> total axle force`` [N], learned and true
    stiffness_hat, stiffness_true : per-tire cornering stiffness (front, rear) [N/rad]
    nominal_stiffness : per-tire stiffness the estimator assumed (front, rear) [N/rad]
    lmi : gain certificate summary
    runtime_s : estimator wall time [s]
    burn_in : seconds left out at the start; on a log shorter than twice the burn-in, the
        first half of the log instead (the value used is reported as ``burn_in_s``)
    curve_history : ``(times, k -> curve at times[k])`` of the *online* estimate, for
        ``convergence_time_s``
    """
    t = np.asarray(t, dtype=float)
    if len(t) < 2:
        raise ValueError(f"need at least 2 rows to score an estimate, got {len(t)}")
    burn_in = float(min(burn_in, 0.5 * (t[-1] - t[0])))
    keep = t >= t[0] + burn_in
    x_true = np.asarray(truth["true_state"])[keep]
    slip_true = np.asarray(truth["true_slip"])[keep]
    force_true = np.asarray(truth["true_force"])[keep]
    names = ("e1", "e1_dot", "e2", "e2_dot")
    out: dict = {
        "state_rmse": {n: _rmse(xi_hat[keep, i], x_true[:, i]) for i, n in enumerate(names)},
        "slip_rmse_deg": {a: math.degrees(_rmse(slip_hat[keep, i], slip_true[:, i])) for i, a in enumerate(AXLES)},
    }
    nl_true = force_true - slip_true * 2.0 * np.asarray(nominal_stiffness)
    out["force_nonlinear_nrmse"] = {
        a: _rmse(force_nonlinear_hat[keep, i], nl_true[:, i]) / float(np.max(np.abs(force_true[:, i])) or np.nan)
        for i, a in enumerate(AXLES)
    }
    ranges = {a: excited_range(slip_true[:, i]) for i, a in enumerate(AXLES)}
    out["tire_curve_nrmse"] = {a: curve_nrmse(curve, true_curve, a, *ranges[a]) for a in AXLES}

    def nominal(alpha, axle):
        return 2.0 * nominal_stiffness[AXLES.index(axle)] * np.asarray(alpha)

    out["tire_curve_nrmse_nominal"] = {a: curve_nrmse(nominal, true_curve, a, *ranges[a]) for a in AXLES}
    out["excited_slip_range_deg"] = {a: [math.degrees(v) for v in ranges[a]] for a in AXLES}
    out["cornering_stiffness"] = {
        a: {
            "estimated": float(stiffness_hat[i]),
            "true": float(stiffness_true[i]),
            "error_pct": stiffness_error_pct(stiffness_hat[i], stiffness_true[i]),
        }
        for i, a in enumerate(AXLES)
    }
    if curve_history is not None:
        times, curve_at = curve_history
        errors = np.array(
            [max(curve_nrmse(curve_at(k), true_curve, a, *ranges[a]) for a in AXLES) for k in range(len(times))]
        )
        out["convergence_time_s"] = convergence_time(times, errors)
    out["lmi"] = lmi or {}
    out["runtime_s"] = runtime_s
    out["burn_in_s"] = burn_in
    return out
