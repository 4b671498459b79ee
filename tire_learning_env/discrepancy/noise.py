"""The noise actually present: measurement noise plus the steering the log does not show.

A log gives the steering only at its rows. Between two rows the model has to assume
something (:func:`.data.steering_slope`); when the rows are sparse (a 10 Hz log of a car
whose steering moves at 100 Hz, a log with irregular or dropped rows) the true steering
differs from any interpolation by a random amount in every interval. That error acts on
the model like process noise: it enters through the dynamics, so the residual it leaves is
correlated in time and across channels, and a whiteness or likelihood-ratio test that
assumes white measurement noise calls it a missing effect (a false alarm).

This module models it as an **errors-in-variables** term estimated from the log itself:

- the steering error held over a block of rows ``b`` is ``e_b ~ N(0, lambda sigma_u^2 / n_b)``
  (``n_b`` rows in the block, independent between blocks), where ``sigma_u`` is the
  roughness of the logged steering at its own row rate (third differences,
  :func:`.data.noise_std`), so ``lambda = 1`` means "the steering moves between rows as much
  as it moves from row to row";
- its effect on the weighted predictions of a window is ``G_w e`` with ``G_w`` the
  sensitivity of the window's predictions to each block's steering
  (:func:`._model.steering_sensitivity`, the fitted window state held);
- the residual covariance of window ``w`` in weighted units is ``C_w = I + lambda A_w A_w^T``
  with ``A_w = G_w diag(sigma_u / sqrt(n_b))``;
- ``lambda`` in ``[0, 1]`` is the restricted-likelihood (REML) estimate on the nominal
  residual (window states profiled out): it cannot exceed what the steering log's roughness
  supports, and it is 0 when the rows resolve the steering (then nothing changes).

With ``lambda > 0`` every residual is whitened per window, ``C_w^{-1/2} r``, and the window
states get the matching generalised-least-squares correction, so ``chi2``, the likelihood-ratio
tests and the whiteness test all use the noise actually present.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ._model import BLK_FIRST, BLK_STOP, steering_sensitivity
from .data import noise_std

__all__ = ["InputNoise", "estimate_input_noise"]

#: candidate values of lambda (REML grid search)
LAMBDA_GRID = np.concatenate([[0.0], np.logspace(-3, 0, 13)])
#: a block of rows whose steering error is held spans at least this long [s]
BLOCK_SPAN = 0.02
#: finite-difference step of the steering [rad]
FD_STEER = 1e-5
#: windows used to estimate lambda (evenly spread; all windows are whitened afterwards)
ESTIMATION_WINDOWS = 24


@dataclass
class InputNoise:
    """The steering-between-rows noise model of one log (see module docstring).

    Attributes
    ----------
    scale : float
        ``lambda`` [-], estimated (0 = the rows resolve the steering).
    sigma_u : float
        Roughness of the logged steering at its row rate [rad].
    block_rows : int
        Rows per block of held steering error.
    basis : list of ndarray
        Per window, the left singular vectors ``U`` (nm, r) of ``A_w`` (empty if ``scale`` is 0).
    gain : list of ndarray
        Per window, ``1 - 1 / sqrt(1 + lambda s^2)`` for each kept singular value ``s``.
    objective : dict
        REML objective per grid value of ``lambda`` (for the report).
    """

    scale: float
    sigma_u: float
    block_rows: int
    basis: list
    gain: list
    objective: dict

    @property
    def active(self) -> bool:
        return self.scale > 0.0

    def whiten(self, data, resid: NDArray, jac: NDArray, x0: NDArray) -> tuple[NDArray, NDArray, NDArray]:
        """``C_w^{-1/2}`` applied to the residual and the state sensitivities of every window, and the
        generalised-least-squares correction of the window states (one exact step of the linearised fit)."""
        if not self.active:
            return resid, jac, x0
        r = np.array(resid, dtype=float)
        J = np.array(jac, dtype=float)
        x = np.array(x0, dtype=float)
        for w in range(data.n_windows):
            a, b = data.meas_ptr[w], data.meas_ptr[w + 1]
            U, c = self.basis[w], self.gain[w]
            if U.shape[1] == 0:
                continue
            rw = r[a:b]
            Jw = J[a:b]
            rw = rw - U @ (c * (U.T @ rw))
            Jw = Jw - U @ (c[:, None] * (U.T @ Jw))
            dx, *_ = np.linalg.lstsq(Jw, rw, rcond=None)
            r[a:b] = rw - Jw @ dx
            J[a:b] = Jw
            x[w] += dx
        return r, J, x

    def to_dict(self) -> dict:
        return {
            "lambda": self.scale,
            "steering_roughness_rad": self.sigma_u,
            "block_rows": self.block_rows,
            "reml_objective": self.objective,
            "description": "steering error between logged rows, e_b ~ N(0, lambda sigma_u^2 / n_b) per block of "
            "rows, propagated through the model; lambda estimated by restricted likelihood on the nominal residual "
            "(0: the rows resolve the steering)",
        }


def _blocks(data, windows: NDArray, n_b: int) -> tuple[NDArray, NDArray]:
    """Blocks of ``n_b`` rows of each window: ``(ptr, rows)``, the blocks of window ``k`` are
    ``rows[ptr[k] : ptr[k + 1]]``, each ``(first row, stop row)`` (the stop row excluded; columns
    ``BLK_FIRST``, ``BLK_STOP``)."""
    ptr = [0]
    rows = []
    for w in windows:
        j0, j1 = int(data.win_sim[w]), int(data.win_end[w])
        for a in range(j0, j1, n_b):
            rows.append((a, min(a + n_b, j1)))
        ptr.append(len(rows))
    return np.array(ptr, dtype=np.int64), np.array(rows, dtype=np.int64).reshape(-1, 2)


def _svd_windows(model, evaluation, windows: NDArray, n_b: int, sigma_u: float, keep_tol: float):
    """Per window of ``windows``: (U, s) of ``A_w`` with singular values above ``keep_tol``."""
    d = model.data
    sub_ptr = np.zeros(len(windows) + 1, dtype=np.int64)
    idx = []
    for k, w in enumerate(windows):
        a, b = d.meas_ptr[w], d.meas_ptr[w + 1]
        idx.append(np.arange(a, b))
        sub_ptr[k + 1] = sub_ptr[k] + (b - a)
    idx = np.concatenate(idx) if idx else np.zeros(0, dtype=np.int64)
    blk_ptr, blk_rows = _blocks(d, windows, n_b)
    n_blk = int(np.max(np.diff(blk_ptr))) if len(windows) else 0
    out = np.zeros((len(idx), max(n_blk, 1)))
    x0 = np.ascontiguousarray(evaluation.x0[windows], dtype=float)
    steering_sensitivity(
        evaluation.theta, x0, d.win_sim[windows], d.win_end[windows], sub_ptr, d.meas_row[idx], d.meas_chan[idx],
        d.meas_w[idx], blk_ptr, blk_rows, d.t, d.delta, d.dslope, d.vx, d.pdd, model.veh, model.tf, model.tr,
        model.tabf, model.tabr, float(model.config.step), FD_STEER, out,
    )  # fmt: skip
    res = []
    for k in range(len(windows)):
        a, b = sub_ptr[k], sub_ptr[k + 1]
        nb = blk_ptr[k + 1] - blk_ptr[k]
        blocks = blk_rows[blk_ptr[k] : blk_ptr[k + 1]]  # each block's rows: first .. stop - 1
        n_rows = (blocks[:, BLK_STOP] - blocks[:, BLK_FIRST]).astype(float)
        A = out[a:b, :nb] * (sigma_u / np.sqrt(n_rows))[None, :]
        U, s, _ = np.linalg.svd(A, full_matrices=False)
        keep = s > keep_tol
        res.append((U[:, keep], s[keep]))
    return res


def _reml(data, evaluation, windows, svds, lam: float) -> float:
    """Restricted -2 log-likelihood (up to a constant) of the residual at ``lam``."""
    total = 0.0
    for w, (U, s) in zip(windows, svds):
        a, b = data.meas_ptr[w], data.meas_ptr[w + 1]
        r, J = evaluation.resid[a:b], evaluation.jac[a:b]
        c = 1.0 - 1.0 / np.sqrt(1.0 + lam * s * s)
        rw = r - U @ (c * (U.T @ r))
        Jw = J - U @ (c[:, None] * (U.T @ J))
        q, rr = np.linalg.qr(Jw)
        keep = np.abs(np.diag(rr)) > 1e-10 * max(np.abs(np.diag(rr)).max(), 1e-300)
        q = q[:, keep]
        rp = rw - q @ (q.T @ rw)
        total += float(rp @ rp) + float(np.sum(np.log1p(lam * s * s))) + 2.0 * float(
            np.sum(np.log(np.abs(np.diag(rr)[keep])))
        )
    return total


def estimate_input_noise(model, evaluation) -> InputNoise:
    """Estimate ``lambda`` on the nominal ``evaluation`` (converged, not whitened) and build the whitening.

    Only camera logs (error-coordinate model) are handled; for an IMU-only log, or a log
    whose steering is perfectly smooth, the model is inactive (``scale = 0``).
    """
    d = model.data
    empty = InputNoise(0.0, 0.0, 1, [], [], {})
    if d.kind != "camera":
        return empty
    sigma_u = noise_std(d.delta)
    if not (math.isfinite(sigma_u) and sigma_u > 0):
        return empty
    dt_med = float(np.median(np.diff(d.t)))
    n_b = max(1, int(round(BLOCK_SPAN / dt_med)))
    W = d.n_windows
    sub = np.unique(np.linspace(0, W - 1, min(W, ESTIMATION_WINDOWS)).round().astype(np.int64))
    svds = _svd_windows(model, evaluation, sub, n_b, sigma_u, 1e-6)
    objective = {float(lam): _reml(d, evaluation, sub, svds, float(lam)) for lam in LAMBDA_GRID}
    lam = min(objective, key=objective.get)
    grid = sorted(objective)
    i = grid.index(lam)
    if 1 < i < len(grid) - 1:
        # refine: the vertex of a parabola in log(lambda) through the best grid point and its neighbours
        x = np.log(grid[i - 1 : i + 2])
        y = np.array([objective[g] for g in grid[i - 1 : i + 2]])
        a, b, _ = np.polyfit(x, y, 2)
        if a > 0:
            cand = float(np.exp(np.clip(-b / (2 * a), x[0], x[2])))
            objective[cand] = _reml(d, evaluation, sub, svds, cand)
            if objective[cand] < objective[lam]:
                lam = cand
    if lam <= 0.0:
        return InputNoise(0.0, sigma_u, n_b, [], [], objective)
    # whitening of every window; singular directions whose variance is below 1e-3 of the noise are dropped
    keep_tol = math.sqrt(1e-3 / lam)
    basis, gain = [], []
    chunk = 64
    for start in range(0, W, chunk):
        wins = np.arange(start, min(W, start + chunk), dtype=np.int64)
        for U, s in _svd_windows(model, evaluation, wins, n_b, sigma_u, keep_tol):
            basis.append(np.ascontiguousarray(U))
            gain.append(1.0 - 1.0 / np.sqrt(1.0 + lam * s * s))
    return InputNoise(float(lam), float(sigma_u), n_b, basis, gain, objective)
