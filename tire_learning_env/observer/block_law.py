r"""The ``"block"`` causal adaptation law of :class:`~.neuro_adaptive.NeuroAdaptiveObserver`.

:class:`~.settings.AdaptationParams` ``causal_update="block"``: the weights are held within a
block of ``block_s`` seconds while the Kalman predictor accumulates the block's
prediction-error normal equations; at each block end one Gauss-Newton step of the fit over all
blocks so far moves the weights (the offline fit's box-projected Newton step,
:func:`.box_step._solve_step`), the predictor's process noise is made consistent (NIS), and the
causal stiffness verdict's data for that instant are recorded (:meth:`BlockLaw.causal_stiffness`).
Only rows before a block's end reach its step: the law is causal.

The verdict's standard deviation is the larger of the model's (the inverse normal matrix ``A^-1``)
and the batch-means sandwich ``A^-1 (Lam + sum_b s_b s_b^T) A^-1`` over the closed blocks' score sums
``s_b`` (:meth:`BlockLaw._sandwich_variance`): the causal counterpart of the offline fit's Newey-West
sandwich (:mod:`.longrun`). Only the verdict reads it; the weights, their covariance in the predictor
and so every estimate of the pass are those of ``A^-1``.
"""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from typing import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _kernel as K
from .box_step import _solve_step  # the box-projected Newton step of the offline fit
from .readout import stiffness_gradient
from .rows import _KernelRows, sensor_rows
from .trace import EstimateTrace

__all__ = ["BlockLaw"]


class _BlockScores:
    """Each closed block's score sum ``grad_b`` (nw,), normal matrix ``H_b`` (nw, nw) and the weights
    ``w_b`` it was run with, in arrays grown by doubling (:meth:`BlockLaw._sandwich_parts`).

    Parameters
    ----------
    nw : int
        Number of weights.
    """

    def __init__(self, nw: int) -> None:
        self.n = 0
        self.grad = np.empty((8, nw))
        self.hess = np.empty((8, nw, nw))
        self.w = np.empty((8, nw))

    def append(self, grad: NDArray, hess: NDArray, w: NDArray) -> None:
        """Add one block's ``grad``, ``hess`` and weights ``w`` (copied)."""
        if self.n == len(self.grad):
            self.grad = np.concatenate([self.grad, np.empty_like(self.grad)])
            self.hess = np.concatenate([self.hess, np.empty_like(self.hess)])
            self.w = np.concatenate([self.w, np.empty_like(self.w)])
        self.grad[self.n], self.hess[self.n], self.w[self.n] = grad, hess, w
        self.n += 1

    def snapshot(self) -> tuple[NDArray, NDArray, NDArray, int]:
        """``(grad, hess, w, n)``: the arrays and the count of the blocks closed so far. The first ``n``
        entries are never written again (:meth:`append` writes entry ``n`` or grows into new arrays), so
        the snapshot stays valid while blocks are added (a verdict computed on a thread reads it)."""
        return self.grad, self.hess, self.w, self.n

    def projected(self, D: NDArray, w: NDArray) -> NDArray:
        """``u[i, b] = D[:, i] . (grad_b + H_b (w_b - w))`` (d, n): the blocks' score sums at the
        weights ``w``, projected on the columns of ``D`` (nw, d)."""
        return _projected(self.snapshot(), D, w)


def _projected(scores: tuple, D: NDArray, w: NDArray) -> NDArray:
    """:meth:`_BlockScores.projected` of a :meth:`_BlockScores.snapshot`."""
    grad, hess, wb, n = scores
    # H_b (w_b - w) as one batched product (a reshaped (n nw, nw) @ D is 50x slower: a skinny BLAS call)
    shift = np.matmul(hess[:n], (wb[:n] - w)[:, :, None])[:, :, 0]
    return ((grad[:n] + shift) @ D).T


def _sandwich_parts_of(G: NDArray, A: NDArray, Lam: NDArray, scores: tuple,
                       w: NDArray) -> tuple[NDArray, NDArray] | None:  # fmt: skip
    """:meth:`BlockLaw._sandwich_parts` from its inputs: the normal matrix ``A``, the prior precision ``Lam``,
    a :meth:`_BlockScores.snapshot` and the weights ``w``."""
    if scores[3] == 0:
        return None
    A = 0.5 * (A + A.T)
    try:
        D = np.linalg.solve(A, G.T)  # (nw, d): A^-1 g_i
    except np.linalg.LinAlgError:
        return None
    return np.einsum("ji,jk,ki->i", D, Lam, D), _projected(scores, D, w)


