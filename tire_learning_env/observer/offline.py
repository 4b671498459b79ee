r"""Offline refinement: when the whole log is there, use all of it.

The causal observer learns the weights on line, one measurement at a time, from a prior.
Offline, the same observer (same model, same certified gains) is a one-step-ahead
predictor of every measurement, and the weights that make its innovations smallest over
the whole log are found by a prediction-error fit (Ljung, *System Identification*, ch. 7):

    w* = argmin_w  sum_k nu_k(w)^T S_k^-1 nu_k(w) + (w - w_0)^T Lambda_0 (w - w_0)

with ``S_k = H Sigma H^T + R`` the innovation covariance at exact weights and ``Lambda_0`` the
prior precision (the smooth-curve prior of the causal observer, which only matters where
the driving did not excite the tires). The gradient is exact and cheap: the observer
already propagates ``Upsilon = dx/dw``, and ``d nu / dw = -Psi = -(H Upsilon + D_w)``.
Levenberg-Marquardt-damped Gauss-Newton steps from the causal end weights converge in a few
passes over the log (:func:`refine`).

Uncertainty (:class:`OfflineFit`). The curve and the stiffness are linear functionals
``g^T w`` of the weights. Their variance is the sandwich ``g^T A^-1 G A^-1 g`` with
``A = Psi^T S^-1 Psi + Lambda_0`` and ``G`` the long-run covariance of the scores
``s_k = Psi_k^T S_k^-1 nu_k`` (Newey-West, Bartlett weights, bandwidth from the scores' own
autocorrelation): innovations of a fixed-gain observer are not white, and with model
mismatch they are larger and slower than ``S`` says; the sandwich accounts for both,
where ``A^-1`` alone would be over-confident. The prior's own share is kept unscaled.

Verdict. The stiffness is *identified* when its two-sigma band is within
``identifiable_rel_2sigma`` of the value; otherwise it is reported as not identifiable (a
straight road, a drive that never loads the tires) and no number is printed as the answer.
The *learned slip range* of each axle is where the curve's two-sigma band is within
``curve_rel_2sigma`` of the force, inside the slip the drive covered.
"""

from __future__ import annotations

import copy
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .box_step import _solve_step  # noqa: F401  (re-exported: prior_length and tests use it here)
from .longrun import NW_KEPT_LAGS, ScoreLongRun, _newey_west_columns, newey_west_variance, nw_columns_per_fft  # noqa: F401  (re-exported)
from .neuro_adaptive import NeuroAdaptiveObserver, axle_index
from .passes import _nis_per_dof, _pass, innovation_whiteness, pass_pieces, pass_threads  # noqa: F401  (re-exported)
from .readout import curve_gradient, stiffness_gradient, stiffness_readout
from .trace import EstimateTrace

__all__ = ["OfflineFit", "PendingFit", "refine", "stiffness_gradient", "curve_gradient", "newey_west_variance", "innovation_whiteness",
           "hold_fit", "pass_pieces", "pass_threads"]


#: The process-noise stages of :func:`refine` (force error as fractions of the mean static axle load), largest first.
FORCE_ERROR_STAGES = (3e-2, 1e-2, 3e-3, 1e-3, 3e-4, 1e-4)

#: The fit's attributes holding, per assumption the log cannot settle, the weight changes of its plausible
#: alternatives (:meth:`OfflineFit.prior_sensitivity` adds them to the bands; a refit carries them over).
ALTERNATIVES = ("prior_alternatives", "hold_alternatives", "dynamics_alternatives", "mismatch_alternatives",
                "delay_alternatives", "latency_alternatives", "process_noise_alternatives")


#: More directions than this in one variance call (a curve's band, a slip grid) go through
#: :class:`.longrun.ScoreLongRun` (one long-run covariance matrix per fit and bandwidth); fewer (the
#: stiffness) through the FFTs of each direction's own series, as always.
GRID_DIRECTIONS = 8


