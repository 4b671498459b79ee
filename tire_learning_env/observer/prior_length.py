r"""The smooth-curve prior's length scale, chosen or weighed by the log's evidence.

:func:`select_prior_length` compares the lengths of a grid by the Laplace evidence of the
offline fit's quadratic model, refits with the best one, and keeps the plausible neighbours'
answers (``fit.prior_alternatives``) so that :meth:`.offline.OfflineFit.variance` can add
how much the answer leans on the choice (a prior-sensitivity term).
"""

from __future__ import annotations

import numpy as np

from .neuro_adaptive import NeuroAdaptiveObserver
from .box_step import _solve_step
from .offline import ALTERNATIVES, OfflineFit, _final_fit, _gauss_newton

__all__ = ["select_prior_length"]


def select_prior_length(observer: NeuroAdaptiveObserver, sensors: dict, fit: OfflineFit,
                        lengths: tuple[float, ...] = (0.25, 0.5, 1.0, 2.0), gate: float = 25.0,
                        max_iter: int = 2, tol: float = 1e-3, min_decrease: float = 1e-2,
                        plausible_nats: float = 5.0, choose: bool = True) -> tuple[OfflineFit, dict]:  # fmt: skip
    """The smooth-curve prior's length scale [deg] chosen by the log's evidence (type-II maximum likelihood).

    The prior :meth:`~.basis.SoftClipBasis.slope_prior` correlates the slopes of neighbouring
    segments; a length too long for the tire pulls the curve toward a straight line through the
    range the drive excited, so the slope at zero (the stiffness) comes out low on a
    saturating curve (measured on a low-order Pacejka race car: -0.83 / -0.61 % at 1 deg,
    -0.19 / -0.22 % at 0.5 deg). No single length suits every tire and drive, so the log
    decides: with the data's quadratic model at the fit (``D(w*+d) = D* - 2 g^T d + d^T H d``,
    ``H``, ``g`` the normal equations of the final pass) the evidence of a prior ``Lambda``
    is, up to a constant, ``-(J + log det(H + Lambda) - log det(Lambda)) / 2`` with ``J`` the
    minimum of the posterior cost (the Laplace approximation). The best length is refitted
    with at most ``max_iter`` Gauss-Newton passes; the observer's adaptation settings take it.

    The neighbouring lengths of the grid whose evidence is within ``plausible_nats`` of the
    best (a Bayes factor below e^5, short of "very strong" on the Kass-Raftery scale) are
    answers the log cannot rule out (with ``choose=False`` the configured length is kept and
    its neighbours are judged against it; a neighbour the log prefers is always plausible):
    their weight differences are kept
    (``fit.prior_alternatives``) and :meth:`OfflineFit.variance` adds the largest squared
    change of a functional among them to its variance (a prior-sensitivity term).
    """
    from dataclasses import replace as _replace

    if getattr(fit, "data_grad", None) is None:
        return fit, {"chosen_deg": observer.adaptation.prior_length, "evidence": None}
    lo, hi = observer._weight_box()
    a0 = observer.adaptation
    w_star = fit.weights
    w0 = np.zeros_like(w_star)
    H = fit.hessian - fit.prior_precision
    H = 0.5 * (H + H.T)
    g = fit.data_grad
    evidence: dict = {}
    solutions: dict = {}
    best = None
    for length in lengths:
        observer.adaptation = _replace(a0, prior_length=float(length))
        P = observer.prior_covariance(offline=True)
        observer.adaptation = a0
        Lam = np.linalg.inv(P)
        Lam = 0.5 * (Lam + Lam.T)
        A = H + Lam
        try:
            d = _solve_step(A, g - Lam @ (w_star - w0), w_star, lo, hi)
            sa, lda = np.linalg.slogdet(A)
            sl, ldl = np.linalg.slogdet(Lam)
        except np.linalg.LinAlgError:
            continue
        if sa <= 0 or sl <= 0:
            continue
        w = w_star + d
        J = fit.data_cost - 2.0 * float(g @ d) + float(d @ H @ d) + float((w - w0) @ Lam @ (w - w0))
        ev = -0.5 * (J + lda - ldl)
        evidence[f"{length:g}"] = ev
        solutions[float(length)] = (ev, w)
        if best is None or ev > best[0]:
            best = (ev, float(length), w, Lam)
    info = {"method": "evidence (Laplace) of the smooth-curve prior's length scale", "evidence_by_length_deg": evidence,
            "chosen_deg": a0.prior_length}  # fmt: skip
    if not choose and float(a0.prior_length) in solutions:  # keep the configured length
        ev_c, w_c = solutions[float(a0.prior_length)]
        best = (ev_c, float(a0.prior_length), w_c, None)
    if best is not None:  # the plausible neighbouring lengths: how much the answer leans on the choice
        grid = sorted(solutions)
        i = grid.index(best[1])
        near = [grid[j] for j in (i - 1, i + 1) if 0 <= j < len(grid) and best[0] - solutions[grid[j]][0] <= plausible_nats]
        fit.prior_alternatives = [solutions[x][1] - best[2] for x in near]
        info["plausible_neighbours_deg"] = near
    if best is None or abs(best[1] - a0.prior_length) < 1e-12:
        return fit, info
    _, length, w, Lam = best
    info["chosen_deg"] = length
    observer.adaptation = _replace(a0, prior_length=length)
    t = np.asarray(sensors["t"], dtype=float)
    fit_from = float(t[0]) + observer.settle_s
    w, _, costs, it = _gauss_newton(observer, sensors, w, w0, Lam, lo, hi, fit_from, gate, max_iter, tol, min_decrease)
    new = _final_fit(observer, sensors, w, Lam, fit_from, gate, list(fit.cost) + costs, fit.iterations + it)
    new.force_error = fit.force_error
    new.force_error_calibration = fit.force_error_calibration
    for name in ALTERNATIVES:
        setattr(new, name, getattr(fit, name, []))
    return new, info
