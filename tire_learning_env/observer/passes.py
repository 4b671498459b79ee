"""Fixed-weight passes of the offline fit (:mod:`.offline`): one pass of the Kalman predictor over the
log with the weights held, accumulating the normal equations; a long log's pass runs as pieces on
threads (:func:`pass_pieces`); the innovations' whiteness test (:func:`innovation_whiteness`)."""

from __future__ import annotations

import copy
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numpy.typing import NDArray

from . import _kernel as K

__all__ = ["MIN_PIECE_S", "MAX_PIECES", "PIECE_OVERLAP_S", "pass_threads", "pass_pieces", "innovation_whiteness"]

#: A fixed-weight pass over a long log runs as pieces on threads (:func:`_pass`): pieces of at least this
#: length [s], at most :data:`MAX_PIECES`, each started :data:`PIECE_OVERLAP_S` early so that its predictor
#: has forgotten its cold start before its rows count. The pieces depend on the log alone (never on the
#: machine's cores), so every machine computes the same fit.
MIN_PIECE_S = 120.0
MAX_PIECES = 4
PIECE_OVERLAP_S = 30.0


def pass_threads() -> int:
    """Threads for the pieces of a pass: ``TIRE_LEARNING_THREADS`` if set, else the usable cores."""
    env = os.environ.get("TIRE_LEARNING_THREADS")
    if env:
        try:
            n = int(env)
        except ValueError:
            raise ValueError(f"TIRE_LEARNING_THREADS must be a positive integer, got {env!r}") from None
        if n < 1:
            raise ValueError(f"TIRE_LEARNING_THREADS must be a positive integer, got {env!r}")
        return n
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def pass_pieces(t: NDArray, settle_s: float) -> list[tuple[int, int, int]]:
    """``(start, first, end)`` row indices of the pieces of a fixed-weight pass over rows with times ``t``.

    Piece ``i`` runs rows ``start:end`` from a cold state and counts rows ``first:end``; the
    counted rows tile the log. The overlap ``first - start`` spans :data:`PIECE_OVERLAP_S` (at least
    15 settling times): the fixed-weight Kalman predictor forgets its start within a few seconds (on
    a 300 s, 100 Hz lane-change log a Gauss-Newton step from two pieces differs from the one-piece
    step by 0.09 posterior standard deviations with no overlap, 9e-4 with 2 s, 5e-8 with 5 s and
    3e-12 with 30 s: ``python benchmarks/bench_pass_pieces.py``).
    One piece (the exact single pass) when the log is shorter than two :data:`MIN_PIECE_S`.
    """
    n = len(t)
    if n < 2:
        return [(0, 0, n)]
    span = float(t[-1] - t[0])
    pieces = int(min(MAX_PIECES, span // MIN_PIECE_S))
    if pieces < 2:
        return [(0, 0, n)]
    overlap = max(PIECE_OVERLAP_S, 15.0 * settle_s)
    cuts = np.searchsorted(t, t[0] + span * np.arange(1, pieces) / pieces)
    firsts = np.r_[0, cuts].astype(int)
    ends = np.r_[cuts, n].astype(int)
    starts = [0] + [int(np.searchsorted(t, t[f] - overlap)) for f in firsts[1:]]
    return [(int(a), int(f), int(b)) for a, f, b in zip(starts, firsts, ends)]


def _run_fixed(observer, rows, w, acc, accumulate_from, gate, final):
    """The observer from ``w`` over ``rows`` with the weights held, accumulating into ``acc``
    (``final``: also the recorded trace with the scores and the state std)."""
    observer.reset(weights=w)
    return observer.run(rows, mode="fixed", accumulator=acc, accumulate_from=accumulate_from, gate=gate,
                        store_scores=final, compute_std=final, store_weights=False, kalman=True, record=final,
                        shift_frames=not final)  # fmt: skip


def _pass(observer, sensors, w, fit_from, gate, final=False, innovations=False):
    """One pass with the weights held and the Kalman predictor; returns the normal equations
    (with ``innovations``, also the fit's camera innovations by row, ``acc.innov``).

    Without ``final`` a long log's pass runs as pieces (:func:`pass_pieces`) on threads (the compiled
    loop releases the GIL), each on its own copy of the observer, and their normal equations add up.
    """
    nw = observer.n_weights
    t = np.asarray(sensors["t"], dtype=float)
    n = len(t) if innovations else 0
    acc = K.Accumulator(np.zeros((nw, nw)), np.zeros(nw), np.zeros(4), np.full((n, 2), np.nan))
    pieces = [(0, 0, len(t))] if final else pass_pieces(t, observer.settle_s)
    if len(pieces) == 1:
        return acc, _run_fixed(observer, sensors, w, acc, fit_from, gate, final)

    def piece(args):
        start, first, end = args
        part = K.Accumulator(np.zeros((nw, nw)), np.zeros(nw), np.zeros(4), acc.innov[start:end] if n else acc.innov)
        rows = {k: np.asarray(v)[start:end] for k, v in sensors.items()}
        counted_from = fit_from if first == 0 else max(fit_from, float(t[first]))
        # its own copy of the observer (reset there: its own state); the model and gains are shared, read only
        _run_fixed(copy.copy(observer), rows, w, part, counted_from, gate, False)
        return part

    with ThreadPoolExecutor(max_workers=min(pass_threads(), len(pieces))) as pool:
        parts = list(pool.map(piece, pieces))
    for part in parts:  # in piece order: the same sums on every machine
        acc.hess[:] += part.hess
        acc.grad[:] += part.grad
        acc.stats[:] += part.stats
    observer.reset(weights=w)
    return acc, None


def innovation_whiteness(innov: NDArray, lags: int = 5, level: float = 0.999) -> dict:
    """Ljung-Box test of each camera channel's innovations (rows without a frame are NaN).

    The innovations of a Kalman predictor whose model is right are white (Mehra's optimality
    test); a model that misses dynamics the data have leaves them correlated over a few frames.
    ``Q = n (n + 2) sum_l rho_l^2 / (n - l)`` over ``lags`` frame lags is chi-square with
    ``lags`` degrees of freedom under whiteness; a channel is white when ``Q`` is below its
    ``level`` quantile.

    Returns
    -------
    dict
        ``q`` per channel, ``bound``, ``white`` (every channel with enough frames).
    """
    from scipy.special import gammaincinv  # scipy.stats.chi2.ppf's own formula, without 0.44 s of scipy.stats import

    bound = float(2.0 * gammaincinv(lags / 2.0, level))  # the chi-square(lags) quantile at level
    q = []
    for c in range(innov.shape[1]):
        x = innov[:, c]
        x = x[np.isfinite(x)]
        n = len(x)
        if n < 10 * lags:
            q.append(float("nan"))
            continue
        x = x - x.mean()
        d = float(x @ x)
        if d <= 0:
            q.append(0.0)
            continue
        rho = np.array([float(x[k:] @ x[:-k]) / d for k in range(1, lags + 1)])
        q.append(float(n * (n + 2) * np.sum(rho**2 / (n - np.arange(1, lags + 1)))))
    white = all(not (v > bound) for v in q)
    return {"q": q, "bound": bound, "white": bool(white)}


def _nis_per_dof(acc) -> float:
    return float(acc.stats[0] / max(acc.stats[2], 1.0))