@dataclass
class OfflineFit:
    """Result of :func:`refine`.

    Attributes
    ----------
    weights : (nw,) refined weights
    hessian : (nw, nw) ``A = sum Psi^T S^-1 Psi + Lambda_0`` at the solution
    prior_precision : (nw, nw)
    covariance : (nw, nw) ``A^-1`` (model-based)
    trace : EstimateTrace
        Final pass with the refined weights held (states, slips, forces, health, std).
    cost : list of float
        Cost per Gauss-Newton iteration.
    iterations : int
    updates : int
        Measurements in the fit (after the burn-in and the gate).
    inflation : dict
        Sandwich / model variance ratio of the stiffness per axle.
    """

    weights: NDArray
    hessian: NDArray
    prior_precision: NDArray
    covariance: NDArray
    trace: EstimateTrace
    cost: list
    iterations: int
    updates: int
    scores: NDArray = field(repr=False, default=None)
    _sandwich_cache: dict = field(default_factory=dict, repr=False)

    def variance(self, g: NDArray) -> NDArray:
        """Variance of ``g^T w`` for rows ``g`` (n, nw): sandwich on the data share, prior share kept."""
        g = np.atleast_2d(g)
        Ainv_g = np.linalg.solve(self.hessian, g.T)  # (nw, n)
        model = np.einsum("ij,ij->j", g.T, Ainv_g)
        data_H = self.hessian - self.prior_precision
        data_part = np.einsum("ij,ij->j", Ainv_g, data_H @ Ainv_g)
        prior_part = np.maximum(model - data_part, 0.0)
        if self.scores is None or self.scores.shape[0] < 8:
            return model + self.prior_sensitivity(g)
        # the sandwich of the same directions is asked for again and again (the stiffness: by the summary, the
        # verdict, the report and the learned slip range per axle; 7 times in an estimate command): once per fit
        key = (g.shape, g.tobytes(), id(self.hessian), id(self.prior_precision), id(self.scores))
        if key not in self._sandwich_cache:
            self._sandwich_cache[key] = self._sandwich(Ainv_g)
        sandwich = self._sandwich_cache[key]
        return prior_part + np.maximum(sandwich, data_part) + self.prior_sensitivity(g)

    def _sandwich(self, Ainv_g: NDArray) -> NDArray:
        """Newey-West long-run variance of the scores projected on the columns of ``Ainv_g`` (nw, n)."""
        scores = self.scores
        if Ainv_g.shape[1] > GRID_DIRECTIONS:  # a grid (a curve's band): the quadratic form of the long-run covariance
            key = ("long_run", id(scores))
            if key not in self._sandwich_cache:
                self._sandwich_cache[key] = ScoreLongRun(scores)
            out = self._sandwich_cache[key].variance(Ainv_g)
            if out is not None:
                return out
        many = Ainv_g.shape[1] > nw_columns_per_fft(scores.shape[0])
        scores64 = np.ascontiguousarray(scores.T, dtype=float) if many else None  # once for many directions (a grid)

        def columns(c0: int, c1: int) -> NDArray:
            """Directions ``c0:c1``' score series as rows (c1 - c0, rows); never all directions at once (a
            plot's 401 directions over a 300 s, 1 kHz log would be 1 GB)."""
            v = np.ascontiguousarray(Ainv_g[:, c0:c1].T)
            if scores64 is not None:
                return v @ scores64
            u = np.empty((c1 - c0, scores.shape[0]))
            block = 32768  # the single-precision scores converted a block of rows at a time
            for r in range(0, u.shape[1], block):
                u[:, r : r + block] = v @ scores[r : r + block].T.astype(float)
            return u

        return _newey_west_columns(columns, scores.shape[0], Ainv_g.shape[1])

    def prior_sensitivity(self, g: NDArray) -> NDArray:
        """Sensitivity variance of ``g^T w``: per assumption the log cannot settle, the largest
        squared change among its plausible alternatives (the prior length,
        :func:`.prior_length.select_prior_length`; the steering hold,
        :func:`.sensitivity.steering_hold_sensitivity`; the yaw dynamics when the log rejects
        the vehicle file's, :func:`.sensitivity.yaw_dynamics_check`; a steering lag when the log rejects
        the lag-free model, :func:`.sensitivity.steering_delay_check`; the camera latency estimated from
        the log, :func:`.sensitivity.latency_sensitivity`; the process noise where the
        innovations showed the model's own error, :func:`refine`, or, for camera and IMU fused, one
        stage above the chosen one, :func:`.sensitivity.process_noise_sensitivity`), summed over the
        assumptions."""
        g = np.atleast_2d(g)
        out = np.zeros(g.shape[0])
        for name in ALTERNATIVES:
            alts = getattr(self, name, None) or []
            if alts:
                out += np.max(np.vstack([(g @ d) ** 2 for d in alts]), axis=0)
        return out

    def inflation_factor(self, g: NDArray) -> NDArray:
        g = np.atleast_2d(g)
        Ainv_g = np.linalg.solve(self.hessian, g.T)
        model = np.einsum("ij,ij->j", g.T, Ainv_g)
        return self.variance(g) / np.maximum(model, 1e-300)


