r"""What the log cannot settle, in the bands: assumptions refitted under their alternatives.

The offline fit (:mod:`.offline`) answers for a model: the vehicle file's masses and
geometry, a steering signal between rows, a smooth-curve prior. Where the log cannot decide
an assumption, the answer's change under the alternative is added to the bands
(:meth:`.offline.OfflineFit.prior_sensitivity`):

- :func:`steering_hold_sensitivity`: what the steering did between two log rows (held or
  ramped), which the log does not record;
- :func:`yaw_dynamics_check`: whether the log's transient response agrees with the vehicle
  file's yaw dynamics. The stiffness read from a lane-keeping drive leans on the yaw
  inertia (a 7 % change of ``Iz`` moved it by 3-4 % on a low-order Pacejka log). When the
  prediction-error cost decisively prefers another inertia, the file's ``Iz`` or the
  bicycle model itself (roll, suspension and relaxation dynamics of a real body) is off,
  and the stiffness is only as sure as its change under that inertia;
- :func:`process_noise_sensitivity` (camera and IMU fused): the process noise one stage above
  the chosen one, which the innovations' NIS cannot rule out.
"""

from __future__ import annotations

import numpy as np

from .neuro_adaptive import NeuroAdaptiveObserver
from .box_step import _solve_step
from .offline import OfflineFit, _continuation_rows, _gauss_newton, hold_fit
from .passes import _pass

__all__ = ["steering_hold_sensitivity", "yaw_dynamics_check", "steering_delay_check", "latency_sensitivity",
           "prefetch_window_baseline", "prefetch_window_refits", "process_noise_sensitivity"]

#: The window and the refit of :func:`steering_hold_sensitivity` and :func:`yaw_dynamics_check` (their defaults):
#: ``(window_s, gate, max_iter, tol, min_decrease)``.
WINDOW_REFIT = (300.0, 25.0, 2, 1e-3, 1e-2)


#: The yaw inertia factor :func:`yaw_dynamics_check` refits with first (and its inverse).
YAW_FACTOR = 0.85

#: The steering delay [s] :func:`steering_delay_check` refits with first (twice it after a rejection), and the
#: cost decrease [chi-square] that rejects the lag-free model (as :func:`yaw_dynamics_check`'s).
STEERING_DELAY = 0.01
DELAY_DECISIVE_CHI2 = 10.0

#: The factor by which :func:`process_noise_sensitivity` raises the chosen force error: one stage of
#: :data:`.offline.FORCE_ERROR_STAGES`, whose neighbours are 3 or 10/3 apart (the larger of the two).
PROCESS_NOISE_STEP = 10.0 / 3.0


def _baseline_key(observer: NeuroAdaptiveObserver, window_s: float, gate: float, max_iter: int, tol: float,
                  min_decrease: float) -> tuple:  # fmt: skip
    """The window baseline's cache key: the window and refit settings and the observer's own assumptions."""
    return (float(window_s), observer.steering_hold, float(observer.vehicle.Iz), float(gate), int(max_iter), float(tol),
            float(min_decrease))  # fmt: skip


def _cache(fit) -> dict:
    """The fit's cache of the window baseline and the alternatives' refits (created on first use)."""
    cached = getattr(fit, "_window_baselines", None)
    if cached is None:
        cached = fit._window_baselines = {}
    return cached


def _assumptions(observer: NeuroAdaptiveObserver) -> tuple:
    """What an alternative's refit reads that may change between the checks: steering hold, yaw inertia,
    process noise, latency."""
    return (observer.steering_hold, float(observer.vehicle.Iz), float(observer.force_error), float(observer.latency))


def _window_baseline(observer: NeuroAdaptiveObserver, sensors: dict, fit: OfflineFit, window_s: float, gate: float,
                     max_iter: int, tol: float, min_decrease: float) -> tuple[dict, float, np.ndarray, float]:  # fmt: skip
    """The log's most active ``window_s`` (the whole log if shorter) and the fit refitted on it under the
    observer's own assumptions: the baseline every alternative is compared with (computed once per fit)."""
    key = _baseline_key(observer, window_s, gate, max_iter, tol, min_decrease)
    cached = _cache(fit)
    if key not in cached:
        rows = _continuation_rows(sensors, window_s)
        fit_from = float(np.asarray(rows["t"], dtype=float)[0]) + observer.settle_s
        lo, hi = observer._weight_box()
        w, _, costs, _ = _gauss_newton(observer, rows, fit.weights, np.zeros_like(fit.weights), fit.prior_precision, lo,
                                       hi, fit_from, gate, max_iter, tol, min_decrease)  # fmt: skip
        cached[key] = (rows, fit_from, w, float(costs[-1]))
    return cached[key]


