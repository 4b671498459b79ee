"""Reference paths as curvature profiles ``kappa(s)`` of the distance travelled ``s``.

A road here is the *reference path* the car should follow: a lane centre, or the path of a
lane change between lane centres. Each profile gives ``kappa(s)`` [1/m] and its slope
``dkappa/ds`` [1/m^2], vectorised over numpy arrays, from which

    psi_dot_des  = vx kappa                          (eq. 4)
    psi_ddot_des = vx^2 dkappa/ds + ax kappa

are computed consistently (:meth:`Road.desired_yaw`). Curvature changes are blended by
clothoids (curvature linear in ``s``) so ``psi_ddot_des`` stays finite.

Lane changes are paths whose lateral offset from the straight lane centre moves by one
lane width; their curvature is a full sine period (zero at both ends, continuous), so
the heading returns to the lane direction at the end.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .params import ParameterError, RoadParams

__all__ = [
    "Road",
    "StraightRoad",
    "PiecewiseCurvatureRoad",
    "LaneChangeRoad",
    "SineRoad",
    "ChirpRoad",
    "CallableRoad",
    "study1_road",
    "make_road",
    "BUILTIN_ROADS",
]


class Road(ABC):
    """A reference path given by its curvature as a function of distance."""

    lane_width: float = 3.7

    @abstractmethod
    def curvature(self, s: ArrayLike) -> NDArray:
        """Curvature ``kappa(s)`` [1/m]; positive turns left."""

    @abstractmethod
    def curvature_rate(self, s: ArrayLike) -> NDArray:
        """``dkappa/ds`` [1/m^2]."""

    def desired_yaw(self, s: ArrayLike, vx: ArrayLike, ax: ArrayLike = 0.0) -> tuple[NDArray, NDArray]:
        """``psi_dot_des = vx kappa`` [rad/s] and ``psi_ddot_des = vx^2 dkappa/ds + ax kappa`` [rad/s^2]."""
        kappa = self.curvature(s)
        vx = np.asarray(vx, dtype=float)
        return vx * kappa, vx**2 * self.curvature_rate(s) + np.asarray(ax) * kappa

    def lateral_target(self, s: ArrayLike) -> NDArray:
        """Lateral offset of the path from the starting lane centre [m] (lane-change roads)."""
        return np.zeros_like(np.asarray(s, dtype=float))

    def geometry(self, length: float, ds: float = 0.5) -> dict[str, NDArray]:
        """Global ``x, y, heading`` of the path sampled every ``ds`` metres (for plots)."""
        s = np.arange(0.0, length + ds, ds)
        kappa = self.curvature(s)
        heading = np.concatenate([[0.0], np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * ds)])
        x = np.concatenate([[0.0], np.cumsum(0.5 * (np.cos(heading[1:]) + np.cos(heading[:-1])) * ds)])
        y = np.concatenate([[0.0], np.cumsum(0.5 * (np.sin(heading[1:]) + np.sin(heading[:-1])) * ds)])
        return {"s": s, "x": x, "y": y, "heading": heading, "kappa": kappa}


@dataclass(frozen=True)
class StraightRoad(Road):
    """A straight lane (``kappa = 0``)."""

    lane_width: float = 3.7

    def curvature(self, s: ArrayLike) -> NDArray:
        return np.zeros_like(np.asarray(s, dtype=float))

    def curvature_rate(self, s: ArrayLike) -> NDArray:
        return np.zeros_like(np.asarray(s, dtype=float))


@dataclass(frozen=True)
class PiecewiseCurvatureRoad(Road):
    """Curvature linear between knots: lines, arcs and clothoids; constant beyond the ends.

    Parameters
    ----------
    s_knots : sequence of float
        Strictly increasing distances [m].
    kappa_knots : sequence of float
        Curvature at the knots [1/m].
    """

    s_knots: tuple[float, ...]
    kappa_knots: tuple[float, ...]
    lane_width: float = 3.7

    def __post_init__(self) -> None:
        s = np.asarray(self.s_knots, dtype=float)
        k = np.asarray(self.kappa_knots, dtype=float)
        if s.ndim != 1 or s.shape != k.shape or len(s) < 2:
            raise ParameterError("PiecewiseCurvatureRoad: s_knots and kappa_knots need equal length >= 2")
        if not np.all(np.diff(s) > 0):
            raise ParameterError("PiecewiseCurvatureRoad.s_knots must be strictly increasing")
        if not (np.all(np.isfinite(s)) and np.all(np.isfinite(k))):
            raise ParameterError("PiecewiseCurvatureRoad knots must be finite")
        object.__setattr__(self, "_s", s)
        object.__setattr__(self, "_k", k)
        object.__setattr__(self, "_slopes", np.diff(k) / np.diff(s))

    def curvature(self, s: ArrayLike) -> NDArray:
        return np.interp(np.asarray(s, dtype=float), self._s, self._k)

    def curvature_rate(self, s: ArrayLike) -> NDArray:
        s = np.asarray(s, dtype=float)
        idx = np.searchsorted(self._s, s, side="right") - 1
        inside = (idx >= 0) & (idx < len(self._slopes))
        return np.where(inside, self._slopes[np.clip(idx, 0, len(self._slopes) - 1)], 0.0)

    @classmethod
    def from_segments(
        cls, segments: Sequence[tuple[float, float]], transition_length: float = 30.0, lane_width: float = 3.7
    ) -> "PiecewiseCurvatureRoad":
        """Road from ``(length [m], radius [m])`` segments; radius ``inf`` is straight.

        Consecutive segments are joined by clothoids of ``transition_length`` centred on
        the joint. Positive radius turns left.
        """
        if not segments:
            raise ParameterError("from_segments needs at least one segment")
        s_knots = [0.0]
        kappa = [1.0 / segments[0][1] if math.isfinite(segments[0][1]) else 0.0]
        s = 0.0
        for (length, radius), nxt in zip(segments, list(segments[1:]) + [None]):
            if not length > 0:
                raise ParameterError(f"segment length must be > 0, got {length!r}")
            if radius == 0:
                raise ParameterError("segment radius must be non-zero (use inf for straight)")
            k_here = 1.0 / radius if math.isfinite(radius) else 0.0
            s += length
            if nxt is None:
                s_knots.append(s)
                kappa.append(k_here)
                break
            k_next = 1.0 / nxt[1] if math.isfinite(nxt[1]) else 0.0
            half = 0.5 * min(transition_length, length, nxt[0])
            s_knots += [s - half, s + half]
            kappa += [k_here, k_next]
        return cls(tuple(s_knots), tuple(kappa), lane_width=lane_width)


def study1_road(road: RoadParams | None = None) -> PiecewiseCurvatureRoad:
    """The paper's Study 1 road: straight 300 m, then R = 300 m for 750 m, then R = 250 m.

    At 30 m/s: 10 s straight, 25 s on R = 300 m, then R = 250 m to the end of the 60 s run
    (and beyond).
    """
    road = road or RoadParams()
    return PiecewiseCurvatureRoad.from_segments(
        [(300.0, math.inf), (750.0, 300.0), (2000.0, 250.0)],
        transition_length=road.transition_length,
        lane_width=road.lane_width,
    )


@dataclass(frozen=True)
class LaneChangeRoad(Road):
    """Straight road with lane changes between neighbouring lanes.

    Each change moves the path by ``direction * lane_width`` over ``change_length``
    metres with curvature ``kappa = A sin(2 pi u)``, ``u = (s - s_start)/change_length``,
    ``A = 2 pi lane_width / change_length^2`` (small-angle path geometry).

    Parameters
    ----------
    starts : tuple of float
        Distance at which each change starts [m] (increasing, non-overlapping).
    directions : tuple of int
        +1 (to the left) or -1 (to the right) per change.
    change_length : float
        Longitudinal length of one change [m].
    lane_width : float
        Lane width, i.e. the lateral displacement of one change [m].
    """

    starts: tuple[float, ...] = (150.0,)
    directions: tuple[int, ...] = (1,)
    change_length: float = 90.0
    lane_width: float = 3.7

    def __post_init__(self) -> None:
        if len(self.starts) != len(self.directions):
            raise ParameterError("LaneChangeRoad: starts and directions need equal length")
        if any(d not in (-1, 1) for d in self.directions):
            raise ParameterError("LaneChangeRoad.directions must be +1 or -1")
        if not self.change_length > 0:
            raise ParameterError("LaneChangeRoad.change_length must be > 0")
        st = np.asarray(self.starts, dtype=float)
        if len(st) > 1 and not np.all(np.diff(st) >= self.change_length):
            raise ParameterError("LaneChangeRoad: changes overlap (starts must be change_length apart)")

    @classmethod
    def repeated(
        cls, first: float = 150.0, spacing: float = 300.0, count: int = 6, change_length: float = 90.0, lane_width: float = 3.7
    ) -> "LaneChangeRoad":
        """``count`` alternating left/right changes every ``spacing`` metres."""
        starts = tuple(first + i * spacing for i in range(count))
        directions = tuple(1 if i % 2 == 0 else -1 for i in range(count))
        return cls(starts, directions, change_length, lane_width)

    def _phase(self, s: NDArray) -> tuple[NDArray, NDArray]:
        amp = np.zeros_like(s)
        u = np.zeros_like(s)
        for start, direction in zip(self.starts, self.directions):
            inside = (s >= start) & (s < start + self.change_length)
            u = np.where(inside, (s - start) / self.change_length, u)
            amp = np.where(inside, direction * 2.0 * math.pi * self.lane_width / self.change_length**2, amp)
        return amp, u

    def curvature(self, s: ArrayLike) -> NDArray:
        s = np.asarray(s, dtype=float)
        amp, u = self._phase(s)
        return amp * np.sin(2.0 * math.pi * u)

    def curvature_rate(self, s: ArrayLike) -> NDArray:
        s = np.asarray(s, dtype=float)
        amp, u = self._phase(s)
        return amp * (2.0 * math.pi / self.change_length) * np.cos(2.0 * math.pi * u)

    def lateral_target(self, s: ArrayLike) -> NDArray:
        s = np.asarray(s, dtype=float)
        y = np.zeros_like(s)
        for start, direction in zip(self.starts, self.directions):
            u = np.clip((s - start) / self.change_length, 0.0, 1.0)
            y = y + direction * self.lane_width * (u - np.sin(2.0 * math.pi * u) / (2.0 * math.pi))
        return y


@dataclass(frozen=True)
class SineRoad(Road):
    """Sinusoidal weaving ``kappa = amplitude sin(2 pi s / wavelength)`` after ``start``."""

    amplitude: float = 1.0 / 400.0  # [1/m]
    wavelength: float = 300.0  # [m]
    start: float = 60.0  # [m]
    lane_width: float = 3.7

    def __post_init__(self) -> None:
        if not self.wavelength > 0:
            raise ParameterError("SineRoad.wavelength must be > 0")

    def curvature(self, s: ArrayLike) -> NDArray:
        s = np.asarray(s, dtype=float)
        return np.where(s >= self.start, self.amplitude * np.sin(2 * math.pi * (s - self.start) / self.wavelength), 0.0)

    def curvature_rate(self, s: ArrayLike) -> NDArray:
        s = np.asarray(s, dtype=float)
        w = 2 * math.pi / self.wavelength
        return np.where(s >= self.start, self.amplitude * w * np.cos(w * (s - self.start)), 0.0)


@dataclass(frozen=True)
class ChirpRoad(Road):
    """Weaving whose spatial frequency rises linearly from ``1/wavelength_start`` to ``1/wavelength_end``.

    ``kappa = amplitude sin(phi(s))`` with ``phi' = 2 pi f(s)`` over ``length`` metres after ``start``.
    """

    amplitude: float = 1.0 / 400.0  # [1/m]
    wavelength_start: float = 600.0  # [m]
    wavelength_end: float = 120.0  # [m]
    length: float = 1800.0  # [m]
    start: float = 60.0  # [m]
    lane_width: float = 3.7

    def __post_init__(self) -> None:
        if not (self.wavelength_start > 0 and self.wavelength_end > 0 and self.length > 0):
            raise ParameterError("ChirpRoad wavelengths and length must be > 0")

    def _phi(self, x: NDArray) -> tuple[NDArray, NDArray]:
        f0, f1 = 1.0 / self.wavelength_start, 1.0 / self.wavelength_end
        x = np.clip(x, 0.0, self.length)
        rate = (f1 - f0) / self.length
        return 2 * math.pi * (f0 * x + 0.5 * rate * x**2), 2 * math.pi * (f0 + rate * x)

    def curvature(self, s: ArrayLike) -> NDArray:
        x = np.asarray(s, dtype=float) - self.start
        phi, _ = self._phi(x)
        return np.where((x >= 0) & (x <= self.length), self.amplitude * np.sin(phi), 0.0)

    def curvature_rate(self, s: ArrayLike) -> NDArray:
        x = np.asarray(s, dtype=float) - self.start
        phi, dphi = self._phi(x)
        return np.where((x >= 0) & (x <= self.length), self.amplitude * np.cos(phi) * dphi, 0.0)


class CallableRoad(Road):
    """A user-defined profile ``kappa = fn(s)`` (vectorised); the slope by central differences if not given."""

    def __init__(
        self,
        curvature_fn: Callable[[NDArray], NDArray],
        curvature_rate_fn: Callable[[NDArray], NDArray] | None = None,
        lane_width: float = 3.7,
        ds: float = 0.05,
    ) -> None:
        if not callable(curvature_fn):
            raise ParameterError("CallableRoad.curvature_fn must be callable")
        self._kappa = curvature_fn
        self._dkappa = curvature_rate_fn
        self.lane_width = lane_width
        self._ds = ds

    def curvature(self, s: ArrayLike) -> NDArray:
        return np.asarray(self._kappa(np.asarray(s, dtype=float)), dtype=float)

    def curvature_rate(self, s: ArrayLike) -> NDArray:
        s = np.asarray(s, dtype=float)
        if self._dkappa is not None:
            return np.asarray(self._dkappa(s), dtype=float)
        return (self.curvature(s + self._ds) - self.curvature(s - self._ds)) / (2 * self._ds)


def _lane_change(road: RoadParams) -> LaneChangeRoad:
    return LaneChangeRoad(starts=(150.0,), directions=(1,), lane_width=road.lane_width)


def _lane_changes(road: RoadParams) -> LaneChangeRoad:
    return LaneChangeRoad.repeated(lane_width=road.lane_width)


BUILTIN_ROADS: dict[str, Callable[[RoadParams], Road]] = {
    "study1": study1_road,
    "straight": lambda road: StraightRoad(lane_width=road.lane_width),
    "lane_change": _lane_change,
    "lane_changes": _lane_changes,
    "sine": lambda road: SineRoad(lane_width=road.lane_width),
    "chirp": lambda road: ChirpRoad(lane_width=road.lane_width),
}


def make_road(name: str | Road, road: RoadParams | None = None) -> Road:
    """A built-in road by name (see :data:`BUILTIN_ROADS`), or ``name`` itself if it is a :class:`Road`."""
    if isinstance(name, Road):
        return name
    if name not in BUILTIN_ROADS:
        raise ParameterError(f"unknown road {name!r}; built-in roads are {sorted(BUILTIN_ROADS)}")
    return BUILTIN_ROADS[name](road or RoadParams())
