"""Fit candidate effects and choose among them: greedy forward selection with a stopping rule.

Criterion. With the channel noise levels fixed (estimated from the data, :mod:`.data`),
``chi2 = sum(((y - y_model) / sigma)^2)`` is ``-2 log-likelihood`` up to a constant. A
candidate with ``k`` parameters that lowers ``chi2`` by ``LR`` is **accepted** only if

1. its likelihood-ratio p-value ``P(chi2_k > LR)`` is below ``alpha / n_candidates``
   (Bonferroni over the candidates tried in the round), and
2. it lowers the BIC: ``LR > k ln(n)`` with ``n`` the number of measurements.

Selection. Each round screens every remaining candidate by its score statistic, fits the
promising ones (others held at their current values), accepts the best one if it
passes, re-fits all accepted effects jointly, and drops any accepted effect that is no
longer significant given the others (backward check). It stops when no candidate passes
or ``max_effects`` are in. The statistics are in :mod:`.criteria`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from .criteria import acceptance_threshold, long_run_variance, signature_correlation, significance
from .effects import CandidateEffect
from .residuals import Evaluation, ResidualModel

__all__ = [
    "CandidateFit",
    "SelectionStep",
    "SelectionResult",
    "fit_effects",
    "score_statistic",
    "forward_selection",
]


@dataclass
class CandidateFit:
    """The fit of a set of effects (the last one being the candidate).

    Attributes
    ----------
    effects : tuple of CandidateEffect
        Effects whose parameters were fitted (others in ``theta`` held).
    values : list of ndarray
        Fitted parameters per effect.
    stderr : list of ndarray
        Standard errors from the Gauss-Newton Hessian (NaN if singular).
    evaluation : Evaluation
        Residual at the optimum (window states converged).
    nfev : int
        Residual evaluations used.
    """

    effects: tuple[CandidateEffect, ...]
    values: list[NDArray]
    stderr: list[NDArray]
    evaluation: Evaluation
    nfev: int
    #: Gauss-Newton Hessian ``J^T J`` of the scaled parameters (None if the fit did not move)
    hessian: NDArray | None = None
    #: fitted scaled parameters (``values / scale``)
    z: NDArray | None = None

    @property
    def chi2(self) -> float:
        return self.evaluation.chi2

    @property
    def theta(self) -> NDArray:
        return self.evaluation.theta


#: the backward check refits without an effect only if its Wald statistic is below this multiple of the threshold
WALD_SKIP = 10.0


def _wald(fit: CandidateFit, effect: CandidateEffect) -> float:
    """Wald statistic of ``effect``'s parameters in a joint ``fit`` (0 when unknown): ``d^T (H^-1)_ee^-1 d``
    with ``d`` the scaled deviation from absence and ``H = J^T J`` the Gauss-Newton Hessian of the scaled
    parameters: near the optimum ``chi2(z) = chi2_min + |J (z - z*)|^2``, so this is the chi2 increase of
    dropping the effect with the others refitted, to second order."""
    if fit.hessian is None or fit.z is None or effect not in fit.effects:
        return 0.0
    i = 0
    for e in fit.effects:
        if e is effect:
            break
        i += e.n_parameters
    k = effect.n_parameters
    d = fit.z[i : i + k] - np.asarray(effect.absent) / np.asarray(effect.scale)
    try:
        cov = np.linalg.inv(fit.hessian)[i : i + k, i : i + k]
        return float(d @ np.linalg.solve(cov, d))
    except np.linalg.LinAlgError:
        return 0.0


def _pack(effects: Sequence[CandidateEffect], theta: NDArray) -> NDArray:
    return np.concatenate([e.values_in(theta) / np.asarray(e.scale) for e in effects])


def _unpack(effects: Sequence[CandidateEffect], theta: NDArray, z: NDArray) -> NDArray:
    out = np.array(theta, dtype=float)
    i = 0
    for e in effects:
        k = e.n_parameters
        out = e.apply(out, z[i : i + k] * np.asarray(e.scale))
        i += k
    return out


def fit_effects(
    model: ResidualModel,
    effects: Sequence[CandidateEffect],
    theta: NDArray,
    starts: Sequence[NDArray] | None = None,
    max_nfev: int = 30,
    x0_guess: NDArray | None = None,
    outer: int = 3,
    reference: Evaluation | None = None,
    warm_start: bool = True,
    diff_step: float = 1e-3,
    jac: str = "2-point",
    ftol: float = 1e-8,
    xtol: float = 1e-6,
    linearised: bool = False,
    kink_restart: bool = True,
) -> CandidateFit:
    """Fit the parameters of ``effects`` jointly (others held at ``theta``) by scipy least squares.

    At every evaluation the window initial states are fitted to convergence
    (:meth:`.ResidualModel.converged`), warm-started from the best states seen so far, so
    the cost is a function of the parameters alone. The optimum is re-evaluated and the
    run repeated (at most ``outer`` times) while that still lowers the cost. Several
    starting points (``starts``, default the effect's own plus the current values) are
    scored first and the best one is refined. ``reference``: the converged evaluation at
    ``theta`` if already known. ``warm_start=False``: every evaluation starts from the
    reference's window states instead of the best seen so far, so the cost is a
    deterministic function of the parameters even where a window has several local
    minima; ``diff_step`` and ``jac``: relative finite-difference step and scheme of the
    optimizer (larger, central, for a rough cost); ``ftol``, ``xtol``: its tolerances.
    ``linearised``: inside the optimizer the window states take ``config.gn_iterations``
    Gauss-Newton steps from the reference's states with the reference's state sensitivities
    (three simulations per window instead of about fifteen for converged states; the cost is
    then a smooth deterministic function of the parameters); the optimum is re-evaluated with
    converged states, and the run repeated from there while that lowers the cost, so the
    result is compared on converged residuals as before. ``kink_restart``: a single effect with a
    ``kink_start`` (:class:`.effects.CandidateEffect`) whose fitted limit is inactive on this log is fitted
    again from a start where it is active, and the better fit is returned.
    """
    effects = tuple(effects)
    lo = np.concatenate([[b[0] / s for b, s in zip(e.bounds, e.scale)] for e in effects])
    hi = np.concatenate([[b[1] / s for b, s in zip(e.bounds, e.scale)] for e in effects])
    current = _pack(effects, theta)
    cands = [current]
    if starts is not None:
        cands += [np.asarray(s, dtype=float) / np.concatenate([e.scale for e in effects]) for s in starts]
    elif len(effects) == 1:
        e = effects[0]
        cands += [np.asarray(s) / np.asarray(e.scale) for s in e.starts]
    cands = [np.clip(c, lo, hi) for c in cands]
    uniq: list[NDArray] = []
    for c in cands:
        if not any(np.allclose(c, u) for u in uniq):
            uniq.append(c)
    ref = reference if reference is not None else model.converged(theta, x0_guess)
    start_eval = ref
    nfev = 1
    span = hi - lo
    warm = {"x0": ref.x0, "chi2": ref.chi2}

    lin = {"x0": ref.x0, "jac": ref.jac}

    def fun(z: NDArray) -> NDArray:
        # window states converged, warm-started from the best states seen so far (the
        # converged residual does not depend on where the iteration starts)
        nonlocal nfev
        nfev += 1
        if linearised:
            return model.evaluate(_unpack(effects, theta, z), jac=lin["jac"], x0_guess=lin["x0"]).resid
        ev = model.evaluate(_unpack(effects, theta, z), x0_guess=warm["x0"], converge=True)
        if warm_start and ev.chi2 < warm["chi2"]:
            warm["x0"], warm["chi2"] = ev.x0, ev.chi2
        return ev.resid

    z, best_cost = current, math.inf
    for z0 in uniq:
        if linearised:
            # starting points on converged states; the best one is where the optimizer linearises
            ev = ref if z0 is current else model.converged(_unpack(effects, theta, z0), ref.x0)
            nfev += 0 if z0 is current else 1
            if ev.chi2 < best_cost:
                z, best_cost = z0, ev.chi2
                lin = {"x0": ev.x0, "jac": ev.jac}
            continue
        r = fun(z0)
        c = float(r @ r)
        if c < best_cost:
            z, best_cost = z0, c
    res_jac = None
    # linearised: re-linearise at the converged optimum until that no longer lowers the cost (a large effect
    # moves the window states far from the reference's)
    for run in range(outer + 3 if linearised else outer):
        z0 = np.clip(z, lo + 1e-6 * span, hi - 1e-6 * span)  # trf needs a strictly feasible start
        res = optimize.least_squares(
            fun, z0, bounds=(lo, hi), method="trf", jac=jac, diff_step=diff_step, x_scale=1.0,
            ftol=ftol, xtol=xtol, gtol=1e-10, max_nfev=max_nfev,
        )  # fmt: skip
        ev = model.converged(_unpack(effects, theta, res.x), warm["x0"])
        if not warm_start:
            warm["x0"], warm["chi2"] = ev.x0, ev.chi2
        nfev += 1
        if not ev.chi2 < ref.chi2:
            break
        # a re-evaluation from better window states that lowers the cost further means
        # the run ended on a stale warm start: run again from there
        stale = ev.chi2 < 2.0 * res.cost - 0.05 - 1e-7 * ev.chi2
        ref, z, res_jac = ev, res.x, res.jac
        lin = {"x0": ev.x0, "jac": ev.jac}
        if not stale:
            break
    final = ref
    if final is start_eval:
        z = current
    # standard errors from the Gauss-Newton Hessian J^T J of the fitted parameters
    se = np.full(len(z), math.nan)
    if res_jac is not None:
        try:
            se = np.sqrt(np.clip(np.diag(np.linalg.inv(res_jac.T @ res_jac)), 0.0, None))
        except np.linalg.LinAlgError:
            pass
    values, stderr = [], []
    i = 0
    for e in effects:
        k = e.n_parameters
        values.append(e.values_in(final.theta))
        stderr.append(se[i : i + k] * np.asarray(e.scale))
        i += k
    hess = None if res_jac is None else res_jac.T @ res_jac
    fit = CandidateFit(effects, values, stderr, final, nfev, hess, np.asarray(z, dtype=float))
    if kink_restart and len(effects) == 1 and effects[0].kink_start is not None:
        start = effects[0].kink_start(values[0], model.data)
        if start is not None:
            other = fit_effects(
                model, effects, theta, starts=[start], max_nfev=max_nfev, outer=outer, reference=start_eval,
                warm_start=warm_start, diff_step=diff_step, jac=jac, ftol=ftol, xtol=xtol, linearised=linearised,
                kink_restart=False,
            )  # fmt: skip
            other.nfev += fit.nfev
            if other.chi2 < fit.chi2:
                return other
            fit.nfev = other.nfev
    return fit


def score_statistic(
    model: ResidualModel, effect: CandidateEffect, current: Evaluation, rel_step: float = 0.2,
    columns: list | None = None, converged: bool = False,
) -> float:  # fmt: skip
    """Predicted ``chi2`` reduction of adding ``effect`` (a score / Lagrange-multiplier test).

    The residual's sensitivity to each parameter is a secant over ``rel_step`` times the
    parameter's scale (window states refitted); one bounded Gauss-Newton step from the
    absent values predicts the reduction. Under the null it is about ``chi2_k``; it costs
    ``k`` evaluations where a fit costs tens. If ``columns`` is a list, the sensitivity
    matrix (M, k) (the effect's *signature* in the residual) is appended to it.
    ``converged``: the secants re-converge the window states (more accurate when the
    residual is far from white, at a few times the cost).
    """
    r0 = current.resid
    cols = []
    for i in range(effect.n_parameters):
        h = rel_step * effect.scale[i]
        lo, hi = effect.bounds[i]
        if effect.absent[i] + h > hi:
            h = -h
        vals = np.array(effect.absent, dtype=float)
        vals[i] += h
        if converged:
            ev = model.converged(effect.apply(current.theta, vals), current.x0)
        else:
            ev = model.evaluate(effect.apply(current.theta, vals), jac=current.jac, x0_guess=current.x0)
        cols.append((ev.resid - r0) / h)
    J = np.column_stack(cols)
    if columns is not None:
        columns.append(J)
    # least squares (a parameter without effect at absence, e.g. the cap of a superelevation whose rate is
    # zero, gives a zero column)
    delta = -np.linalg.lstsq(J, r0, rcond=None)[0]
    # respect the bounds (one-sided parameters such as a relaxation length)
    lo = np.array([b[0] for b in effect.bounds]) - np.asarray(effect.absent)
    hi = np.array([b[1] for b in effect.bounds]) - np.asarray(effect.absent)
    delta = np.clip(delta, lo, hi)
    pred = r0 + J @ delta
    return float(max(r0 @ r0 - pred @ pred, 0.0))



@dataclass
class SelectionStep:
    """One round of the forward selection (for the report)."""

    round: int
    chi2_before: float
    tried: dict[str, dict] = field(default_factory=dict)
    accepted: str | None = None
    dropped: list[str] = field(default_factory=list)


@dataclass
class SelectionResult:
    """Outcome of :func:`forward_selection`."""

    nominal: Evaluation
    final: Evaluation
    accepted: list[tuple[CandidateEffect, NDArray, NDArray]]  # effect, values, stderr
    steps: list[SelectionStep]
    n_evaluations: int


def forward_selection(
    model: ResidualModel,
    candidates: Sequence[CandidateEffect],
    alpha: float,
    max_effects: int,
    progress: Callable[[str], None] | None = None,
    screen_keep: int = 2,
    screen_fraction: float = 0.25,
    screen_ratio: float = 0.05,
    correct_correlation: bool = False,
    signatures: bool = False,
    robust_states: bool = False,
) -> SelectionResult:
    """Greedy forward selection with a backward check (see module docstring).

    Each round first computes every remaining candidate's score statistic
    (:func:`score_statistic`, the linearised chi2 reduction). The ``screen_keep`` best
    are always fitted; the others only if their score reaches ``screen_fraction`` of the
    acceptance threshold and ``screen_ratio`` of the best score (the fitted reduction of a
    candidate was never more than about twice its score in our tests, so a candidate 20x
    below the best cannot win). Unfitted candidates are reported with their score.

    Long logs (more than :data:`FIT_WINDOWS` windows): every candidate is fitted on an evenly spread
    subset of that many windows and its likelihood ratio evaluated on the whole log at the fitted
    parameters (a lower bound of the whole-log ratio: no false alarm from the subset); the accepted
    effects are refitted jointly on the whole log at the end.

    ``correct_correlation``: every likelihood-ratio statistic is divided by the variance
    inflation of the residual *with* the candidate (:func:`long_run_variance`; 1 for a
    white residual), so a real log's correlated residual does not make every small
    improvement "significant" (used for IMU-only logs). ``signatures``: the round's
    candidate signatures are compared and the accepted effect gets
    ``signature_correlation`` with every other candidate (1 = indistinguishable on this log).
    ``robust_states`` (IMU-only logs, whose window fits can have several local minima): the
    nominal model starts from several window states, and after a round's fits the current
    model and every fitted candidate are re-evaluated from all the window states found in
    the round, best per window (:meth:`.ResidualModel.best_of`), so a likelihood ratio never
    credits an effect with a better local minimum that the reference could reach as well.
    It also makes the screen safer for a residual far from white, where the linearised
    score with fixed-Jacobian window states underestimated a fit tenfold (a steering delay
    on a real log): scores use converged secants, and a candidate that passed the
    acceptance test in an earlier round is always fitted again.
    """
    n = model.data.n_measurements
    nominal = model.nominal_start() if robust_states else model.converged()
    sub = None if robust_states else _fit_subset(model)

    def fit_(effects, theta, reference=None, x0_guess=None):
        """fit_effects on the whole log, or (long logs) on a subset of its windows with the result evaluated
        on the whole log: every decision uses all the data, at parameters fitted on part of it."""
        if sub is None:
            return fit_effects(model, effects, theta, reference=reference, x0_guess=x0_guess, **fit_options)
        sub_model, windows = sub
        f = fit_effects(sub_model, effects, theta, **fit_options)
        guess = (reference.x0 if reference is not None else x0_guess)
        ev = model.converged(f.theta, guess)
        return CandidateFit(f.effects, f.values, f.stderr, ev, f.nfev + 1, f.hessian, f.z)

    if progress:
        progress("nominal model")
    current = nominal
    accepted: list[CandidateEffect] = []
    values: dict[str, NDArray] = {}
    errors: dict[str, NDArray] = {}
    steps: list[SelectionStep] = []
    passed_before: set[str] = set()
    # robust: every evaluation of a fit from the same window states, and finite differences that
    # see past the small roughness a tabulated or learned tire leaves in the cost
    fit_options = (
        {"warm_start": False, "diff_step": 0.01, "jac": "3-point", "max_nfev": 12, "ftol": 1e-6, "xtol": 1e-4}
        if robust_states
        # a chi2 change of 1e-6 relative (a few hundredths for a 100 Hz log) and parameter steps of 1e-4 of their
        # scale are far below any decision threshold (LR of ~10) and any reported digit
        else {"ftol": 1e-6, "xtol": 1e-4}
    )
    for rnd in range(max_effects):
        remaining = [c for c in candidates if c.name not in values]
        if not remaining:
            break
        step = SelectionStep(rnd + 1, current.chi2)
        fits: dict[str, CandidateFit] = {}
        level = alpha / len(remaining)
        cols: dict[str, NDArray] = {}
        scores = {}
        # long logs: the screen on the fitting subset, scaled to the whole log's size
        sub_current = sub[0].converged(current.theta) if sub is not None else None
        for c in remaining:
            store: list = []
            if sub is not None:
                scores[c.name] = score_statistic(sub[0], c, sub_current) * n / sub[0].data.n_measurements
                continue
            scores[c.name] = score_statistic(
                model, c, current, columns=store if signatures else None, converged=robust_states
            )
            if signatures:
                cols[c.name] = store[0]
        if progress:
            progress(f"round {rnd + 1}: scores")
        ranked = sorted(remaining, key=lambda c: -scores[c.name])
        top = scores[ranked[0].name]
        # with the correlation correction the screen compares the score after the current residual's inflation
        screen_infl = long_run_variance(model.data, current.resid) if correct_correlation else 1.0
        for i, cand in enumerate(ranked):
            weak = scores[cand.name] / screen_infl < screen_fraction * acceptance_threshold(cand.n_parameters, n, level)
            dominated = scores[cand.name] < screen_ratio * top
            keep = i < screen_keep or (robust_states and cand.name in passed_before)
            if not keep and (weak or dominated):
                step.tried[cand.name] = {"score": scores[cand.name], "fitted": False}
                continue
            step.tried[cand.name] = {}  # filled below (keeps the ranked order)
            fit = fit_([cand], current.theta, reference=current)
            fits[cand.name] = fit
            if progress:
                progress(cand.name)
        if robust_states and fits:
            # every model of the round from every window state found in it, best per window
            starts = [current.x0] + [f.evaluation.x0 for f in fits.values()]
            current = model.best_of(current.theta, starts)
            step.chi2_before = current.chi2
            for name, f in fits.items():
                if np.array_equal(f.theta, current.theta):  # the fit stayed at the current model
                    f.evaluation = current
                else:
                    f.evaluation = model.best_of(f.theta, [f.evaluation.x0, current.x0])
        for name, fit in fits.items():
            cand = fit.effects[0]
            infl = long_run_variance(model.data, fit.evaluation.resid) if correct_correlation else None
            sig = significance(current.chi2, fit.chi2, cand.n_parameters, n, infl)
            step.tried[name] = {
                "parameters": cand.as_dict(fit.values[0]),
                "chi2": fit.chi2,
                "evaluations": fit.nfev,
                "score": scores[name],
                "fitted": True,
                **sig,
            }
        ok = [
            name for name, info in step.tried.items()
            if info["fitted"] and info["p_value"] < level and info["delta_bic"] < 0.0
        ]
        passed_before |= set(ok)
        if not ok:
            steps.append(step)
            break
        best = min(ok, key=lambda name: step.tried[name]["chi2"])
        step.accepted = best
        if signatures:
            step.tried[best]["signature_correlation"] = {
                name: signature_correlation(cols[best], J) for name, J in cols.items() if name != best
            }
        accepted.append(fits[best].effects[0])
        # joint refit of every accepted effect
        joint = fit_(accepted, fits[best].theta, x0_guess=fits[best].evaluation.x0)
        if robust_states:
            joint.evaluation = model.best_of(joint.theta, [joint.evaluation.x0, fits[best].evaluation.x0])
        current = joint.evaluation
        values = {e.name: v for e, v in zip(joint.effects, joint.values)}
        errors = {e.name: s for e, s in zip(joint.effects, joint.stderr)}
        # backward check: is every accepted effect still needed given the others?
        if len(accepted) > 1:
            for e in list(accepted):
                if len(accepted) < 2:
                    break
                others = [a for a in accepted if a is not e]
                if _wald(joint, e) > WALD_SKIP * acceptance_threshold(e.n_parameters, n, alpha):
                    # far beyond the acceptance threshold (the Wald statistic approximates the refit's LR to
                    # second order): no refit needed to know the effect stays
                    continue
                theta_wo = e.apply(current.theta, e.absent)
                # on the whole log: a subset fit would overstate the loss of dropping the effect
                without = fit_effects(model, others, theta_wo, x0_guess=current.x0, **fit_options)
                if robust_states:
                    without.evaluation = model.best_of(without.theta, [without.evaluation.x0, current.x0])
                infl = long_run_variance(model.data, current.resid) if correct_correlation else None
                sig = significance(without.chi2, current.chi2, e.n_parameters, n, infl)
                if not (sig["p_value"] < alpha and sig["delta_bic"] < 0.0):
                    accepted.remove(e)
                    step.dropped.append(e.name)
                    current = without.evaluation
                    values = {a.name: v for a, v in zip(without.effects, without.values)}
                    errors = {a.name: s for a, s in zip(without.effects, without.stderr)}
        steps.append(step)
    if sub is not None and accepted:
        # the reported parameters from all the data: a joint refit of the accepted effects on the whole log
        final = fit_effects(model, accepted, current.theta, reference=current, **{**fit_options, "max_nfev": 8})
        if final.chi2 <= current.chi2:
            current = final.evaluation
            values = {e.name: v for e, v in zip(final.effects, final.values)}
            errors = {e.name: s for e, s in zip(final.effects, final.stderr)}
    final_list = [(e, values[e.name], errors[e.name]) for e in accepted]
    n_eval = model.n_evaluations + (sub[0].n_evaluations if sub is not None else 0)
    return SelectionResult(nominal, current, final_list, steps, n_eval)


#: logs with more windows than this fit candidates on an evenly spread subset of this many windows
FIT_WINDOWS = 60


def _fit_subset(model: ResidualModel):
    """``(model on a subset of the windows, their indices)`` for a long log, else None."""
    from .data import window_subset

    d = model.data
    if d.n_windows <= FIT_WINDOWS or getattr(model, "input_noise", None) is not None:
        return None
    windows = np.unique(np.linspace(0, d.n_windows - 1, FIT_WINDOWS).round().astype(np.int64))
    sub = ResidualModel(window_subset(d, windows), model.vehicle, model.front_tire, model.rear_tire, model.config)
    return sub, windows