def prefetch_window_baseline(observer: NeuroAdaptiveObserver, sensors: dict, fit) -> None:
    """Compute the window baseline that :func:`steering_hold_sensitivity` and :func:`yaw_dynamics_check` start
    from (with their default window and refit, :data:`WINDOW_REFIT`) ahead of them.

    The baseline needs only the fit's weights and prior precision and the observer's assumptions
    (process noise, steering hold, yaw inertia), so :func:`.estimator.estimate` computes it while the
    fit's final recorded pass runs on a thread (``fit``: an :class:`~.offline.PendingFit`, whose
    :meth:`~.offline.PendingFit.result` carries the cache over to the :class:`~.offline.OfflineFit`).
    A check run under other assumptions misses the cache and refits, as before.
    """
    window_s, gate, max_iter, tol, min_decrease = WINDOW_REFIT
    _window_baseline(observer, sensors, fit, window_s, gate, max_iter, tol, min_decrease)


def _window_refit(observer: NeuroAdaptiveObserver, fit, base_key: tuple, rows: dict, fit_from: float,
                  w_start: np.ndarray, n_iter: int, gate: float, tol: float,
                  min_decrease: float) -> tuple[np.ndarray, list, int]:  # fmt: skip
    """``(w, costs, iterations)`` of :func:`.offline._gauss_newton` on the window ``rows`` from the baseline's
    weights ``w_start`` under the observer's current assumptions (an alternative's refit), cached on the fit
    beside its baseline (``base_key``), so that :func:`prefetch_window_refits` can compute it ahead.

    The key holds every assumption the refit reads that may change between the checks (steering hold, yaw
    inertia, process noise, latency) and the refit's settings; the weight box and the prior precision are the
    fit's own."""
    key = ("refit", base_key, *_assumptions(observer), int(n_iter), float(gate), float(tol), float(min_decrease))
    cached = _cache(fit)
    if key not in cached:
        lo, hi = observer._weight_box()
        w, _, costs, it = _gauss_newton(observer, rows, w_start, np.zeros_like(w_start), fit.prior_precision, lo, hi,
                                        fit_from, gate, n_iter, tol, min_decrease)  # fmt: skip
        cached[key] = (w, costs, it)
    return cached[key]


def _delayed_rows(rows: dict, delay: float) -> dict:
    """``rows`` with the steering ``delay`` [s] late (linear interpolation between the finite rows, the first
    value before the start; missing rows stay missing)."""
    t = np.asarray(rows["t"], dtype=float)
    d = np.asarray(rows["delta"], dtype=float)
    ok = np.isfinite(d)
    late = np.interp(t - delay, t[ok], d[ok]) if ok.any() else d.copy()
    late[~ok] = np.nan
    return dict(rows, delta=late)


def _delay_refit(observer: NeuroAdaptiveObserver, fit, base_key: tuple, rows: dict, fit_from: float,
                 w_start: np.ndarray, delay: float, n_iter: int, gate: float, tol: float,
                 min_decrease: float) -> tuple[np.ndarray, list, int]:  # fmt: skip
    """:func:`_window_refit` on the window with its steering ``delay`` [s] late (:func:`steering_delay_check`); the
    delay joins the cache key."""
    return _window_refit(observer, fit, (*base_key, "delay", float(delay)), _delayed_rows(rows, delay), fit_from,
                         w_start, n_iter, gate, tol, min_decrease)  # fmt: skip


def _one_step(observer: NeuroAdaptiveObserver, fit, rows: dict, fit_from: float, w_start: np.ndarray,
              gate: float) -> tuple[np.ndarray, float, float]:
    """One pass at ``w_start`` under the observer's current assumptions and the Gauss-Newton step from it:
    ``(step, cost at w_start, the step's predicted cost decrease)`` [weights, chi-square, chi-square]
    (:func:`_delay_screen`, :func:`_latency_step`)."""
    lo, hi = observer._weight_box()
    lam = fit.prior_precision
    acc, _ = _pass(observer, rows, w_start, fit_from, gate)
    A = acc.hess + lam
    rhs = acc.grad - lam @ w_start
    dw = _solve_step(A, rhs, w_start, lo, hi)
    return dw, float(acc.stats[0] + w_start @ lam @ w_start), 2.0 * float(rhs @ dw) - float(dw @ A @ dw)