def calibrate_force_error(observer: NeuroAdaptiveObserver, sensors: dict, w: NDArray, fit_from: float, gate: float,
                          bounds: tuple[float, float]) -> tuple[float, dict]:  # fmt: skip
    """The process-noise force error [N] at which the Kalman predictor's innovations are
    consistent (mean NIS per degree of freedom 1), found on a log grid and interpolated in
    ``log NIS`` against ``log force error`` (a method-of-moments noise identification)."""
    lo, hi = bounds
    grid = np.geomspace(lo, hi, 4)
    t = np.asarray(sensors["t"], dtype=float)
    if len(pass_pieces(t, observer.settle_s)) == 1 and pass_threads() > 1:
        # the grid's passes are independent: on threads, each on its own copy of the observer (its own state
        # and process noise; the compiled loop releases the GIL), as the latency profile runs its candidates.
        # A log this short makes each pass one piece on one core (the latency profile's 120 s window: 4 passes
        # in series took 0.23 s of a 30 min log's estimate with the other core idle); the same passes, bit for bit
        def nis_at(fe):
            ob = copy.copy(observer)
            ob.set_force_error(fe)
            return _nis_per_dof(_pass(ob, sensors, w, fit_from, gate)[0])

        with ThreadPoolExecutor(max_workers=min(pass_threads(), len(grid))) as pool:
            nis = list(pool.map(nis_at, grid))
    else:  # a long log's passes run as pieces on threads already
        nis = []
        for fe in grid:
            observer.set_force_error(fe)
            acc, _ = _pass(observer, sensors, w, fit_from, gate)
            nis.append(_nis_per_dof(acc))
    nis = np.array(nis)
    ln_fe, ln_n = np.log(grid), np.log(np.maximum(nis, 1e-12))
    if nis[-1] > 1.0:  # still inconsistent at the largest: the model error is larger than the range
        fe = hi
    elif nis[0] < 1.0:  # consistent even at the smallest
        fe = lo
    else:
        j = int(np.flatnonzero(nis <= 1.0)[0])  # nis decreases with the force error
        x0, x1, y0, y1 = ln_fe[j - 1], ln_fe[j], ln_n[j - 1], ln_n[j]
        fe = float(np.exp(x0 + (0.0 - y0) * (x1 - x0) / (y1 - y0)))
    observer.set_force_error(fe)
    return fe, {"force_error_N": fe, "grid_N": grid.tolist(), "nis_per_dof": nis.tolist()}


