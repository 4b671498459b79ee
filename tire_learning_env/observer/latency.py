"""The camera latency from the log: the one-step prediction-error cost profiled over candidate
latencies (step 4 of :func:`.estimator.estimate`; re-exported by :mod:`.estimator`)."""

from __future__ import annotations

import copy
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numpy.typing import NDArray

from .config import ObserverConfig
from .neuro_adaptive import NeuroAdaptiveObserver
from .offline import calibrate_force_error, pass_threads, pem_cost


#: The latencies [s] profiled first (those up to ``max_latency``), and those profiled when the best is the first
#: grid's largest (up to ``max_latency``, which is profiled too).
LATENCY_GRID = (0.0, 0.01, 0.02, 0.035, 0.05, 0.07, 0.1, 0.13)
LATENCY_GRID_ABOVE = (0.16, 0.2)


def _profile_window(t: NDArray, delta: NDArray, max_s: float = 120.0) -> slice:
    """The ``max_s`` window with the most steering activity (the whole log if shorter)."""
    if t[-1] - t[0] <= 1.25 * max_s:
        return slice(0, len(t))
    dt = float(np.median(np.diff(t)))
    n = max(int(max_s / dt), 10)
    d = np.nan_to_num(np.diff(delta, prepend=delta[0])) ** 2
    c = np.cumsum(d)
    act = c[n:] - c[:-n]
    s = int(np.argmax(act)) if len(act) else 0
    return slice(s, s + n)


def _estimate_latency(obs: NeuroAdaptiveObserver, rows: dict, config: ObserverConfig, weights: NDArray | None = None,
                      around: float | None = None) -> tuple[float, dict]:  # fmt: skip
    """Profile the one-step prediction-error cost over candidate latencies (:mod:`.estimator`'s docstring).

    First from the nominal curve (``weights=None``: the process noise is calibrated for it),
    then again over the whole grid (and the first estimate) with the refined weights and
    their process noise: a wrong curve biases the first profile (a stiffness error and a
    delay both shift the phase of the response), the refined curve much less (measured in
    the generalisation benchmark: a 91-95 ms latency first found as 30 ms).
    """
    win = _profile_window(rows["t"], rows["delta"])
    sub = {k: v[win] for k, v in rows.items()}
    if weights is None:
        w0 = np.zeros(obs.n_weights)
        load = 0.5 * obs.vehicle.m * 9.81
        calibrate_force_error(obs, sub, w0, float(sub["t"][0]) + obs.settle_s, 25.0, (1e-4 * load, 3e-2 * load))
    else:
        w0 = np.asarray(weights, dtype=float)
    cands = [c for c in LATENCY_GRID if c <= config.max_latency + 1e-12]
    if around is not None:  # the whole grid again (a biased first profile can be far off) plus the first estimate
        cands = sorted(set(cands) | {round(float(around), 4)})
    costs = {}
    updates = [0]

    def profile(d):  # on a copy of the observer (its own state): the grid's candidates run on threads
        ob = copy.copy(obs)
        ob.latency = d
        ob.reset(weights=w0)
        return pem_cost(ob, sub, w0)

    def keep(d, J, n):
        costs[d] = J / max(n, 1)
        updates[0] = max(updates[0], int(n))

    def cost(d):
        d = round(float(d), 4)
        if d not in costs:
            keep(d, *profile(d))
        return costs[d]

    def profile_all(candidates):  # the candidates not yet profiled, on threads; kept in sorted order
        todo = sorted({round(float(c), 4) for c in candidates} - set(costs))
        if todo:
            with ThreadPoolExecutor(max_workers=min(pass_threads(), len(todo))) as pool:
                for d, (J, n) in zip(todo, pool.map(profile, todo)):
                    keep(d, J, n)

    profile_all(cands)
    ds = sorted(costs)
    j = int(np.argmin([costs[d] for d in ds]))
    # the best at the grid's top: the camera may be later still (the grid goes on to max_latency only then, so that
    # logs whose latency lies inside it pay nothing). An independent generator's cameras 120-150 ms late (plus up to
    # a 10 ms row of delivery) were all found at the old grid's top, 130 ms
    above = [c for c in LATENCY_GRID_ABOVE if ds[-1] < c < config.max_latency - 1e-12]
    if j == len(ds) - 1 and ds[-1] < config.max_latency - 1e-12:
        profile_all(above + [float(config.max_latency)])
        ds = sorted(costs)
        j = int(np.argmin([costs[d] for d in ds]))
    best = ds[j]
    if 0 < j < len(ds) - 1:  # parabola through the minimum and its neighbours
        x0, x1, x2 = ds[j - 1], ds[j], ds[j + 1]
        y0, y1, y2 = costs[x0], costs[x1], costs[x2]
        den = (x0 - x1) * (x0 - x2) * (x1 - x2)
        a = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / den
        b = (x2 * x2 * (y0 - y1) + x1 * x1 * (y2 - y0) + x0 * x0 * (y1 - y2)) / den
        if a > 0:
            xv = float(np.clip(-b / (2 * a), x0, x2))
            if cost(xv) < costs[best]:
                best = round(xv, 4)
    elif j == 0 and len(ds) > 1:
        near = (ds[1] / 4, ds[1] / 2)
        # both are profiled whatever the first gives (each is compared with the best so far), so on threads as
        # the grid (in series they took 0.13 s of a 30 min log's estimate with the other core idle); the same
        # costs, compared in the same order
        profile_all(near)
        for xv in near:
            if cost(xv) < costs[best]:
                best = round(xv, 4)
    obs.latency = best
    obs.reset()
    sigma = latency_sigma(costs, updates[0], best, float(config.max_latency))
    return best, {
        "source": "estimated from the log (prediction-error profile)",
        "latency_s": best,
        "latency_std_s": sigma,
        "profile_s_to_cost_per_update": {f"{k:.4f}": v for k, v in sorted(costs.items())},
        "window_s": [float(sub["t"][0]), float(sub["t"][-1])],
        "updates": updates[0],
    }


def latency_sigma(costs: dict, updates: int, best: float, max_latency: float) -> float:
    """The latency's standard deviation [s] from its profile: ``1 / sqrt(a)`` of the parabola ``J = a (L - L0)^2 +
    c`` least-squares fitted to the profiled points within chi-square 25 of the best (``J`` the cost in chi-square
    units, ``costs`` per update times ``updates``; the three nearest the best when fewer lie there), so that the
    cost rises by 1 at one standard deviation. At most half ``max_latency`` (a flat or concave profile: the log
    does not show its latency)."""
    ds = np.array(sorted(costs))
    J = np.array([costs[d] for d in ds]) * max(int(updates), 1)
    Jmin = float(np.min(J))
    use = J - Jmin <= 25.0
    if use.sum() < 3:
        use = np.zeros(len(ds), dtype=bool)
        use[np.argsort(np.abs(ds - best))[:3]] = True
    cap = 0.5 * max_latency
    if use.sum() < 3:
        return cap
    a = np.polyfit(ds[use], J[use], 2)[0]
    return float(min(1.0 / np.sqrt(a), cap)) if a > 0 else cap