def _delay_screen(observer: NeuroAdaptiveObserver, fit, base_key: tuple, rows: dict, fit_from: float,
                  w_start: np.ndarray, delay: float, gate: float) -> float:
    """The cost decrease [chi-square] one Gauss-Newton step from the window's baseline predicts with the steering
    ``delay`` [s] late: one pass instead of a refit's three. The quadratic model is optimistic: on 18 drives
    (multi-body scenarios 0-7, low-order 0-9) the prediction exceeded the two-step refit's decrease on every one
    (by 0.3-200), so a prediction at or below the decisive level decides "consistent" without the refit
    (:func:`steering_delay_check`). Cached on the fit like the refits."""
    key = ("delay_screen", base_key, float(delay), *_assumptions(observer), float(gate))
    cached = _cache(fit)
    if key not in cached:
        _, cost, decrease = _one_step(observer, fit, _delayed_rows(rows, delay), fit_from, w_start, gate)
        cached[key] = cost - decrease
    return cached[key]


def _latency_step(observer: NeuroAdaptiveObserver, fit, base_key: tuple, rows: dict, fit_from: float,
                  w_start: np.ndarray, latency: float, gate: float) -> np.ndarray:
    """The Gauss-Newton step [weights] from the window's baseline ``w_start`` with the camera ``latency`` [s]: one pass
    (:func:`latency_sensitivity`). Cached on the fit like the refits."""
    cached = _cache(fit)
    used = observer.latency
    try:
        observer.latency = float(latency)
        key = ("latency_step", base_key, *_assumptions(observer), float(gate))  # the latency stepped to among them
        if key not in cached:
            cached[key] = _one_step(observer, fit, rows, fit_from, w_start, gate)[0]
    finally:
        observer.latency = used
    return cached[key]


def latency_bracket(latency: float, sigma: float) -> tuple[float, float]:
    """The latencies [s] :func:`latency_sensitivity` steps to: one standard deviation either side, the lower at least 0."""
    return max(float(latency) - float(sigma), 0.0), float(latency) + float(sigma)


def latency_sensitivity(observer: NeuroAdaptiveObserver, sensors: dict, fit: OfflineFit, sigma: float,
                        gate: float = 25.0) -> dict:  # fmt: skip
    """The estimated camera latency's own uncertainty, in the bands.

    The latency is estimated from the log (:func:`.latency._estimate_latency`) with a standard deviation
    ``sigma`` [s] from its profile. The stiffness leans on it: on the generalisation benchmark's highway drives
    it moved 0.4-0.8 % per millisecond, and an estimate 1-4 ms off left the stiffness out of its band. The
    weights' change per ``sigma`` is the difference of one Gauss-Newton step from the window's baseline at
    ``latency - sigma`` (at least 0) and at ``latency + sigma``, scaled to ``2 sigma`` apart (both steps share the
    baseline's own residual step, which cancels); it is kept in ``fit.latency_alternatives`` and the bands add
    its squared projection (the delta method; :meth:`.offline.OfflineFit.prior_sensitivity`). The reported
    weights stay.

    Returns
    -------
    dict
        The latency, its standard deviation, the latencies stepped to and the window.
    """
    window_s, _, max_iter, tol, min_decrease = WINDOW_REFIT
    rows, fit_from, w_same, _ = _window_baseline(observer, sensors, fit, window_s, gate, max_iter, tol, min_decrease)
    base = _baseline_key(observer, window_s, gate, max_iter, tol, min_decrease)
    lo, hi = latency_bracket(observer.latency, sigma)
    try:
        step_lo = _latency_step(observer, fit, base, rows, fit_from, w_same, lo, gate)
        step_hi = _latency_step(observer, fit, base, rows, fit_from, w_same, hi, gate)
    finally:
        hold_fit(observer, fit)
    fit.latency_alternatives = [(step_hi - step_lo) * (float(sigma) / (hi - lo))] if hi > lo else []
    t_w = np.asarray(rows["t"], dtype=float)
    return {"latency_s": float(observer.latency), "latency_std_s": float(sigma), "stepped_to_s": [lo, hi],
            "window_s": [float(t_w[0]), float(t_w[-1])],
            "method": "the weights' change per standard deviation of the latency (one Gauss-Newton step from the "
                      "window's fit at either end), added to the bands (delta method)"}  # fmt: skip


def _other_hold(hold: str) -> str:
    """The steering hold :func:`steering_hold_sensitivity` refits under: the other one."""
    return "hold" if hold == "ramp" else "ramp"


def _row_period(sensors: dict) -> float:
    """Median row spacing [s] (0 with fewer than two rows): :func:`steering_hold_sensitivity` skips fast logs."""
    t = np.asarray(sensors["t"], dtype=float)
    return float(np.median(np.diff(t))) if len(t) > 1 else 0.0


