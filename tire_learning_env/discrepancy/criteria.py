"""The statistics of the selection criterion (:mod:`.selection`).

- :func:`significance`: likelihood-ratio statistic, its chi-square p-value and the BIC change of
  adding an effect (optionally discounted by the residual's variance inflation);
- :func:`acceptance_threshold`: the smallest likelihood ratio that passes both;
- :func:`long_run_variance`: the variance inflation of a residual correlated in time (Newey-West);
- :func:`signature_correlation`: how alike two candidates' signatures in the residual are.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy import stats

__all__ = ["significance", "acceptance_threshold", "long_run_variance", "signature_correlation"]


def significance(
    chi2_before: float, chi2_after: float, k: int, n: int, inflation: float | None = None
) -> dict[str, float]:
    """Likelihood-ratio statistic, its chi-square p-value and the BIC change (negative = better).

    ``inflation`` (>= 1, :func:`long_run_variance`): the statistic is divided by it before
    the test and the BIC (a residual that is correlated in time carries fewer independent
    samples than it has; the raw statistic is kept as ``lr_raw``). ``None``: no correction
    (the keys are then exactly those of the uncorrected test).
    """
    lr = max(chi2_before - chi2_after, 0.0)
    out = {}
    if inflation is not None:
        out = {"lr_raw": float(lr), "inflation": float(inflation)}
        lr = lr / inflation
    return {
        "lr": float(lr),
        "p_value": float(stats.chi2.sf(lr, k)),
        "delta_bic": float(-lr + k * math.log(n)),
        "k": int(k),
        **out,
    }


def long_run_variance(data, resid: NDArray, span: float = 1.0) -> float:
    """Variance inflation of a weighted residual from its correlation in time, floored at 1.

    Per channel, within windows: the Bartlett-weighted long-run variance
    ``gamma_0 + 2 sum_{l=1}^{L} (1 - l / (L + 1)) gamma_l`` (``L`` = ``span`` seconds of
    lags, no mean removed: a residual offset is misfit too) of ``resid`` (which is
    ``(y - y_model) / sigma``); the channels' values averaged by their sample counts. For
    white residual at the assumed noise level it is 1; a residual correlated over a
    second, or noisier than assumed, makes it larger, and the likelihood-ratio statistic
    of an effect whose signature is slow (all of them: they act through the dynamics) has
    its variance inflated by about this factor (a Newey-West correction).
    """
    wid = data.window_of_measurement()
    total, count = 0.0, 0
    for ch in data.primary:
        idx = np.flatnonzero(data.meas_chan == ch)
        if len(idx) < 20:
            continue
        x = resid[idx]
        w = wid[idx]
        rate = 1.0 / float(np.median(np.diff(data.t[data.meas_row[idx]])))
        n_lag = max(1, int(round(span * rate)))
        lrv = float(x @ x) / len(x)
        for lag in range(1, n_lag + 1):
            same = w[lag:] == w[:-lag]
            gamma = float(np.sum(x[lag:][same] * x[:-lag][same])) / len(x)
            lrv += 2.0 * (1.0 - lag / (n_lag + 1.0)) * gamma
        total += lrv * len(idx)
        count += len(idx)
    return max(1.0, total / count) if count else 1.0


def signature_correlation(a: NDArray, b: NDArray) -> float:
    """Largest canonical correlation between the column spaces of two signature matrices (M, k)."""
    qa, ra = np.linalg.qr(a)
    qb, rb = np.linalg.qr(b)
    qa = qa[:, np.abs(np.diag(ra)) > 1e-12 * max(np.abs(np.diag(ra)).max(), 1e-300)]
    qb = qb[:, np.abs(np.diag(rb)) > 1e-12 * max(np.abs(np.diag(rb)).max(), 1e-300)]
    if qa.shape[1] == 0 or qb.shape[1] == 0:
        return 0.0
    return float(np.linalg.svd(qa.T @ qb, compute_uv=False)[0])


def acceptance_threshold(k: int, n: int, level: float) -> float:
    """Smallest likelihood-ratio statistic that passes both the test at ``level`` and the BIC."""
    return float(max(stats.chi2.isf(level, k), k * math.log(n)))