def _gauss_newton(observer, sensors, w, w0, Lam, lo, hi, fit_from, gate, max_iter, tol, min_decrease=0.0,
                  innovations=False):  # fmt: skip
    """Levenberg-Marquardt-damped Gauss-Newton passes at the current process noise.

    Stops after ``max_iter`` steps, when a step's largest change is below ``tol`` times the
    weight range, or (without the pass) when the next step's predicted cost decrease, in the
    cost's chi-square units (the squared length of the step in posterior standard deviations),
    is below ``min_decrease``: every linear functional of the weights would then move by less
    than ``sqrt(min_decrease)`` of its standard deviation.
    """
    mu = 1e-3
    acc, _ = _pass(observer, sensors, w, fit_from, gate, innovations=innovations)
    cost = float(acc.stats[0] + (w - w0) @ Lam @ (w - w0))
    costs = [cost]
    scale = observer.basis.weight_range
    it = 0
    for it in range(1, max_iter + 1):
        A = acc.hess + Lam
        rhs = acc.grad - Lam @ (w - w0)
        if min_decrease > 0:
            dw = _solve_step(A, rhs, w, lo, hi)
            if 2.0 * float(rhs @ dw) - float(dw @ A @ dw) < min_decrease:
                it -= 1
                break
        while True:
            dw = _solve_step(A + mu * np.diag(np.diag(A)), rhs, w, lo, hi)
            w_new = w + dw
            acc_new, _ = _pass(observer, sensors, w_new, fit_from, gate, innovations=innovations)
            cost_new = float(acc_new.stats[0] + (w_new - w0) @ Lam @ (w_new - w0))
            if cost_new <= cost * (1 + 1e-9) or mu > 1e6:
                break
            mu *= 10.0
        if cost_new <= cost * (1 + 1e-9):
            w, acc, cost = w_new, acc_new, cost_new
            mu = max(mu / 10.0, 1e-6)
        costs.append(cost)
        if np.max(np.abs(dw[: observer.basis.n_weights])) < tol * scale:
            break
    return w, acc, costs, it


def _continuation_rows(sensors: dict, max_s: float) -> dict:
    """The ``max_s`` window of the log with the most steering activity (the whole log if
    shorter): the rows the intermediate process-noise stages are fitted on."""
    t = np.asarray(sensors["t"], dtype=float)
    if t[-1] - t[0] <= 1.25 * max_s or "delta" not in sensors:
        return sensors
    dt = float(np.median(np.diff(t)))
    n = max(int(max_s / dt), 10)
    d = np.nan_to_num(np.diff(np.asarray(sensors["delta"], dtype=float), prepend=sensors["delta"][0])) ** 2
    c = np.cumsum(d)
    act = c[n:] - c[:-n]
    s0 = int(np.argmax(act)) if len(act) else 0
    return {k: np.asarray(v)[s0 : s0 + n] for k, v in sensors.items()}