def prefetch_window_refits(observer: NeuroAdaptiveObserver, sensors: dict, fit, midpoint: bool = False,
                           min_row_period: float = 0.0, latency_sigma: float | None = None) -> None:
    """:func:`prefetch_window_baseline`, then the refits from it that :func:`yaw_dynamics_check` (its two
    inertias, :data:`YAW_FACTOR` and its inverse), :func:`steering_delay_check` (:data:`STEERING_DELAY`) and
    :func:`steering_hold_sensitivity` (the other hold;
    ``midpoint`` and ``min_row_period`` as the caller will pass them) make with their defaults, ahead of them,
    and :func:`latency_sensitivity`'s two steps when ``latency_sigma`` [s] is given.

    Why: like the baseline, these refits need only the fit's weights and prior precision and the observer's
    assumptions, so :func:`.estimator.estimate` computes them on the thread that runs beside the fit's final
    recorded pass (one core): on a 30 min, 100 Hz log that core was idle for about 0.9 s after the second latency
    profile and the baseline, and the checks then ran their refits after the final pass. The checks find them
    in the cache (:func:`_window_refit`); the same refits, bit for bit. The observer's assumptions are restored.
    """
    window_s, gate, max_iter, tol, min_decrease = WINDOW_REFIT
    rows, fit_from, w_same, c_same = _window_baseline(observer, sensors, fit, window_s, gate, max_iter, tol, min_decrease)
    base = _baseline_key(observer, window_s, gate, max_iter, tol, min_decrease)
    vehicle, used = observer.vehicle, observer.steering_hold
    try:
        for f in (YAW_FACTOR, 1.0 / YAW_FACTOR):
            observer.set_vehicle(vehicle.replace(Iz=vehicle.Iz * f))
            _window_refit(observer, fit, base, rows, fit_from, w_same, max_iter, gate, tol, min_decrease)
    finally:
        observer.set_vehicle(vehicle)
    if c_same - _delay_screen(observer, fit, base, rows, fit_from, w_same, STEERING_DELAY, gate) > DELAY_DECISIVE_CHI2:
        _delay_refit(observer, fit, base, rows, fit_from, w_same, STEERING_DELAY, max_iter, gate, tol, min_decrease)
    if latency_sigma is not None:
        for latency in latency_bracket(observer.latency, latency_sigma):
            _latency_step(observer, fit, base, rows, fit_from, w_same, latency, gate)
    if _row_period(sensors) < min_row_period:  # steering_hold_sensitivity skips the refit there
        return
    try:
        observer.steering_hold = _other_hold(used)
        n_alt = 2 * max_iter if midpoint else max_iter
        _window_refit(observer, fit, base, rows, fit_from, w_same, n_alt, gate, tol, min_decrease)
    finally:
        observer.steering_hold = used


