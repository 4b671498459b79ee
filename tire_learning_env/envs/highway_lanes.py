"""Lane geometry of a highway-env road network as the ego's reference path.

:func:`lane_curvature` (curvature of a highway-env lane), :class:`LaneReference` (successors,
hand-over points and the piecewise-linear curvature profile the physics loop reads) and the
two kinds of target-lane switch (:data:`SWITCH_JOIN`, :data:`SWITCH_LANE_CHANGE`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from highway_env.road.lane import AbstractLane, CircularLane, StraightLane
from highway_env.road.road import RoadNetwork

from .._kernels import knot_lookup

__all__ = ["LaneReference", "lane_curvature", "wrap_angle", "SWITCH_JOIN", "SWITCH_LANE_CHANGE"]

#: Kinds of target-lane switch: the hand-over to the next road segment, and a lane change.
SWITCH_JOIN, SWITCH_LANE_CHANGE = 0, 1


def wrap_angle(angle):
    """``angle`` wrapped to ``[-pi, pi)`` [rad]."""
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


def lane_curvature(lane: AbstractLane, s: NDArray) -> NDArray:
    """Curvature ``kappa(s)`` [1/m] of a highway-env lane's centre line, positive turning toward +lateral.

    Straight lanes are exactly 0 and circular lanes exactly ``direction / radius``; any other
    lane gets the central difference of ``heading_at`` over +/- 5 cm (the heading change along
    the lane).
    """
    s = np.asarray(s, dtype=float)
    if type(lane) is StraightLane:
        return np.zeros_like(s)
    if type(lane) is CircularLane:
        return np.full_like(s, lane.direction / lane.radius)
    h = 0.05
    try:
        up = np.asarray(lane.heading_at(s + h), dtype=float)
        down = np.asarray(lane.heading_at(s - h), dtype=float)
        if up.shape != s.shape:
            raise ValueError
    except (ValueError, TypeError):
        up = np.array([lane.heading_at(x + h) for x in s.ravel()]).reshape(s.shape)
        down = np.array([lane.heading_at(x - h) for x in s.ravel()]).reshape(s.shape)
    return wrap_angle(up - down) / (2.0 * h)


@dataclass(frozen=True)
class _Handover:
    """Where a lane hands the ego over to the next segment, and the join's mismatch there."""

    next_index: tuple
    s_switch: float  # [m] on the current lane
    s_next: float  # [m] the same point on the next lane
    lateral: float  # [m] the current lane's centre at the switch, in the next lane's frame
    heading: float  # [rad] next lane heading minus current lane heading there


def _is_constant_curvature(lane: AbstractLane) -> bool:
    return type(lane) in (StraightLane, CircularLane)


