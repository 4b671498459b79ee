"""The box-projected Newton step shared by the offline fit (:mod:`.offline`), the prior-length evidence
(:mod:`.prior_length`) and the block causal law (:mod:`.block_law`): the weights live in a box
(:meth:`.basis.SoftClipBasis.weight_lower` / ``weight_upper``) and a step never leaves it."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["_solve_step"]


def _solve_step(A: NDArray, rhs: NDArray, w: NDArray, lo: NDArray, hi: NDArray) -> NDArray:
    """Box-projected Newton step: solve ``A dw = rhs`` with variables at an active bound fixed."""
    free = np.ones(len(w), dtype=bool)
    dw = np.zeros_like(w)
    for _ in range(len(w)):
        dw[:] = 0.0
        idx = np.flatnonzero(free)
        dw[idx] = np.linalg.solve(A[np.ix_(idx, idx)], rhs[idx] - A[np.ix_(idx, ~free)] @ dw[~free])
        new = w + dw
        hit = free & (((new < lo) & (dw < 0)) | ((new > hi) & (dw > 0)))
        if not hit.any():
            break
        free &= ~hit
        dw[~free] = np.clip(w[~free] + dw[~free], lo[~free], hi[~free]) - w[~free]
    return np.clip(w + dw, lo, hi) - w