def steering_hold_sensitivity(observer: NeuroAdaptiveObserver, sensors: dict, fit: OfflineFit, gate: float = 25.0,
                              max_iter: int = 2, tol: float = 1e-3, min_decrease: float = 1e-2,
                              min_row_period: float = 0.0, window_s: float = 300.0, decide_by_cost: bool = False,
                              decisive_chi2: float = 10.0, midpoint: bool = False,
                              alternative_iter: int | None = None, fast_rows: tuple[float, float] = (0.002, 100.0),
                              keep_term: bool = False) -> dict:  # fmt: skip
    """Refit under the other steering hold (``hold`` <-> ``ramp``) from the fit's weights and keep
    the weight change in ``fit.hold_alternatives`` (:meth:`OfflineFit.variance` adds it).

    What the steering did between two log rows is not in the log. A simulator holds it over
    its step; a steering wheel sampled by a logger moves continuously; a driver reacting to
    camera frames does a bit of both. Neither the prediction-error cost nor the evidence can
    tell (the learned curve and the latency absorb a wrong choice), so the answer's change
    under the other hold is reported as uncertainty: half of it is one standard deviation
    (the two holds bracket what the steering did). Rows closer than ``min_row_period`` [s]
    are skipped (the two holds differ by less than half a row there). The default, 0, asks at every
    row rate, as :func:`.estimator.estimate` does (it had skipped IMU logs below 2 ms): a camera log's
    answer moves 0.1-0.5 % between the holds even at 1 kHz rows (a package drive's steering steps at a frame's row in reaction to that frame's noise; an
    independent generator's steering is smooth: the two preferred opposite holds), and an exact 1 kHz
    IMU's by 0.5-0.8 %, ten of its standard deviations (the cost decides there: chi-square 840-950).
    A log longer than ``window_s`` [s] is refitted under both holds on its most active window
    (the change, a timing effect, is about the same on any stretch of the drive).

    With ``decide_by_cost`` (a model that measures a_y: the force, hence the steering, shows in
    it at once) a cost difference above ``decisive_chi2`` between the two refitted holds
    decides instead: no sensitivity term, and ``info["switch"]`` says whether the other hold
    won (the caller refits under it). Rows closer than ``fast_rows[0]`` [s] need ``fast_rows[1]`` to drop the
    other hold's answer from the bands (between the two, ``switch`` as above and the term kept): there the
    holds are less than a millisecond of steering timing apart, which other timing errors of a model can
    outweigh (measured: a package drive's exact 1 kHz IMU, steering held over each tick, preferred the hold by
    840-950 and read right with it; the generalisation benchmark's IMU scenario ``imu_white`` 9, a sampled
    continuous wheel at 1 kHz, preferred the hold by 13.7 and read +0.30 / +0.28 % with it, +0.01 / +0.03 %
    ramped; an independent generator's 1 kHz logs 8.6 and -0.4). With ``keep_term`` the other hold's answer stays
    in the bands whatever the cost says, and a hold preferred by more than ``decisive_chi2`` is reported
    instead of the midpoint. A camera alone decides only so (the estimator passes ``keep_term`` and
    ``decisive_chi2`` 100): the curve and the latency
    absorb a wrong hold (a 100 Hz log's cost preferred the held steering by 20 while it read the stiffness
    +1.8 / +2.6 % off, the ramped +0.15 / +0.14 %; the package's noisy camera drives differ by less than 3.2).
    Noise-free cameras decide right: the package's simulator (rows = its ticks, steering held over each) held
    by 2221, an independent generator's sampled wheel ramped by 2081 (100 Hz rows) and 24 (1 kHz).

    With ``midpoint`` (a camera log whose rows lie between its frames, where nothing in the log
    decides; :func:`.estimator.estimate` keeps the ramp when the rows are the frames themselves,
    which come from a drive faster than its frames) the reported weights move
    to the midpoint of the two holds' answers, and the band's term is half their difference:
    the answer nearest to whichever the steering did, with a band that reaches both. Kept at
    one end (the ramp), a 100 Hz log whose steering was held read -1.75 / -2.17 % with a band of
    +/-1.65 / 2.47 % (front not covered), its held refit -0.14 / +0.20 %; a 1 kHz log decimated
    to 100 Hz read +0.11 / +0.54 % ramped and +1.87 / +3.09 % held. The samples cannot tell the
    two apart: in both, the steering change at a frame's row is the reaction to that frame
    (R^2 0.47). At a 20 Hz camera's frames only, from the same 1 kHz drive, the holds differ by
    10-16 % and the ramp is the near one (+1.2 / +1.8 %; the midpoint +5.4 / +8.6 %).
    ``alternative_iter`` Gauss-Newton steps (default ``2 * max_iter`` with ``midpoint``, else
    ``max_iter``) carry the other hold's refit from the window's baseline.
    """
    period = _row_period(sensors)
    used = observer.steering_hold
    other = _other_hold(used)
    if period < min_row_period:
        fit.hold_alternatives = []
        return {"other": other, "sensitivity": "skipped: rows closer than "
                f"{1000 * min_row_period:g} ms, the holds differ by less than half of that"}  # fmt: skip
    lo, hi = observer._weight_box()
    # a long log: its most active window, both holds refitted
    rows, fit_from, w_same, c_same = _window_baseline(observer, sensors, fit, window_s, gate, max_iter, tol, min_decrease)
    base = _baseline_key(observer, window_s, gate, max_iter, tol, min_decrease)
    t_w = np.asarray(rows["t"], dtype=float)
    try:
        observer.steering_hold = other
        n_alt = int(alternative_iter) if alternative_iter is not None else (2 * max_iter if midpoint else max_iter)
        w_alt, c_alt, it = _window_refit(observer, fit, base, rows, fit_from, w_same, n_alt, gate, tol, min_decrease)
    finally:
        observer.steering_hold = used
        hold_fit(observer, fit)
    w_alt = fit.weights + (w_alt - w_same)
    decrease = float(c_same - c_alt[-1])  # > 0: the other hold fits the window better (chi-square units)
    info = {"other": other, "iterations": it, "window_s": [float(t_w[0]), float(t_w[-1])],
            "cost_decrease_under_other_chi2": decrease}  # fmt: skip
    decisive = fast_rows[1] if period < fast_rows[0] else decisive_chi2
    if decide_by_cost:  # the threshold that acts: dropping the other's answer, or (keep_term) preferring one
        info["decisive_chi2"] = float(decisive_chi2 if keep_term else decisive)
    if decide_by_cost and not keep_term and abs(decrease) > decisive:
        fit.hold_alternatives = []
        info["sensitivity"] = "decided by the fit (the measurement answers the steering directly)"
        info["switch"] = decrease > 0
        return info
    # the two holds bracket what the steering did (held, ramped, or in between): half the change
    # is the standard deviation, so the two-sigma band reaches the other hold's answer
    half = 0.5 * (w_alt - fit.weights)
    fit.hold_alternatives = [half]
    info["sensitivity"] = "refitted under the other hold; the change is in the bands"
    preferred = decide_by_cost and abs(decrease) > decisive_chi2
    if preferred:  # fast rows, or keep_term (a camera log): preferred, the other's answer kept in the bands
        info["switch"] = decrease > 0
        info["sensitivity"] = ("the fit prefers one hold (short of dropping the other: rows this close, or a camera "
                               "alone): its answer, with the other's in the bands")  # fmt: skip
    if midpoint and not preferred:  # the answer midway between the holds; its band (2 sigma >= the half change) reaches both
        fit.weights = np.clip(fit.weights + half, lo, hi)
        hold_fit(observer, fit)
        info["reported"] = (f"midway between the answers under {used!r} and {other!r} (the log cannot tell which the "
                            "steering did); the band reaches both")  # fmt: skip
    return info


