r"""Long-run variance of a fit's scores (Newey-West, Bartlett weights).

The innovations of a fixed-gain observer are not white, and with model mismatch they are
larger and slower than the model says: the offline fit's sandwich variance
(:meth:`.offline.OfflineFit.variance`) weighs its scores by their long-run covariance, computed
here for one series (:func:`newey_west_variance`) or for many directions of the same scores at
once (:func:`_newey_west_columns`, FFT autocovariances, a block of directions at a time). For a grid
of directions (a curve's band) :class:`ScoreLongRun` gives the same variances from the scores'
long-run covariance matrix in the weight space, computed once per fit and bandwidth.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from .passes import pass_threads

__all__ = ["newey_west_variance", "nw_columns_per_fft", "NW_KEPT_LAGS", "ScoreLongRun", "bartlett_bandwidth"]


def newey_west_variance(u: NDArray, max_lag: int | None = None) -> NDArray:
    """Long-run variance of the sum of each column of ``u`` (n, d) (Newey-West, Bartlett).

    The bandwidth is the lag where the mean absolute autocorrelation of the columns first
    drops below ``2/sqrt(n)`` (their noise level), times 4, at least ``4 n^(2/9)`` and at
    most ``n/4``.

    Parameters
    ----------
    u : (n, d) array
        The series (e.g. the scores of a fit projected on ``d`` directions).
    max_lag : int, optional
        The Bartlett bandwidth; default chosen from ``u`` as above.

    Returns
    -------
    (d,) ndarray
        ``sum_l w_l sum_k u_k u_{k+l}`` over lags ``|l| <= max_lag`` (``u`` centred).
    """
    u = np.asarray(u, dtype=float)
    if u.shape[0] < 8:
        return np.sum(u**2, axis=0)
    return _newey_west_columns(lambda c0, c1: u[:, c0:c1].T, u.shape[0], u.shape[1], max_lag)


#: Lags of each column's autocovariance kept while the bandwidth is not yet known (:func:`_newey_west_columns`):
#: a bandwidth beyond them (rare: scores correlated over more than 1/4 of these lags) costs a second sweep.
NW_KEPT_LAGS = 16384

#: Elements of one block of FFTs (columns x transform length): a few tens of MB whatever the log length.
NW_FFT_BLOCK_ELEMENTS = 2**22


def _nw_fft_length(n: int, lags: int) -> int:
    """FFT length for the first ``lags`` autocovariances of ``n`` rows without wrap-around."""
    import scipy.fft as sfft

    return sfft.next_fast_len(n + lags - 1, real=True)


def nw_columns_per_fft(n: int) -> int:
    """Columns that :func:`newey_west_variance` transforms together on ``n`` rows (its memory block)."""
    return max(1, int(NW_FFT_BLOCK_ELEMENTS // _nw_fft_length(n, n // 4 + 1)))


def _newey_west_columns(columns, n: int, d: int, max_lag: int | None = None) -> NDArray:
    """:func:`newey_west_variance` of the ``d`` series that ``columns(c0, c1)`` returns as rows ((c1 - c0, n)
    arrays, made a block of series at a time: the caller need not hold all of ``u``).

    Each column's autocovariance ``sum_k u_k u_{k+l}`` comes from one FFT of length at least
    ``n + L`` (the ``L`` lags that can be used, at most ``n/4 + 1``: linear, not circular,
    correlation there), on :func:`.passes.pass_threads` threads (scipy's pocketfft: the same
    transform as numpy's). The bandwidth reads the mean absolute autocorrelation only up to the
    lag ``n/16``: from there on ``4 x lag`` reaches the cap ``n/4`` whatever the lag is. Against
    FFTs of twice the log's length over every lag (before 2026-11-29) the variances agree to
    rounding (at most 8e-16 relative; the ``estimate`` command's files on a 300 s, 1 kHz log identical),
    and the eleven variance calls of that command (stiffness, learned slip range, curve file, plot:
    1526 directions) take 12-16 s instead of 58-69 s (CPU 16-17 s instead of 51 s).
    """
    import scipy.fft as sfft

    keep_all = n // 4 + 1 if max_lag is None else min(max_lag + 1, n)  # the lags that can be used
    n_rho = -(-(n // 4) // 4) if max_lag is None else 0  # lags whose autocorrelation can decide the bandwidth
    kept = min(keep_all, NW_KEPT_LAGS)
    nfft = _nw_fft_length(n, keep_all)
    workers = pass_threads()
    step = max(1, int(NW_FFT_BLOCK_ELEMENTS // nfft))  # columns per FFT
    out = np.empty(d)
    acov = None if max_lag is not None else np.empty((kept, d))
    rho_sum = np.zeros(n_rho)
    w = None
    if max_lag is not None:
        lags = np.arange(1, max_lag + 1)
        w = 1.0 - lags / (max_lag + 1.0)
    for c in range(0, d, step):
        x = np.asarray(columns(c, min(c + step, d)), dtype=float)
        x = x - x.mean(axis=1, keepdims=True)
        F = sfft.rfft(x, nfft, axis=1, workers=workers)
        del x
        a = sfft.irfft(F * np.conj(F), nfft, axis=1, workers=workers)[:, :keep_all].T  # (lags, columns)
        del F
        if max_lag is None:
            rho_sum += np.sum(np.abs(a[:n_rho] / np.maximum(a[0], 1e-300)), axis=1)
            acov[:, c : c + step] = a[:kept]
        else:
            out[c : c + step] = a[0] + 2.0 * np.sum(w[:, None] * a[1 : max_lag + 1], axis=0)
    if max_lag is not None:
        return out
    rho = rho_sum / d
    below = np.flatnonzero(rho < 2.0 / math.sqrt(n))
    max_lag = bartlett_bandwidth(n, int(below[0]) if len(below) else None)
    if max_lag + 1 > kept:  # a bandwidth beyond the kept lags: a second sweep with it
        return _newey_west_columns(columns, n, d, max_lag)
    lags = np.arange(1, max_lag + 1)
    w = 1.0 - lags / (max_lag + 1.0)
    return acov[0] + 2.0 * np.sum(w[:, None] * acov[1 : max_lag + 1], axis=0)


def bartlett_bandwidth(n: int, first_lag: int | None) -> int:
    """The Bartlett bandwidth of :func:`newey_west_variance` on ``n`` rows: 4 times ``first_lag`` (the first
    lag whose mean absolute autocorrelation is below ``2/sqrt(n)``; ``None``: none up to ``n/16``, which gives
    the cap), at least ``4 n^(2/9)`` and at most ``n/4``."""
    first = n // 4 if first_lag is None else first_lag
    return int(min(max(4 * first, 4 * n ** (2.0 / 9.0)), n // 4))


#: Lags :class:`ScoreLongRun` computes directly (in doubling batches) while it looks for the bandwidth; a direction
#: set whose autocorrelation is still above its noise level there goes to the FFTs of :func:`_newey_west_columns`.
DIRECT_BANDWIDTH_LAGS = 32

#: Rows of the scores :class:`ScoreLongRun` converts to float64 at a time.
_ROW_BLOCK = 32768


class ScoreLongRun:
    r"""Newey-West long-run covariance of a fit's scores in the weight space, for many directions at once.

    The variance :func:`newey_west_variance` gives the projection ``u = S c`` of the scores ``S`` (n, nw) on a
    direction ``c`` is a quadratic form in ``c``: with the lag covariances ``Gamma_l = sum_k s_k s_{k+l}^T``
    of the centred scores and the Bartlett weights ``w_l = 1 - |l| / (L + 1)``,

    .. math:: \sum_{|l| \le L} w_l \sum_k u_k u_{k+l} = c^T \Omega_L c, \quad
              \Omega_L = \sum_{|l| \le L} w_l \Gamma_l = S^T (T_L S),

    ``T_L S`` being the scores filtered by the triangle ``w`` (two running sums, ``O(n nw)``). So a grid of
    hundreds of directions (a curve's band) costs one ``Omega_L`` per bandwidth instead of two FFTs of the log's
    length per direction. The bandwidth is chosen as there, from the same directions' mean absolute
    autocorrelation ``c^T Gamma_l c / c^T Gamma_0 c``, with the ``Gamma_l`` computed in batches of lags (kept for
    the next call) up to :data:`DIRECT_BANDWIDTH_LAGS`; beyond, or when the lag-1 autocorrelation, decaying
    geometrically, would cross its noise level beyond twice that (scores correlated over hundreds of rows, as a
    noise-free 1 kHz camera's), :meth:`variance` returns ``None`` and the caller uses the FFTs. The variances equal :func:`_newey_west_columns`' to rounding (the quadratic form's
    cancellation: 1e-8 relative on a 30 min log's curve grid, whose FFT variances differ by as much from a
    direct lag sum). Nothing of the size of the scores is kept between calls.

    Parameters
    ----------
    scores : (n, nw) array
        The fit's scores (any float type; used as float64, centred per column).
    """

    def __init__(self, scores: NDArray):
        self._scores = scores
        self._mean = None
        self._gamma: list[NDArray] = []  # Gamma_0, Gamma_1, ... (nw, nw)
        self._omega: dict[int, NDArray] = {}

    def _rows(self, r0: int, r1: int, cols: slice = slice(None)) -> NDArray:
        """Rows ``r0:r1`` (columns ``cols``) of the centred scores as float64 (the scores are never copied whole)."""
        if self._mean is None:
            total = np.zeros(self._scores.shape[1])
            for c in range(0, self._scores.shape[0], _ROW_BLOCK):
                total += np.sum(self._scores[c : c + _ROW_BLOCK], axis=0, dtype=float)
            self._mean = total / max(self._scores.shape[0], 1)
        return np.asarray(self._scores[r0:r1, cols], dtype=float) - self._mean[cols]

    def _lag_covariances(self, upto: int) -> None:
        """Make ``Gamma_0 .. Gamma_upto`` available (the missing lags in one sweep over the rows)."""
        n, nw = self._scores.shape
        first = len(self._gamma)
        if upto < first:
            return
        new = np.zeros((upto + 1 - first, nw, nw))
        for r0 in range(0, n, _ROW_BLOCK):
            r1 = min(r0 + _ROW_BLOCK, n)
            x = self._rows(r0, min(r1 + upto, n))
            head = x[: r1 - r0]
            for lag in range(first, upto + 1):
                m = min(r1 - r0, x.shape[0] - lag)  # the rows k of this block with k + lag inside the log
                if m > 0:
                    new[lag - first] += head[:m].T @ x[lag : lag + m]
        self._gamma.extend(new)

    def bandwidth(self, C: NDArray) -> int | None:
        """The Bartlett bandwidth of :func:`_newey_west_columns` for the directions ``C`` (nw, d); ``None`` when
        their autocorrelation stays above the noise level beyond :data:`DIRECT_BANDWIDTH_LAGS` lags."""
        n = self._scores.shape[0]
        n_rho = -(-(n // 4) // 4)  # the lags whose autocorrelation can decide the bandwidth
        level = 2.0 / math.sqrt(n)
        den = None
        last = min(n_rho, DIRECT_BANDWIDTH_LAGS + 1) - 1
        for lag in range(last + 1):
            if lag >= len(self._gamma):  # lags in doubling batches: at most twice the lags the crossing needs
                self._lag_covariances(min(max(2 * lag, 1), last))
            a = np.einsum("id,ij,jd->d", C, self._gamma[lag], C)
            if lag == 0:
                den = np.maximum(a, 1e-300)
            rho = np.mean(np.abs(a / den))
            if rho < level:
                return bartlett_bandwidth(n, lag)
            if lag == 1 and (rho >= 1.0 or math.log(level) / math.log(rho) > 2 * DIRECT_BANDWIDTH_LAGS):
                return None  # decaying as rho^lag, this would cross far beyond the direct lags (a noise-free camera)
        return bartlett_bandwidth(n, None) if n_rho <= DIRECT_BANDWIDTH_LAGS + 1 else None

    def omega(self, max_lag: int) -> NDArray:
        """``Omega_L`` (nw, nw) for the bandwidth ``L = max_lag`` (kept per bandwidth)."""
        if max_lag not in self._omega:
            n, nw = self._scores.shape
            L = min(int(max_lag), n - 1)
            om = np.zeros((nw, nw))
            step = 8  # columns filtered at a time: a few arrays of (n, 8), whatever nw is
            k = np.arange(-L, n)
            for c0 in range(0, nw, step):
                cols = slice(c0, min(c0 + step, nw))
                x = self._rows(0, n, cols)
                # box sums y_k = sum_{j=0..L} x_{k+j} for k = -L .. n-1 (x zero outside the log) ...
                cx = np.zeros((n + 1, x.shape[1]))
                np.cumsum(x, axis=0, out=cx[1:])
                del x
                y = cx[np.minimum(k + L + 1, n)] - cx[np.maximum(k, 0)]
                del cx
                # ... then z_k = sum_{j=0..L} y_{k-j}: the triangle (L + 1 - |l|) over lags -L .. L
                cy = np.zeros((n + L + 1, y.shape[1]))
                np.cumsum(y, axis=0, out=cy[1:])
                del y
                z = cy[L + 1 : n + L + 1] - cy[:n]
                del cy
                for r0 in range(0, n, _ROW_BLOCK):
                    om[:, cols] += self._rows(r0, r0 + _ROW_BLOCK).T @ z[r0 : r0 + _ROW_BLOCK]
            om /= L + 1.0
            self._omega[max_lag] = 0.5 * (om + om.T)
        return self._omega[max_lag]

    def variance(self, C: NDArray, max_lag: int | None = None) -> NDArray | None:
        """:func:`_newey_west_columns` of the scores projected on the columns of ``C`` (nw, d), or ``None``
        when the bandwidth is not found within :data:`DIRECT_BANDWIDTH_LAGS` lags (use the FFTs then)."""
        C = np.asarray(C, dtype=float)
        L = self.bandwidth(C) if max_lag is None else max_lag
        if L is None:
            return None
        return np.einsum("id,ij,jd->d", C, self.omega(L), C)