class LaneReference:
    """Lane geometry of a highway-env road network as the ego's reference path.

    For each lane it finds the successor (highway-env's ``next_lane``) and the hand-over
    point: the place near the lane end where the two centre lines agree best (highway-env
    joins some segments with small overlaps, kinks or lateral offsets; switching where the
    headings agree leaves at most the lateral offset of the join, up to 0.22 m on its
    racetrack).

    The reference curvature around the car (:meth:`profile`) is piecewise linear: each
    lane's own curvature (:func:`lane_curvature`), its predecessor's before the entry and
    its successor's after the hand-over, joined by linear ramps of width ``ramp`` centred on
    the hand-over points. A ramp has the same integral (heading change) as the curvature
    step of the join, so the reference heading is exact on both sides of it, and
    ``psi_ddot_des`` stays finite.

    Parameters
    ----------
    network : RoadNetwork
        highway-env road network (its lanes are not modified).
    ramp : float
        Width of the curvature ramp at a join [m].
    """

    _SAMPLE = 0.25  # [m] knot spacing on lanes of varying curvature

    def __init__(self, network: RoadNetwork, ramp: float = 0.1) -> None:
        self.network = network
        self.ramp = float(ramp)
        self._handover: dict[tuple, _Handover | None] = {}
        entering: dict[tuple, list[tuple]] = {}
        for index in network.lanes_dict():
            h = self._find_handover(index)
            self._handover[index] = h
            if h is not None:
                entering.setdefault(h.next_index, []).append(index)
        # the predecessor, when a lane is entered from exactly one other lane
        self._predecessor = {k: v[0] for k, v in entering.items() if len(v) == 1}

    def _find_handover(self, index: tuple) -> _Handover | None:
        lane = self.network.get_lane(index)
        end = lane.position(lane.length, 0.0)
        nxt = tuple(self.network.next_lane(index, position=end))
        if nxt == tuple(index) or nxt[:2] == tuple(index[:2]):
            return None
        nlane = self.network.get_lane(nxt)

        def mismatch(s: float) -> tuple[float, float, float]:
            sn, lat = nlane.local_coordinates(lane.position(s, 0.0))
            return sn, lat, float(wrap_angle(nlane.heading_at(sn) - lane.heading_at(s)))

        def cost(s: float) -> float:
            _, lat, dh = mismatch(s)
            return abs(lat) + 5.0 * abs(dh) + 1e-3 * abs(s - lane.length)  # tiny preference for the end

        lo = max(0.5 * lane.length, lane.length - 15.0)
        grid = np.arange(lo, lane.length + 3.0, 0.05)
        s0 = grid[int(np.argmin([cost(s) for s in grid]))]
        fine = np.arange(s0 - 0.05, s0 + 0.05, 0.002)
        s_best = float(fine[int(np.argmin([cost(s) for s in fine]))])
        sn, lat, dh = mismatch(s_best)
        return _Handover(nxt, s_best, float(sn), float(lat), dh)

    def handover(self, index: tuple) -> _Handover | None:
        """Successor and hand-over point of lane ``index`` (``None`` if the lane has no successor)."""
        return self._handover[tuple(index)]

    def s_stop(self, index: tuple) -> float:
        """Path coordinate [m] at which the ego is handed over to the next lane, or inf.

        It is the middle of the ramp: the next lane's profile has the same ramp around its
        entry, so curvature and ``psi_dot_des`` are continuous through the hand-over.
        """
        h = self._handover[tuple(index)]
        return math.inf if h is None else h.s_switch

    def _segments(self, index: tuple) -> list[tuple[float, float, AbstractLane, float]]:
        """``(s_from, s_to, lane, offset)``: on ``[s_from, s_to]`` the curvature is ``lane``'s at ``s + offset``."""
        index = tuple(index)
        own = self.network.get_lane(index)
        s_entry, s_exit = -math.inf, math.inf
        segs = []
        pred = self._predecessor.get(index)
        if pred is not None:
            hp = self._handover[pred]
            s_entry = hp.s_next
            segs.append((-math.inf, s_entry, self.network.get_lane(pred), hp.s_switch - hp.s_next))
        h = self._handover[index]
        if h is not None:
            s_exit = h.s_switch
        segs.append((s_entry, s_exit, own, 0.0))
        if h is not None:
            segs.append((s_exit, math.inf, self.network.get_lane(h.next_index), h.s_next - h.s_switch))
        return segs

    def profile(self, index: tuple, s_lo: float, s_hi: float) -> tuple[NDArray, NDArray, NDArray]:
        """Knots ``(ks, kv)`` of the curvature covering ``[s_lo, s_hi]`` and its running integral at the knots."""
        w2 = 0.5 * self.ramp
        lo, hi = s_lo - 1.0, s_hi + 1.0
        ks: list[NDArray] = []
        kv: list[NDArray] = []
        for a, b, lane, off in self._segments(index):
            a_eff = a + w2 if math.isfinite(a) else -math.inf
            b_eff = b - w2 if math.isfinite(b) else math.inf
            a_c, b_c = max(a_eff, lo - self.ramp), min(b_eff, hi + self.ramp)
            if a_c > b_c:
                continue
            if _is_constant_curvature(lane) or b_c - a_c < self._SAMPLE:
                pts = np.array([a_c, b_c]) if b_c - a_c > 1e-9 else np.array([a_c])
            else:
                pts = np.append(np.arange(a_c, b_c, self._SAMPLE), b_c)
                if pts[-1] - pts[-2] < 1e-9:
                    pts = pts[:-1]
            ks.append(pts)
            kv.append(lane_curvature(lane, pts + off))
        s = np.concatenate(ks)
        k = np.concatenate(kv)
        if len(s) == 1:
            s, k = np.array([s[0], s[0] + 1.0]), np.array([k[0], k[0]])
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (k[1:] + k[:-1]) * np.diff(s))])
        return np.ascontiguousarray(s), np.ascontiguousarray(k), cum

    def max_curvature_ahead(self, index: tuple, s: float, distance: float) -> float:
        """Largest ``|kappa|`` [1/m] of the lane centres from ``s`` to ``distance`` metres ahead (following hand-overs)."""
        kmax, cur, s_cur, left = 0.0, tuple(index), float(s), float(distance)
        for _ in range(50):
            lane = self.network.get_lane(cur)
            h = self._handover[cur]
            end = min(h.s_switch if h is not None else math.inf, s_cur + left)
            if end > s_cur:
                pts = np.array([s_cur, end]) if _is_constant_curvature(lane) else np.linspace(s_cur, end, 2 + int((end - s_cur) / self._SAMPLE))
                kmax = max(kmax, float(np.max(np.abs(lane_curvature(lane, pts)))))
                left -= end - s_cur
            if left <= 0.0 or h is None:
                break
            cur, s_cur = h.next_index, h.s_next
        return kmax

    def kappa(self, index: tuple, s: float) -> float:
        """Curvature [1/m] at ``s`` exactly as the physics kernel interpolates it."""
        ks, kv, _ = self.profile(index, s, s)
        return float(knot_lookup(s, ks, kv)[0])