def yaw_dynamics_check(observer: NeuroAdaptiveObserver, sensors: dict, fit: OfflineFit, factor: float = YAW_FACTOR,
                       max_factor: float = 1.43, gate: float = 25.0, max_iter: int = 2, tol: float = 1e-3, min_decrease: float = 1e-2,
                       window_s: float = 300.0, decisive_chi2: float = 10.0) -> dict:  # fmt: skip
    """Does the log's transient response agree with the vehicle file's yaw dynamics?

    The weights are refitted (at most ``max_iter`` Gauss-Newton steps from the fit, on the
    log's most active ``window_s`` seconds) with the yaw inertia scaled by ``factor`` and by
    ``1 / factor``. Where the model is right the prediction-error cost is lowest at the
    file's inertia (measured on low-order Pacejka lane-change and curve logs: both sides cost
    30-190 more); a decrease above ``decisive_chi2`` (chi-square units, one parameter) on either
    side rejects the file's yaw dynamics: the inertia is off, or the vehicle has dynamics a
    bicycle lacks (on a CommonRoad multi-body log the cost falls toward a lower inertia, by 7 at
    x0.8 at the reported process noise: ``benchmarks/bench_multi_body_diagnosis.py``).

    Then the stiffness is only as sure as its dependence on the yaw dynamics. The weights are
    refitted once more at the inertia the cost prefers (the parabola through the three costs
    in log inertia, within ``1 / max_factor`` .. ``max_factor``), and the weight changes of all
    refits are kept in ``fit.dynamics_alternatives``: the bands add the largest squared change
    of each functional. The direction is not trusted: on a log whose vehicle file has a wrong
    ``Iz`` the preferred inertia is the right one (a file 25 % low: preferred x1.39), on a
    multi-body log it is the best *bicycle*, not the vehicle's effective stiffness (preferred
    lower, while the effective stiffness lies the other way). A consistent log adds nothing.

    Returns
    -------
    dict
        ``verdict`` (``"consistent"`` or ``"rejected"``), the cost decrease per inertia
        factor refitted (positive: that inertia fits better; the third, after a rejection, is
        the preferred one), the window, and a sentence saying what
        a rejection means.
    """
    rows, fit_from, w_same, c_same = _window_baseline(observer, sensors, fit, window_s, gate, max_iter, tol, min_decrease)
    base = _baseline_key(observer, window_s, gate, max_iter, tol, min_decrease)
    t_w = np.asarray(rows["t"], dtype=float)
    vehicle = observer.vehicle
    decrease, changes = {}, []

    def refit(f: float, n_iter: int = max_iter) -> None:
        observer.set_vehicle(vehicle.replace(Iz=vehicle.Iz * f))
        w_f, costs, _ = _window_refit(observer, fit, base, rows, fit_from, w_same, n_iter, gate, tol, min_decrease)
        decrease[f"{f:.4g}"] = float(c_same - costs[-1])
        changes.append(w_f - w_same)

    try:
        for f in (factor, 1.0 / factor):
            refit(f)
        d_lo, d_hi = decrease[f"{factor:.4g}"], decrease[f"{1.0 / factor:.4g}"]
        rejected = max(d_lo, d_hi) > decisive_chi2
        if rejected:  # the inertia the cost prefers (parabola in log inertia), within [max_factor^-1, max_factor]
            h = -np.log(factor)
            curv = -(d_lo + d_hi) / (h * h)  # cost(x) = c0 - d(x): its second derivative
            slope = (d_lo - d_hi) / (2.0 * h)  # first derivative at x = 0
            x = -slope / curv if curv > 0 else np.sign(-slope) * np.inf
            x = float(np.clip(x, -np.log(max_factor), np.log(max_factor)))
            if abs(abs(x) - h) > 0.03:
                refit(float(np.exp(x)), 3 * max_iter)  # the answer the band reaches for: converged
    finally:
        observer.set_vehicle(vehicle)
        hold_fit(observer, fit)
    fit.dynamics_alternatives = changes if rejected else []
    info = {
        "verdict": "rejected" if rejected else "consistent",
        "test": f"refit with the yaw inertia x{factor:g} and x{1 / factor:.4g}; rejected when either fits the "
        f"window better by more than chi-square {decisive_chi2:g}",
        "cost_decrease_chi2_by_inertia_factor": decrease,
        "window_s": [float(t_w[0]), float(t_w[-1])],
    }
    if rejected:
        best = max(decrease, key=decrease.get)
        info["preferred_inertia_factor"] = float(best)
        info["meaning"] = (f"the log's transient response prefers {float(best):.3g} x the file's yaw inertia: the "
                           "vehicle file's Iz, or the bicycle model itself (roll, suspension or tire relaxation "
                           "dynamics), is off; the bands add the stiffness's change under that inertia")  # fmt: skip
    return info


