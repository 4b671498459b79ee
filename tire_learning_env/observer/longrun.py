r"""Long-run variance of a fit's scores (Newey-West, Bartlett weights).

The innovations of a fixed-gain observer are not white, and with model mismatch they are
larger and slower than the model says: the offline fit's sandwich variance
(:meth:`.offline.OfflineFit.variance`) weighs its scores by their long-run covariance, computed
here for one series (:func:`newey_west_variance`) or for many directions of the same scores at
once (:func:`_newey_west_columns`, FFT autocovariances, a block of directions at a time).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from .passes import pass_threads

__all__ = ["newey_west_variance", "nw_columns_per_fft", "NW_KEPT_LAGS"]


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
    first = int(below[0]) if len(below) else n // 4  # none below up to n/16: the cap, as any later lag gives
    max_lag = int(min(max(4 * first, 4 * n ** (2.0 / 9.0)), n // 4))
    if max_lag + 1 > kept:  # a bandwidth beyond the kept lags: a second sweep with it
        return _newey_west_columns(columns, n, d, max_lag)
    lags = np.arange(1, max_lag + 1)
    w = 1.0 - lags / (max_lag + 1.0)
    return acov[0] + 2.0 * np.sum(w[:, None] * acov[1 : max_lag + 1], axis=0)