def refine(
    observer: NeuroAdaptiveObserver,
    sensors: dict,
    w_start: NDArray,
    prior_mean: NDArray | None = None,
    prior_cov: NDArray | None = None,
    max_iter: int = 4,
    tol: float = 1e-3,
    gate: float = 25.0,
    force_errors: tuple[float, ...] = FORCE_ERROR_STAGES,
    nis_limit: float = 1.3,
    continuation_iter: int = 2,
    continuation_s: float = 300.0,
    min_decrease: float = 1e-2,
    whiteness: bool = False,
    background_final: bool = False,
) -> OfflineFit | PendingFit:
    """Prediction-error refinement of the weights over the whole log (module docstring).

    The Kalman predictor needs the process noise (the model's force error), which depends on
    how good the curve already is. A continuation finds both: starting from a large force
    error (a forgiving, low-information predictor that converges from a poor start), the fit
    is repeated with the force error lowered stage by stage, each stage starting from the
    previous weights, as long as the fitted innovations stay consistent (mean NIS per
    degree of freedom at most ``nis_limit``); the last consistent stage is the answer.

    Parameters
    ----------
    observer : NeuroAdaptiveObserver
        Its model, noise and latency define the predictor (the Kalman predictor of its
        model); its state is reset, its force error set to the chosen stage's.
    sensors : dict
        The log's sensor columns.
    w_start : (nw,)
        Starting weights (e.g. the causal pass' end weights).
    prior_mean, prior_cov : optional
        Prior of the weights (default: zero weights, the observer's prior covariance).
    max_iter : int
        Gauss-Newton passes per stage at most.
    tol : float
        A stage stops when the step's largest change is below ``tol`` times the weight range.
    gate : float
        Measurements whose NIS per degree of freedom exceeds this are left out (outliers,
        frames during a health trip).
    force_errors : tuple of float
        Process-noise stages, as fractions of the mean static axle load.
    nis_limit : float
        Largest mean NIS per degree of freedom accepted as consistent.
    continuation_iter : int
        Gauss-Newton passes per intermediate stage at most. The intermediate stages only
        carry the weights from the forgiving start to the last stage, so they are fitted
        cheaply: on the ``continuation_s`` window of the log with the most steering
        activity (the whole log if shorter) and with a few passes; the stage they reach is
        then fitted on the whole log with ``max_iter`` passes, and its consistency checked
        there (the stage below or above is fitted on the whole log too when the whole log's
        NIS disagrees with the window's), so the chosen stage is the whole log's.
    continuation_s : float
        Length of that window [s].
    min_decrease : float
        A stage also stops when the next step's predicted cost decrease (chi-square units:
        the step's squared length in posterior standard deviations) is below this; the
        intermediate stages use 100 times this.
    whiteness : bool
        A stage is consistent only if its camera innovations are also white
        (:func:`innovation_whiteness`). The NIS alone misses a model that lacks dynamics the
        vehicle has: on a CommonRoad multi-body log every stage had a NIS of 0.9-1.05 while the
        lateral-offset innovations were correlated 0.19-0.24 over 1-5 frames at the smallest
        process noise (the chosen one), and the stiffness read -5.7 / -8.3 % against the
        effective stiffness; at the stage whose innovations were white, -2.6 / -3.9 %.
        The answer then leans on where the descent stopped: the stage whose innovations turned
        correlated is refitted on the whole log from the answer (``continuation_iter`` passes),
        and the weight change is kept in ``fit.mismatch_alternatives`` (the bands add it, as
        :meth:`OfflineFit.prior_sensitivity` does every assumption the log cannot settle); the
        result's ``summary()["model_error_detected"]`` says so. The turn counts whether or not
        that stage's NIS also failed: on multi-body drive 2 of the generalisation benchmark the
        innovations turned correlated (Ljung-Box Q 132) at a NIS of 1.32, and the model error went
        unreported while the rear read -8.3 % against the effective stiffness.
    background_final : bool
        Return a :class:`PendingFit` as soon as the weights are fitted, without the final recorded
        pass (:func:`_final_fit`, one thread: it records the trace): the caller runs it while a
        thread does work that needs only the weights and the process noise
        (:func:`.estimator.estimate` profiles the latency again meanwhile). The fit is the same,
        bit for bit.

    Returns
    -------
    OfflineFit or PendingFit
        The fit; a :class:`PendingFit` with ``background_final``.
    """
    nw = observer.n_weights
    lo, hi = observer._weight_box()
    w0 = np.zeros(nw) if prior_mean is None else np.asarray(prior_mean, dtype=float)
    P0 = observer.prior_covariance(offline=True) if prior_cov is None else np.asarray(prior_cov, dtype=float)
    Lam = np.linalg.inv(P0)
    Lam = 0.5 * (Lam + Lam.T)
    t = np.asarray(sensors["t"], dtype=float)
    fit_from = float(t[0]) + observer.settle_s
    load = 0.5 * observer.vehicle.m * 9.81
    w = np.clip(np.asarray(w_start, dtype=float), lo, hi)
    stages: list = []
    all_costs: list = []
    iters = 0
    n_st = len(force_errors)
    sub = _continuation_rows(sensors, continuation_s)
    sub_from = float(np.asarray(sub["t"])[0]) + observer.settle_s

    def fit_stage(i, w_from, rows, start, n_iter, dec, phase):
        nonlocal iters, all_costs
        frac = force_errors[i]
        observer.set_force_error(frac * load)
        tested = whiteness and phase == "continuation"
        w_fit, acc, costs, it = _gauss_newton(observer, rows, w_from, w0, Lam, lo, hi, start, gate, n_iter, tol, dec,
                                              innovations=tested)  # fmt: skip
        iters += it
        all_costs += costs
        return w_fit, _nis_per_dof(acc), record(frac * load, acc, it, phase, tested)

    def record(force_error, acc, it, phase, tested):
        """Append the stage's record; its innovations' whiteness when ``tested`` (else ``None``)."""
        stage = {"force_error_N": force_error, "nis_per_dof": _nis_per_dof(acc), "iterations": it, "fit": phase}
        stages.append(stage)
        if not tested:
            return None
        test = innovation_whiteness(acc.innov)
        stage["ljung_box_q"], stage["ljung_box_bound"], stage["white"] = test["q"], test["bound"], test["white"]
        return test["white"]

    # continuation: the intermediate stages, cheaply (window, few passes); with ``whiteness`` the descent
    # also stops where the innovations, white at a larger process noise, turn correlated (a process noise
    # too large leaves them correlated too, the other way: only that turn marks the model's own error)
    cheap_w: list = []
    j = n_st - 1  # the stage to fit on the whole log
    seen_white = False
    coloured = None  # the first stage whose innovations turned correlated after white ones: the model's own error
    turn = None  # that stage's record (the evidence the result reports)
    for i in range(n_st - 1):
        w_fit, nis, white = fit_stage(i, w, sub, sub_from, continuation_iter, 100.0 * min_decrease, "continuation")
        if i > 0 and (nis > nis_limit or (seen_white and white is False)):
            j = i - 1  # the model error is larger than this stage's process noise
            if seen_white and white is False:  # the turn to correlated innovations: the model's own error, whatever
                coloured, turn = i, stages[-1]  # the NIS says (a NIS just over its limit once hid it: multi-body 2)
            break
        cheap_w.append(w_fit)
        w = w_fit
        seen_white = seen_white or bool(white)
        if nis > nis_limit:  # inconsistent even at the largest process noise
            j = 0
            break
    if whiteness and seen_white and j == n_st - 1:  # the last stage's innovations, on the window, too
        observer.set_force_error(force_errors[j] * load)
        acc_last, _ = _pass(observer, sub, w, sub_from, gate, innovations=True)
        if not record(force_errors[j] * load, acc_last, 0, "continuation (test only)", True):
            coloured, turn = j, stages[-1]
            j -= 1
            w = cheap_w[j]
    # the stage reached, on the whole log; its neighbours too when the whole log disagrees
    w_j, nis, _ = fit_stage(j, w, sensors, fit_from, max_iter, min_decrease, "whole log")
    if nis > nis_limit:
        while nis > nis_limit and j > 0:  # the stage below (from its continuation weights)
            j -= 1
            w_j, nis, _ = fit_stage(j, cheap_w[j], sensors, fit_from, max_iter, min_decrease, "whole log")
        chosen = (force_errors[j] * load, w_j.copy(), nis)
    else:
        chosen = (force_errors[j] * load, w_j.copy(), nis)
        while (j + 1 < n_st and not (whiteness and seen_white)
               and not any(s["fit"] == "whole log" and s["force_error_N"] == force_errors[j + 1] * load for s in stages)):
            w_up, nis_up, _ = fit_stage(j + 1, w_j, sensors, fit_from, max_iter, min_decrease, "whole log")
            if nis_up > nis_limit:
                break
            j += 1
            w_j = w_up
            chosen = (force_errors[j] * load, w_j.copy(), nis_up)
    fe, w, nis = chosen
    mismatch = []
    if coloured is not None and coloured == j + 1:  # how far the answer leans on the stage the model's error stopped
        w_c, _, _ = fit_stage(coloured, w, sensors, fit_from, continuation_iter, 100.0 * min_decrease,
                              "whole log (model-error sensitivity)")  # fmt: skip
        mismatch = [w_c - w]
    observer.set_force_error(fe)

    def final(obs: NeuroAdaptiveObserver) -> OfflineFit:
        fit = _final_fit(obs, sensors, w, Lam, fit_from, gate, all_costs, iters)
        fit.force_error = fe
        fit.mismatch_alternatives = mismatch
        fit.force_error_calibration = {"stages": stages, "chosen_force_error_N": fe,
                                       "model_error_stage": turn if mismatch else None}
        return fit

    if not background_final:
        return final(observer)
    # the final pass on its own copy of the observer (reset there: its own state; the model and gains
    # are shared, read only, and replaced, never written, by set_force_error / set_vehicle)
    worker = copy.copy(observer)
    observer.reset(weights=w)
    return PendingFit(observer, lambda: final(worker), w.copy(), fe, Lam)