def steering_delay_check(observer: NeuroAdaptiveObserver, sensors: dict, fit: OfflineFit,
                         delay: float = STEERING_DELAY, max_delay: float = 0.05, gate: float = 25.0, max_iter: int = 2,
                         tol: float = 1e-3, min_decrease: float = 1e-2, window_s: float = 300.0,
                         decisive_chi2: float = DELAY_DECISIVE_CHI2) -> dict:  # fmt: skip
    """Does the log's response follow the logged steering without a lag?

    The single-track model turns the logged road-wheel angle into tire force at once. A real car
    does not quite: the tires build their force over a relaxation length (0.3-1 m, i.e. 10-40 ms
    at road speeds), the steering system is compliant, an actuator lags. The stiffness leans hard
    on that timing: refitted with the steering 10 ms late, the generalisation benchmark's drives
    read it 4-10 % higher. So the weights are refitted (on the log's most active ``window_s``
    seconds, from the fit, at most ``max_iter`` Gauss-Newton steps) with the steering ``delay``
    late, screened first by one pass (:func:`_delay_screen`). Where the model is right the
    prediction-error cost rises (the low-order Pacejka drives of the generalisation benchmark's
    tuning family, scenarios 0-9: by 25-270 at 10 ms); a decrease above ``decisive_chi2``
    rejects the lag-free model (its CommonRoad multi-body family, 0.45 m tire relaxation: 13
    of 20 drives; scenario 0 by 37, whose stiffness read -8.7 / -0.6 % with a front band that
    missed). Then the steering is refitted 2
    ``delay`` late, and at the delay the cost prefers (the parabola through the three, within
    ``max_delay``), and the weight changes of the refits the log cannot rule out (cost within
    ``decisive_chi2`` of the best) are kept in ``fit.delay_alternatives``: the bands add the
    largest squared change of each functional (:meth:`.offline.OfflineFit.variance`).
    A delay stands for a lag of any origin, so the direction is not trusted and the reported
    weights stay; a consistent log adds nothing.

    Returns
    -------
    dict
        ``verdict`` (``"consistent"`` or ``"rejected"``), the cost decrease per delay refitted
        [ms] (positive: that delay fits better), the window, and, after a rejection, the delay
        the cost prefers and a sentence saying what it means.
    """
    rows, fit_from, w_same, c_same = _window_baseline(observer, sensors, fit, window_s, gate, max_iter, tol, min_decrease)
    base = _baseline_key(observer, window_s, gate, max_iter, tol, min_decrease)
    t_w = np.asarray(rows["t"], dtype=float)
    decrease, changes = {}, []

    def refit(d: float, n_iter: int = max_iter) -> float:
        w_d, costs, _ = _delay_refit(observer, fit, base, rows, fit_from, w_same, d, n_iter, gate, tol, min_decrease)
        decrease[f"{1e3 * d:.4g}"] = float(c_same - costs[-1])
        changes.append((float(c_same - costs[-1]), w_d - w_same))
        return decrease[f"{1e3 * d:.4g}"]

    screened = float(c_same - _delay_screen(observer, fit, base, rows, fit_from, w_same, delay, gate))
    try:
        # one pass first: a Gauss-Newton step's predicted decrease, which overstates the refit's
        d1 = refit(delay) if screened > decisive_chi2 else screened
        rejected = d1 > decisive_chi2
        preferred = None
        if rejected:  # the delay the cost prefers: the parabola dec(x) = a x + b x^2 through (0, 0), (h, d1), (2h, d2)
            h = delay
            d2 = refit(2.0 * h)
            b = (d2 - 2.0 * d1) / (2.0 * h * h)
            a = (d1 - b * h * h) / h
            preferred = float(np.clip(-a / (2.0 * b), 0.0, max_delay)) if b < 0 else float(max_delay)
            if min(abs(preferred - h), abs(preferred - 2.0 * h)) > 0.002:
                refit(preferred, 3 * max_iter)  # the answer the band reaches for: converged
    finally:
        hold_fit(observer, fit)
    # the delays the log cannot rule out: within decisive_chi2 of the best fitting one (a probe beyond it, e.g. 2 x
    # delay when the best is near delay, is not an answer: the stiffness moves 7-10 % per 10 ms)
    best = max((c for c, _ in changes), default=0.0)
    fit.delay_alternatives = [w for c, w in changes if c >= best - decisive_chi2] if rejected else []
    info = {
        "verdict": "rejected" if rejected else "consistent",
        "test": f"refit with the steering {1e3 * delay:g} ms late; rejected when it fits the window better by more "
        f"than chi-square {decisive_chi2:g}",
        "cost_decrease_chi2_by_delay_ms": decrease,
        "predicted_decrease_chi2_one_step": screened,
        "window_s": [float(t_w[0]), float(t_w[-1])],
    }
    if screened <= decisive_chi2:
        info["screened"] = (f"one Gauss-Newton step at {1e3 * delay:g} ms predicted a decrease of {screened:.3g}, not "
                            f"above {decisive_chi2:g}: consistent without the refit")  # fmt: skip
    if rejected:
        info["preferred_delay_s"] = preferred
        info["meaning"] = (f"the log's response follows the steering about {1e3 * preferred:.0f} ms late: tire "
                           "relaxation, steering compliance or an actuator lag the single-track model lacks (or a "
                           "steering column logged early, or a lane camera whose e1 is measured ahead of the CG where "
                           "the vehicle file's camera_x does not put it: 1.5 m ahead read as the CG's is rejected so, "
                           "at 17 ms); the bands add the stiffness's change under that lag")  # fmt: skip
    return info


