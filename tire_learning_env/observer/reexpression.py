r"""Steps of the lane camera's ``e1`` that no motion makes: re-expressions in another lane line.

A lane camera reports the lateral offset ``e1`` from the centre of the lane it tracks. When the
car changes lanes, the camera (and the planner feeding the log) switches to the new lane, and
``e1`` jumps by a lane width between two frames; a camera that hands over to another lane line
(a junction, a merge, repainted markings; in simulation, highway-env's racetrack joins, offset by
up to 0.22 m) makes smaller steps. The vehicle did not move: only the reference did. In the error
model (SPEC §1) ``e1`` enters only through its derivative, so a step of the reference is exactly
a shift of the state's ``e1``. Fed to the estimator as it is, a lane width is a 4 m innovation:
it dominates the prediction-error fit, trips the health flag and biases the latency profile.

:func:`lane_reexpressions` finds such steps from the log alone and removes them (the ``e1``
column made continuous; :func:`shift_back` puts the estimates back on the log's reference):

1. Between consecutive camera frames ``a, b`` the motion predicts
   ``e1_b - e1_a = integral(v_y + v_x e2) dt``; the residual
   ``r = e1_b - e1_a - (t_b - t_a) v_x (e2_a + e2_b) / 2`` is the lateral-velocity part plus
   noise, and ``d = r - trend`` removes the slowly varying lateral velocity (the median rate of
   ``r`` over the ``half`` frames on either side, the pair itself excluded).
2. ``d`` is scaled by its robust spread (1.4826 x the median absolute deviation over the log, at
   least the observer's noise floor), grown in proportion to the frame gap when frames were lost.
3. A candidate is a pair beyond :data:`CANDIDATE_SIGMAS` (5) spreads that stands alone (no other
   pair within ``half`` frames beyond it: a single bad frame makes a spike and its opposite, a
   vehicle losing control a run of them) and at which ``e2`` does not step too (a lane change
   keeps the heading to parallel lanes; a step of ``e2`` as well is not a shift of ``e1`` and is
   left to the health test).
4. A step is a candidate whose fitted step exceeds :data:`STEP_SIGMAS` (7) standard errors and
   :data:`STEP_FLOOR_M`: a line plus a step fitted to ``e1`` less the integrated ``v_x e2`` over
   :data:`STEP_WINDOW` frames on either side. ``e1`` of that frame and every later row is lowered
   by the fitted step, and the estimator adds the step's square to the variance of ``e1`` before
   that frame (:func:`release_variance`): the fitted size is only as good as the frames' noise,
   and the offset it leaves is learnt from the frames after it instead of being taken for motion.

On the generalisation benchmark's camera families (no re-expressions: 29 valid logs of 10-100 Hz,
0.5-2 cm noise, latency, dropouts) no candidate passed 3.7 spreads nor a windowed test 3.1: none is
touched, and their answers are unchanged bit for bit (``--quick``). Measured on highway-env logs
(20 Hz camera, 1 cm / 0.3 deg gaussian noise, 50 ms latency; vehicle file +10 / -8 %): a 44 s
highway drive with five 4 m lane changes, +1.8 / +1.2 % with bands of +/-28 / +/-38 %
(``not_identifiable``, health ``inconsistent`` on 31 % of the rows) before, -0.0 / +0.2 %
identified with bands of +/-2.2 / +/-2.9 % after; 60 s of the racetrack (five 0.09-0.22 m join
steps), rear +8.5 % with a band missing the truth (``not_identifiable``) before, -1.8 / -2.5 %
identified, bands covering, after.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .calibration import NOISE_FLOOR

__all__ = ["lane_reexpressions", "shift_back", "row_offsets", "release_variance", "CANDIDATE_SIGMAS", "STEP_SIGMAS", "STEP_FLOOR_M"]

#: a candidate pair: its frame-to-frame residual beyond this many robust spreads (valid benchmark logs: <= 3.7)
CANDIDATE_SIGMAS = 5.0
#: a step: the windowed step fit beyond this many standard errors (valid benchmark logs' candidates: <= 3.1)
STEP_SIGMAS = 7.0
#: rejected candidates listed in the record (all are counted)
MAX_LISTED = 20
#: frames on either side of the windowed step fit
STEP_WINDOW = 8
#: smallest step treated [m] (the observer's e1 noise floor is 0.1 mm; noise-free simulated cameras)
STEP_FLOOR_M = 1e-3
#: frames on either side for the lateral-velocity trend and the isolation test
HALF_WINDOW = 5


def _median_rate_trend(q: NDArray, dt: NDArray, half: int) -> NDArray:
    """Per pair ``i``: the median of ``q`` over the ``half`` pairs on either side (``i`` excluded), times ``dt[i]``.

    Pairs with ``half`` neighbours on both sides are done at once (one median along the rows of a sliding
    window, the same partition and mean of the middle pair as one at a time); the ``2 half`` pairs at
    the ends, whose windows are cut short, one at a time (a 30 min, 100 Hz log: 0.6 s -> about 10 ms).
    """
    n = len(q)
    trend = np.empty(n)
    if n > 2 * half:
        win = np.lib.stride_tricks.sliding_window_view(q, 2 * half + 1)  # row j is centred on pair j + half
        neighbours = np.concatenate([win[:, :half], win[:, half + 1 :]], axis=1)
        trend[half : n - half] = np.median(neighbours, axis=1) * dt[half : n - half]
        ends = [*range(half), *range(n - half, n)]
    else:
        ends = range(n)
    for i in ends:
        lo, hi = max(0, i - half), min(n, i + half + 1)
        nb = np.concatenate([q[lo:i], q[i + 1 : hi]])
        trend[i] = (np.median(nb) if len(nb) else 0.0) * dt[i]
    return trend


def _scaled_residual(d: NDArray, dt: NDArray, least: float) -> tuple[NDArray, float]:
    """``d`` in robust spreads (at least ``least``; grown with the frame gap beyond the median gap) and the spread."""
    spread = max(float(1.4826 * np.median(np.abs(d - np.median(d)))), least)
    gap = np.maximum(1.0, dt / np.median(dt))
    return np.abs(d) / np.maximum(spread * gap, 1e-300), spread


def _windowed_step(tf: NDArray, y: NDArray, i: int, window: int) -> tuple[float, float]:
    """Least-squares step between frames ``i`` and ``i + 1`` of ``y`` (a line plus a step over ``window``
    frames on either side): the step and the factor ``sqrt([(A^T A)^-1]_step)`` of its standard error."""
    lo, hi = max(0, i + 1 - window), min(len(y), i + 1 + window)
    tau = tf[lo:hi] - tf[i + 1]
    A = np.column_stack([np.ones_like(tau), tau, (np.arange(lo, hi) >= i + 1).astype(float)])
    coef, *_ = np.linalg.lstsq(A, y[lo:hi], rcond=None)
    return float(coef[2]), float(np.sqrt(np.linalg.inv(A.T @ A)[2, 2]))


def lane_reexpressions(
    t: ArrayLike,
    e1: ArrayLike,
    e2: ArrayLike,
    vx: ArrayLike,
    sigmas: float = STEP_SIGMAS,
    floor: float = STEP_FLOOR_M,
    half: int = HALF_WINDOW,
) -> tuple[NDArray, dict]:
    """Detect the steps of ``e1`` no motion explains and remove them (module docstring).

    Parameters
    ----------
    t : array_like
        Row times [s], increasing.
    e1, e2 : array_like
        Camera lateral offset [m] and heading error [rad] per row; NaN between frames.
    vx : array_like
        Speed [m/s] per row.
    sigmas : float
        Threshold of the windowed step test, in standard errors.
    floor : float
        Smallest step treated [m].
    half : int
        Frames on either side for the trend and the isolation test (the step fit uses
        :data:`STEP_WINDOW`).

    Returns
    -------
    e1_continuous : ndarray
        ``e1`` with the steps removed (the input array itself when none was found).
    info : dict
        ``detected`` (count), ``steps`` (per step: ``row``, ``t_s``, ``jump_m``, ``spreads``: the
        pair's residual in spreads, ``t_stat``: the windowed test), ``rejected`` (the first
        :data:`MAX_LISTED` candidates that failed a test, with the ``reason``; ``rejected_count``
        all of them), ``spread_m``, ``rule`` and ``note``.
    """
    t = np.asarray(t, dtype=float)
    e1 = np.asarray(e1, dtype=float)
    e2 = np.asarray(e2, dtype=float)
    vx = np.asarray(vx, dtype=float)
    info: dict = {"detected": 0, "steps": [], "rejected": [],
                  "rule": (f"a pair of consecutive frames whose e1 residual (the change minus vx * mean e2 * dt, minus the "
                           f"local lateral-velocity trend) exceeds {CANDIDATE_SIGMAS:g} robust spreads, alone within {half} "
                           f"frames, e2 not stepping, and whose step (a line plus a step fitted to e1 minus the integrated "
                           f"vx * e2 over {STEP_WINDOW} frames on either side) exceeds {sigmas:g} standard errors and "
                           f"{floor:g} m: a re-expression in another lane line (a lane change); e1 of that frame and "
                           "every later row lowered by the fitted step")}  # fmt: skip
    f = np.flatnonzero(np.isfinite(e1) & np.isfinite(e2) & np.isfinite(vx))
    if len(f) < 2 * max(half, STEP_WINDOW) + 3:
        info.update(spread_m=None, note="too few camera frames to look for steps of e1")
        return e1, info
    tf = t[f]
    dt = np.diff(tf)
    pred = dt * 0.5 * (vx[f][1:] + vx[f][:-1]) * 0.5 * (e2[f][1:] + e2[f][:-1])  # integral of vx e2
    r = np.diff(e1[f]) - pred
    d = r - _median_rate_trend(r / dt, dt, half)
    z, spread = _scaled_residual(d, dt, np.sqrt(2.0) * NOISE_FLOOR[0])  # a noise-free camera: the observer's floor
    d2 = np.diff(e2[f])
    z2, _ = _scaled_residual(d2 - _median_rate_trend(d2 / dt, dt, half), dt, np.sqrt(2.0) * NOISE_FLOOR[1])
    y = e1[f] - np.r_[0.0, np.cumsum(pred)]  # e1 less the motion the heading explains: a line plus steps
    info["spread_m"] = spread
    out = e1
    for i in np.flatnonzero(z > CANDIDATE_SIGMAS):
        row = int(f[i + 1])
        lo, hi = max(0, i - half), min(len(z), i + half + 1)
        others = np.concatenate([z[lo:i], z[i + 1 : hi]])
        cand = {"row": row, "t_s": float(t[row]), "residual_m": float(d[i]), "spreads": float(z[i])}
        if np.any(others > CANDIDATE_SIGMAS):
            info["rejected"].append(dict(cand, reason="not alone: another large residual within the window "
                                         "(a bad frame, or the vehicle losing control)"))  # fmt: skip
            continue
        if z2[i] > sigmas:
            info["rejected"].append(dict(cand, reason="e2 steps at the same frame: not a shift of e1 alone"))
            continue
        jump, factor = _windowed_step(tf, y, i, STEP_WINDOW)
        t_stat = abs(jump) / max(spread / np.sqrt(2.0) * factor, 1e-300)  # frame noise = spread / sqrt(2)
        if t_stat <= sigmas or abs(jump) <= floor:
            info["rejected"].append(dict(cand, reason=f"step {jump:+.4f} m is {t_stat:.1f} standard errors "
                                         f"(threshold {sigmas:g}, floor {floor:g} m)"))  # fmt: skip
            continue
        if out is e1:
            out = e1.copy()
        out[row:] -= jump
        y[i + 1 :] -= jump
        info["steps"].append({"row": row, "t_s": float(t[row]), "jump_m": jump, "spreads": float(z[i]), "t_stat": t_stat})
    info["detected"] = len(info["steps"])
    info["rejected_count"] = len(info["rejected"])
    info["rejected"] = info["rejected"][:MAX_LISTED]
    listed = ", ".join("%+.3f m at %.2f s" % (s["jump_m"], s["t_s"]) for s in info["steps"][:6])
    info["note"] = ("no step of e1 that motion does not explain" if not info["steps"] else
                    f"{info['detected']} step(s) of e1 no motion explains (lane changes or lane-line hand-overs: "
                    f"{listed}{' ...' if info['detected'] > 6 else ''}) removed before the estimate and the e1 state "
                    "released at each (a shift, not motion); the reported e1 estimates are on the log's lane reference")  # fmt: skip
    return out, info


def row_offsets(n: int, info: dict) -> NDArray:
    """Per row, the sum of the steps removed at or before it [m] (``e1_log = e1_continuous + offset``)."""
    off = np.zeros(n)
    for s in info.get("steps", []):
        off[s["row"] :] += s["jump_m"]
    return off


def release_variance(n: int, info: dict) -> NDArray:
    """Per row, the variance [m^2] the estimator adds to ``e1`` before the frame of a removed step:
    the step's size squared, as good as a restart of ``e1`` alone (zero elsewhere).

    The removed step is known only to the frames' noise (1-3 cm on the benchmark's 4 m lane changes
    at 1 cm camera noise: the lateral velocity the manoeuvre starts at the same frame biases a local
    fit); a residual offset left in ``e1`` would be explained by the fit as lateral motion, i.e. as
    tire force (on a 44 s highway drive with five lane changes: -2.0 / -4.8 % with the steps removed
    exactly as fitted, the bands missing the truth; -0.7 / -0.8 % with the exact steps). Released,
    the offset is learnt from the frames after the step, and ``e1`` enters no other state's dynamics.
    """
    out = np.zeros(n)
    for s in info.get("steps", []):
        out[s["row"]] += s["jump_m"] ** 2
    return out


def shift_back(trace, info: dict, e1_index: int) -> None:
    """Put a trace's ``e1`` estimates back on the log's lane reference (in place; no-op without steps).

    Parameters
    ----------
    trace : EstimateTrace or None
        An estimate of the continuous log.
    info : dict
        :func:`lane_reexpressions`' record.
    e1_index : int
        Column of ``e1`` in ``trace.state``.
    """
    if trace is None or not info.get("steps") or trace.state.shape[1] <= e1_index:
        return
    trace.state[:, e1_index] += row_offsets(len(trace.t), info)