class PendingFit:
    """A :func:`refine` whose final recorded pass has not run yet (``background_final``).

    The weights, the process noise and the prior precision are known at once. :meth:`run` makes
    the final pass (on a copy of the observer taken when the weights were fitted, so the caller
    may meanwhile use the observer on another thread); :meth:`result` returns the
    :class:`OfflineFit` and leaves the observer holding it (its weights and their covariance, as
    :func:`refine` leaves it).

    Why: the final pass records the trace, so it runs as one piece on one core; on a 2-core
    machine the other core is idle for its duration (2-4 s on a 30 min, 100 Hz log) unless the
    caller has work that needs only the weights (:func:`.estimator.estimate` profiles the latency
    again, refits the sensitivity checks' window and their alternatives from it meanwhile, on a thread
    (:func:`.sensitivity.prefetch_window_refits`); the final pass itself
    runs on the caller's thread, so its large per-row arrays come from the same allocator arena
    as before: on a worker thread the peak memory of a 30 min, 100 Hz estimate rose from
    499-501 MB to 513-540 MB).

    Attributes
    ----------
    weights : (nw,) the fitted weights
    force_error : float
        The chosen stage's force error [N].
    prior_precision : (nw, nw)
    """

    def __init__(self, observer: NeuroAdaptiveObserver, final, weights: NDArray, force_error: float,
                 prior_precision: NDArray) -> None:  # fmt: skip
        self._observer = observer
        self._final = final
        self._fit: OfflineFit | None = None
        self.weights = weights
        self.force_error = float(force_error)
        self.prior_precision = prior_precision

    def run(self) -> OfflineFit:
        """The final pass (once); the :class:`OfflineFit`. The observer is not touched."""
        if self._fit is None:
            self._fit = self._final()
        return self._fit

    def result(self) -> OfflineFit:
        """The :class:`OfflineFit` (:meth:`run` if not yet); the observer is left holding it."""
        fit = self.run()
        if getattr(self, "_window_baselines", None):  # computed from these weights meanwhile (sensitivity)
            fit._window_baselines = self._window_baselines
        hold_fit(self._observer, fit)
        return fit