def _sandwich_variance_of(G: NDArray, A: NDArray, Lam: NDArray, scores: tuple, w: NDArray) -> NDArray | None:
    """:meth:`BlockLaw._sandwich_variance` from its inputs (:func:`_sandwich_parts_of`)."""
    parts = _sandwich_parts_of(G, A, Lam, scores, w)
    if parts is None:
        return None
    prior, u = parts
    return prior + np.sum(u**2, axis=1)


def _verdict(t_end: float, c0: NDArray, G: NDArray, w: NDArray, pw: NDArray, A: NDArray, Lam: NDArray,
             scores: tuple) -> tuple:  # fmt: skip
    """:meth:`BlockLaw._causal_stiffness` from a snapshot of its inputs (:meth:`BlockLaw._verdict_inputs`):
    a pure function, so that a long causal pass computes it on a thread (:meth:`BlockLaw._run_blocks`)."""
    k = c0 + G @ w
    var = np.einsum("ij,jk,ik->i", G, pw, G)
    sand = _sandwich_variance_of(G, A, Lam, scores, w)
    if sand is not None:
        var = np.maximum(var, sand)
    s = np.sqrt(np.maximum(var, 0.0))
    return float(t_end), (float(k[0]), float(k[1])), (float(s[0]), float(s[1]))


