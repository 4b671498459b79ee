"""Compiled recursive-least-squares weight update shared by the camera and IMU observers.

Both observers learn the weights from a two-channel innovation ``nu = z - z_hat`` with the
regressor ``Psi`` (2, nw) (``Psi = C Upsilon`` for the camera, ``C Upsilon + D_w`` for the
IMU, where lateral acceleration depends on the force directly).
"""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True)
def rls_gain(pw, psi, r0, r1, q, p_max, kg, pk):
    """RLS gain ``K = P Psi^T (Psi P Psi^T + diag(r0, r1))^-1`` into ``kg`` (nw, 2).

    Updates ``P <- P - K Psi P + q I`` in place and caps every diagonal entry at ``p_max``
    (the covariance stays bounded without excitation). ``pk`` (2, nw) is work space.
    """
    nw = pw.shape[0]
    for a in range(nw):
        s0 = 0.0
        s1 = 0.0
        for b in range(nw):
            s0 += pw[a, b] * psi[0, b]
            s1 += pw[a, b] * psi[1, b]
        pk[0, a] = s0  # (P Psi^T)^T
        pk[1, a] = s1
    s00 = r0
    s01 = 0.0
    s11 = r1
    for a in range(nw):
        s00 += psi[0, a] * pk[0, a]
        s01 += psi[0, a] * pk[1, a]
        s11 += psi[1, a] * pk[1, a]
    det = s00 * s11 - s01 * s01
    i00 = s11 / det
    i01 = -s01 / det
    i11 = s00 / det
    for a in range(nw):
        kg[a, 0] = pk[0, a] * i00 + pk[1, a] * i01
        kg[a, 1] = pk[0, a] * i01 + pk[1, a] * i11
    for a in range(nw):
        for b in range(nw):
            pw[a, b] -= kg[a, 0] * pk[0, b] + kg[a, 1] * pk[1, b]
    if q > 0.0:
        for a in range(nw):
            pw[a, a] += q
    for a in range(nw):
        if pw[a, a] > p_max:
            sc = math.sqrt(p_max / pw[a, a])
            for b in range(nw):
                pw[a, b] *= sc
                pw[b, a] *= sc


@njit(cache=True)
def projected_step(w, kg, nu0, nu1, wlo, whi, dw):
    """``w <- Proj_[wlo, whi](w + K nu)``; the applied change goes to ``dw``. Returns whether w moved."""
    moved = False
    for a in range(w.shape[0]):
        wn = w[a] + kg[a, 0] * nu0 + kg[a, 1] * nu1
        if wn > whi[a]:
            wn = whi[a]
        elif wn < wlo[a]:
            wn = wlo[a]
        dw[a] = wn - w[a]
        if dw[a] != 0.0:
            moved = True
        w[a] = wn
    return moved