def hold_fit(observer: NeuroAdaptiveObserver, fit: OfflineFit) -> None:
    """Leave ``observer`` holding ``fit``: its process noise, weights and weight covariance (after a
    refit under another assumption, or when choosing between fits)."""
    observer.set_force_error(fit.force_error)
    observer.reset(weights=fit.weights)
    observer._state.pw[:] = fit.covariance


def _final_fit(observer, sensors, w, Lam, fit_from, gate, costs, iterations) -> OfflineFit:
    """The final pass at the fitted weights (trace, scores, normal equations) as an :class:`OfflineFit`;
    the observer is left holding the weights and their covariance."""
    acc, trace = _pass(observer, sensors, w, fit_from, gate, final=True)
    A = acc.hess + Lam
    A = 0.5 * (A + A.T)
    cov = np.linalg.inv(A)
    observer.reset(weights=w)
    observer._state.pw[:] = cov
    fit = OfflineFit(w, A, Lam, cov, trace, costs, iterations, int(acc.stats[1]), scores=trace.meta.pop("scores", None))
    fit.data_cost, fit.data_grad = float(acc.stats[0]), acc.grad.copy()
    fit.nis_per_dof = _nis_per_dof(acc)
    return fit


def pem_cost(observer: NeuroAdaptiveObserver, sensors: dict, w: NDArray, prior_cov: NDArray | None = None,
             gate: float = 25.0) -> tuple[float, int]:  # fmt: skip
    """Cost after one Gauss-Newton step from ``w``: ``J - g^T A^-1 g`` (the quadratic model's
    minimum), and the number of updates; compares settings such as the latency cheaply."""
    P0 = observer.prior_covariance(offline=True) if prior_cov is None else prior_cov
    Lam = np.linalg.inv(P0)
    t = np.asarray(sensors["t"], dtype=float)
    acc, _ = _pass(observer, sensors, w, float(t[0]) + observer.settle_s, gate)
    A = acc.hess + Lam
    rhs = acc.grad - Lam @ w
    J = float(acc.stats[0] + w @ Lam @ w)
    try:
        return J - float(rhs @ np.linalg.solve(A, rhs)), int(acc.stats[1])
    except np.linalg.LinAlgError:
        return J, int(acc.stats[1])


__all__ += ["pem_cost", "axle_index", "stiffness_readout", "calibrate_force_error"]