class BlockLaw:
    """The block law's bookkeeping, mixed into :class:`~.neuro_adaptive.NeuroAdaptiveObserver`
    (which owns the state, the settings and :meth:`run`)."""

    def _block_state(self) -> dict:
        if self._block is None:
            P0 = self.prior_covariance(offline=True)
            Lam = np.linalg.inv(P0)
            Lam = 0.5 * (Lam + Lam.T)
            w = self._state.w.copy()
            nw = self.n_weights
            self._block = {
                "A": Lam, "c": Lam @ self.initial_weights, "w_run": w,
                "acc": K.Accumulator(np.zeros((nw, nw)), np.zeros(nw), np.zeros(4), np.empty((0, 2))),
                "t_end": None, "healthy": True, "blocks": 0, "used": 0,
                "verdicts": [],  # per closed block: (t_end, stiffness (2), std (2)), the causal verdict's data
                "Lam": Lam,  # the prior's precision: its share of the sandwich (_causal_stiffness)
                "scores": _BlockScores(nw),  # each closed block's score sum and normal matrix (the batch means)
            }  # fmt: skip
            self._state.pw[:] = P0
        return self._block

    def _close_block(self) -> None:
        """End of a block: one Gauss-Newton step of the fit over all blocks so far."""
        b = self._block
        acc = b["acc"]
        b["blocks"] += 1
        if b["healthy"] and acc.stats[1] > 0:
            H = 0.5 * (acc.hess + acc.hess.T)
            b["A"] = b["A"] + H
            b["scores"].append(acc.grad, H, b["w_run"])
            b["c"] = b["c"] + H @ b["w_run"] + acc.grad
            w = self._state.w.copy()
            lo, hi = self._weight_box()
            A = 0.5 * (b["A"] + b["A"].T)
            try:
                dw = _solve_step(A, b["c"] - A @ w, w, lo, hi)
                cov = np.linalg.inv(A)
            except np.linalg.LinAlgError:
                dw, cov = np.zeros_like(w), None
            if cov is not None and np.all(np.isfinite(dw)):
                self._state.w[:] = w + dw
                self._state.x[:] += self._state.ups @ dw  # the state follows its weights (sensitivity)
                self._state.pw[:] = 0.5 * (cov + cov.T)
                b["used"] += 1
        if b["healthy"] and acc.stats[2] >= 20:  # the predictor's process noise, made consistent block by block
            nis = float(acc.stats[0] / acc.stats[2])
            load = 0.5 * self.vehicle.m * 9.81
            lo_fe, hi_fe = 1e-4 * load, 3e-2 * load  # the offline fit's continuation range
            if nis > 1.3:
                self._adapt_force_error(min(self.force_error * 2.0, hi_fe))
            elif nis < 1.0:
                self._adapt_force_error(max(self.force_error / 1.5, lo_fe))
        inputs = self._verdict_inputs(b["t_end"])  # the verdict: on the pass' thread if it has one (_run_blocks)
        pool = b.get("verdict_pool")
        b["verdicts"].append(pool.submit(_verdict, *inputs) if pool is not None else _verdict(*inputs))
        b["w_run"] = self._state.w.copy()
        b["acc"] = K.Accumulator(np.zeros_like(acc.hess), np.zeros_like(acc.grad), np.zeros(4), np.empty((0, 2)))
        b["healthy"] = True
        b["t_end"] += self.adaptation.block_s

    def _causal_stiffness(self, t_end: float) -> tuple:
        """``(t_end, (Cf, Cr), (std_f, std_r))`` at a block's end: the per-tire stiffness of the curve
        the block law holds from then on (slope at zero, :func:`.readout.stiffness_gradient`: the
        whole-log read-out needs the slip of the whole log) and its standard deviation over all blocks
        so far (the data of rows before ``t_end`` only): the larger of the model's (the weight
        covariance ``A^-1``) and the batch-means sandwich's (:meth:`_sandwich_variance`)."""
        return _verdict(*self._verdict_inputs(t_end))

    def _verdict_inputs(self, t_end: float) -> tuple:
        """What :meth:`_causal_stiffness` reads, as of now (:func:`_verdict`'s arguments): the weights and
        their covariance copied (the next block writes them in place); the normal matrix, the prior
        precision and the scores' snapshot by reference (replaced, never written, by later blocks)."""
        b = self._block
        if "g_stiffness" not in b:
            b["g_stiffness"] = np.vstack([stiffness_gradient(self, i) for i in (0, 1)])
        return (float(t_end), np.array([self.vehicle.Cf, self.vehicle.Cr]), b["g_stiffness"], self._state.w.copy(),
                self._state.pw.copy(), b["A"], b["Lam"], b["scores"].snapshot())  # fmt: skip

    def _sandwich_parts(self, G: NDArray) -> tuple[NDArray, NDArray] | None:
        """The two shares of the batch-means sandwich along the rows of ``G`` (d, nw): the prior's,
        ``g A^-1 Lam A^-1 g`` (d,), and the projected score sums ``u[i, b] = g_i A^-1 s_b`` (d, nb) of
        the closed blocks, ``s_b = grad_b + H_b (w_b - w)`` the block's score sum linearised to the
        current weights ``w`` (``w_b`` the weights the block was run with). ``None`` before a block
        entered the fit or when ``A`` is singular."""
        b = self._block
        return _sandwich_parts_of(G, b["A"], b["Lam"], b["scores"].snapshot(), self._state.w)

    def _sandwich_variance(self, G: NDArray) -> NDArray | None:
        """The batch-means sandwich variance ``g A^-1 (Lam + sum_b s_b s_b^T) A^-1 g`` of the stiffness
        directions ``G`` (d, nw) (:meth:`_sandwich_parts`).

        The model's covariance ``A^-1`` (the inverse normal matrix) takes each row's innovation as
        white with the model's variance; a fixed-gain predictor's innovations are autocorrelated and,
        with model mismatch, larger than modelled, so ``A^-1`` is over-confident. A block's score sum
        is a batch sum over ``block_s`` seconds, longer than the innovations' correlation, so the
        outer products of the closed blocks' sums estimate the long-run covariance of the data's
        score (batch means; the offline fit's Newey-West sandwich, :mod:`.longrun`, for a causal
        law). Only closed blocks enter: the variance at a block's end uses rows before it only.
        """
        b = self._block
        return _sandwich_variance_of(G, b["A"], b["Lam"], b["scores"].snapshot(), self._state.w)

    def causal_stiffness(self) -> dict:
        """The block law's causal stiffness verdict data, one entry per closed block
        (:meth:`_causal_stiffness`): ``t`` (nb,) block ends [s], ``value`` and ``std`` (nb, 2) per
        tire [N/rad] (``std`` the larger of the model's and the batch-means sandwich's). Empty arrays
        before the first block closes or under the ``"rls"`` law."""
        v = (self._block or {}).get("verdicts", [])
        return {"t": np.array([x[0] for x in v], dtype=float),
                "value": np.array([x[1] for x in v], dtype=float).reshape(-1, 2),
                "std": np.array([x[2] for x in v], dtype=float).reshape(-1, 2)}  # fmt: skip

    def _run_blocks(self, sensors: Mapping[str, ArrayLike], predict_last: bool, compute_std: bool,
                    store_weights: bool) -> EstimateTrace:  # fmt: skip
        """:meth:`run` with the ``"block"`` law: the weights held within a block, the Kalman
        predictor accumulating the block's prediction-error normal equations, one
        Gauss-Newton step over all blocks at each block end (:class:`AdaptationParams`)."""
        rows = sensor_rows(sensors, self.model)
        t = rows["t"]
        n = len(t)
        if n and self._t0 is None:
            self._t0 = float(t[0])
        b = self._block_state()
        fit_from = (self._t0 or 0.0) + self.settle_s
        if b["t_end"] is None:
            b["t_end"] = fit_from + self.adaptation.block_s
        pieces: list[EstimateTrace] = []
        held: list[NDArray] = []  # the weights each piece held (a piece's rows all carry them)
        # a long call's verdicts on a thread: the batch-means sandwich grows with the blocks closed (0.2 s of a
        # 30 min log's causal pass, which runs on one core); beside the compiled loop, which releases the GIL,
        # the other core computes them (the same functions of the same inputs, bit for bit). Short calls (an
        # env's steps) compute them in line: a thread per call would cost more than it saves
        long_call = n > 0 and float(t[-1]) - b["t_end"] >= 4.0 * self.adaptation.block_s
        pool = ThreadPoolExecutor(max_workers=1) if long_call else None
        if pool is not None:
            b["verdict_pool"] = pool
        try:
            k = 0
            while k < n:
                while t[k] >= b["t_end"]:
                    self._close_block()
                j = max(int(np.searchsorted(t, b["t_end"], side="left")), k + 1)
                last = j >= n
                piece = _KernelRows({c: v[k:j] for c, v in rows.items()})  # validated once, above
                held.append(self._state.w.copy())
                tr = self.run(piece, predict_last=predict_last if last else False, mode="fixed", accumulator=b["acc"],
                              accumulate_from=fit_from, gate=25.0, compute_std=compute_std, store_weights=False,
                              kalman=True)  # fmt: skip
                h = tr.health
                if np.any((h == K.HEALTH_NO_DATA) | (h == K.HEALTH_INCONSISTENT) | (h == K.HEALTH_DIVERGED)):
                    b["healthy"] = False  # adaptation frozen while the health flag is tripped
                pieces.append(tr)
                if not last and float(t[j] - t[j - 1]) <= self.segment_gap_s:  # to the next row, as run() would
                    # have predicted inside one call (across a pause nothing: run() restarts the state there)
                    dt_j = float(t[j] - t[j - 1])
                    d0, d1 = float(rows["delta"][j - 1]), float(rows["delta"][j])
                    ramp = (d1 - d0) / dt_j if (self.steering_hold == "ramp" and dt_j > 0 and np.isfinite(d1)) else 0.0
                    self.predict(dt_j, d0, float(rows["vx"][j - 1]), float(rows["kappa"][j - 1]), float(rows["ax"][j - 1]),
                                 float(self._state.hs[K.HS_KAPPA_RATE]), ramp)  # fmt: skip
                    self.t = float(t[j])
                k = j
        finally:
            if pool is not None:
                del b["verdict_pool"]
                pool.shutdown(wait=True)
                b["verdicts"] = [v.result() if isinstance(v, Future) else v for v in b["verdicts"]]
        if not pieces:
            return self.run(sensors, predict_last, mode="fixed", compute_std=compute_std, store_weights=store_weights)
        # the per-row weights from the weights each piece held, written once (the pieces do not store them:
        # on a 30 min, 100 Hz log that was 55 MB per copy, and concatenating held two)
        lengths = [len(p.t) for p in pieces]
        weights = np.repeat(np.vstack(held), lengths, axis=0) if store_weights else np.empty((0, self.n_weights))
        if len(pieces) == 1:
            pieces[0].weights = weights
            pieces[0].meta["causal_stiffness"] = self.causal_stiffness()
            return pieces[0]
        first = pieces[0]
        arrays = {f: np.concatenate([getattr(p, f) for p in pieces]) for f in
                  ("t", "state", "slip", "force", "force_nonlinear", "std", "health", "innovation", "nis",
                   "vx", "kappa")}  # fmt: skip
        del pieces
        meta = dict(first.meta, causal_stiffness=self.causal_stiffness())  # the blocks' verdict data (causal)
        return EstimateTrace(**arrays, weights=weights, state_names=first.state_names, meta=meta)