def process_noise_sensitivity(observer: NeuroAdaptiveObserver, sensors: dict, fit: OfflineFit,
                              step: float = PROCESS_NOISE_STEP, gate: float = 25.0, max_iter: int = 2, tol: float = 1e-3,
                              min_decrease: float = 1e-2, window_s: float = 300.0) -> dict:  # fmt: skip
    """How much the answer leans on the process noise the fit stopped at (camera and IMU fused).

    :func:`.offline.refine` lowers the model's force-error process noise stage by stage while
    the innovations stay consistent (mean NIS per degree of freedom at most 1.3) and answers
    at the smallest consistent stage. A larger process noise is never ruled out that way (the
    NIS only falls), and with the camera and the IMU fused the answer moved with it by more
    than the band: on the generalisation benchmark's fused scenario 15 (the driver steering at
    every camera frame in reaction to its noise) the stages from 7.5 N to the chosen 0.75 N
    read +0.20, +0.39, +0.69 % (front) with a two-sigma band of +/-0.37 % at the last, at
    NIS 0.86-0.87 for all three; over six IMU noise realisations of that drive the fused
    answer stayed at +0.57 to +0.73 %, a bias of the drive, not noise the band could hold.
    So the weights are refitted (on the log's most active ``window_s``, from the window's
    baseline, ``max_iter`` Gauss-Newton steps) with the force error ``step`` times the
    chosen one (one stage up: the stages are 3 or 10/3 apart), and the change is kept in
    ``fit.process_noise_alternatives``: the bands add it as every assumption the log cannot
    settle (:meth:`.offline.OfflineFit.prior_sensitivity`). The reported weights stay.

    Returns
    -------
    dict
        The chosen and the refitted force error [N], the window and the iterations.
    """
    rows, fit_from, w_same, _ = _window_baseline(observer, sensors, fit, window_s, gate, max_iter, tol, min_decrease)
    base = _baseline_key(observer, window_s, gate, max_iter, tol, min_decrease)
    chosen = float(fit.force_error)
    try:
        observer.set_force_error(chosen * step)
        w_alt, _, it = _window_refit(observer, fit, base, rows, fit_from, w_same, max_iter, gate, tol, min_decrease)
    finally:
        hold_fit(observer, fit)
    fit.process_noise_alternatives = [w_alt - w_same]
    t_w = np.asarray(rows["t"], dtype=float)
    return {"force_error_N": chosen, "refitted_at_N": chosen * step, "iterations": int(it),
            "window_s": [float(t_w[0]), float(t_w[-1])],
            "sensitivity": "refitted with the process noise one stage up (the NIS cannot rule it out); the change "
                           "is in the bands"}  # fmt: skip
