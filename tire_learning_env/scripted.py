"""Scripted excitation manoeuvres (baselines for learned excitation policies) and an episode runner.

Every manoeuvre is driven in the same task as a learned policy
(:class:`~tire_learning_env.wrappers.excitation.ExcitationWrapper`: same observer,
camera, truth randomisation, limits and scoring) for the same time budget. A manoeuvre
is a *road* for the lane-keeping driver to follow and/or a *steering offset* ``u(t)`` on
top of it, with one amplitude parameter that :func:`tune_amplitude` sets so the
manoeuvre uses the lateral-acceleration limit (the largest amplitude whose max ``|a_y|``
stays within ``fraction * ay_limit`` and whose true ``|e1|`` stays within the lane margin
on the tuning seeds).

=================  ============================================================  ===============
name               what                                                          amplitude
=================  ============================================================  ===============
``none``           lane keeping on a straight road, no excitation                 --
``cornering``      the paper's Study 1 road (straight, then left arcs with radii  kappa of the
                   in the ratio 300 : 250), radii scaled                          tighter arc [1/m]
``lane_changes``   repeated alternating lane changes (sine-curvature paths)      peak kappa [1/m]
``sine_road``      weaving road ``kappa = A sin(2 pi s / 300 m)``                 A [1/m]
``chirp_road``     weaving road, wavelength 600 m -> 120 m over 1800 m           A [1/m]
``sine_weave``     in-lane weaving: offset ``A sin(2 pi f t)`` on a straight road A [rad]
``chirp_weave``    in-lane chirp: offset ``A sin(phi(t))``, f 0.1 -> 1.5 Hz       A [rad]
=================  ============================================================  ===============
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable, ClassVar, Mapping, Sequence

import numpy as np

from .params import ParameterError
from .roads import ChirpRoad, LaneChangeRoad, PiecewiseCurvatureRoad, Road, SineRoad, StraightRoad
from .wrappers.excitation import ExcitationConfig, ExcitationWrapper, TruthRandomization, make_excitation_env

__all__ = [
    "Manoeuvre",
    "NoExcitation",
    "CorneringRoad",
    "LaneChanges",
    "SineWeavingRoad",
    "ChirpWeavingRoad",
    "SineWeave",
    "ChirpWeave",
    "MANOEUVRES",
    "make_manoeuvre",
    "run_policy",
    "run_manoeuvre",
    "tune_amplitude",
]

#: Policy signature used by :func:`run_policy`: ``(observation, step index) -> normalised action``.
ActFn = Callable[[np.ndarray, int], "np.ndarray | float"]


@dataclass(frozen=True)
class Manoeuvre:
    """A scripted manoeuvre: a road for the driver plus a steering offset ``u(t)`` [rad].

    Attributes
    ----------
    amplitude : float
        The one tunable size parameter (unit in :attr:`amplitude_unit`).
    """

    amplitude: float = 0.0

    name: ClassVar[str] = "manoeuvre"
    amplitude_unit: ClassVar[str] = "-"
    amplitude_bounds: ClassVar[tuple[float, float]] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.amplitude) and self.amplitude >= 0):
            raise ParameterError(f"{type(self).__name__}.amplitude must be finite and >= 0, got {self.amplitude!r}")

    @property
    def tunable(self) -> bool:
        return self.amplitude_bounds[1] > self.amplitude_bounds[0]

    def road(self) -> Road:
        """The reference path the lane-keeping driver follows."""
        return StraightRoad()

    def offset(self, t: float) -> float:
        """Steering offset [rad] at time ``t`` [s] added to the driver."""
        return 0.0

    def with_amplitude(self, amplitude: float) -> "Manoeuvre":
        return replace(self, amplitude=float(amplitude))

    def describe(self) -> dict[str, Any]:
        out = {"name": self.name, "amplitude": self.amplitude, "amplitude_unit": self.amplitude_unit}
        out.update({k: v for k, v in self.__dict__.items() if k != "amplitude"})
        return out


@dataclass(frozen=True)
class NoExcitation(Manoeuvre):
    """Lane keeping on a straight road (what a car does most of the time)."""

    name: ClassVar[str] = "none"


@dataclass(frozen=True)
class _RoadManoeuvre(Manoeuvre):
    """A manoeuvre made by the road alone: ``amplitude`` is a path curvature [1/m]."""

    amplitude_unit: ClassVar[str] = "1/m"
    amplitude_bounds: ClassVar[tuple[float, float]] = (1e-4, 0.02)


@dataclass(frozen=True)
class _WeavingRoad(_RoadManoeuvre):
    """A weaving road of peak curvature ``amplitude`` [1/m]."""

    amplitude: float = 1.0 / 400.0


@dataclass(frozen=True)
class CorneringRoad(_RoadManoeuvre):
    """The paper's Study 1 road: 300 m straight, 750 m left arc, then a tighter left arc.

    ``amplitude`` is the curvature of the tighter arc [1/m]; the first arc has
    ``250/300`` of it (the paper's 300 m and 250 m radii, ``amplitude = 1/250`` m).
    """

    amplitude: float = 1.0 / 250.0
    name: ClassVar[str] = "cornering"

    def road(self) -> Road:
        r2 = 1.0 / self.amplitude
        return PiecewiseCurvatureRoad.from_segments([(300.0, math.inf), (750.0, 1.2 * r2), (3000.0, r2)], 30.0)


@dataclass(frozen=True)
class LaneChanges(_RoadManoeuvre):
    """Alternating lane changes, one after the other with ``gap`` metres straight between.

    ``amplitude`` is the peak path curvature [1/m]; a change of one lane width ``w``
    then takes ``sqrt(2 pi w / amplitude)`` metres (:class:`~.roads.LaneChangeRoad`).
    """

    amplitude: float = 2.0 * math.pi * 3.7 / 90.0**2
    gap: float = 30.0  # [m]
    first: float = 30.0  # [m]
    length: float = 2500.0  # [m] covered by changes
    name: ClassVar[str] = "lane_changes"

    def road(self) -> Road:
        width = 3.7
        change = math.sqrt(2.0 * math.pi * width / self.amplitude)
        spacing = change + self.gap + 1e-6  # (the margin keeps rounding from overlapping the changes)
        count = max(1, int((self.length - self.first) // spacing))
        return LaneChangeRoad.repeated(self.first, spacing, count, change, width)


@dataclass(frozen=True)
class SineWeavingRoad(_WeavingRoad):
    """A weaving road ``kappa = A sin(2 pi s / wavelength)`` (after ``start``)."""

    wavelength: float = 300.0  # [m]
    start: float = 30.0  # [m]
    name: ClassVar[str] = "sine_road"

    def road(self) -> Road:
        return SineRoad(amplitude=self.amplitude, wavelength=self.wavelength, start=self.start)


@dataclass(frozen=True)
class ChirpWeavingRoad(_WeavingRoad):
    """A weaving road whose wavelength shrinks from 600 m to 120 m over 1800 m."""

    wavelength_start: float = 600.0  # [m]
    wavelength_end: float = 120.0  # [m]
    length: float = 1800.0  # [m]
    start: float = 30.0  # [m]
    name: ClassVar[str] = "chirp_road"

    def road(self) -> Road:
        return ChirpRoad(self.amplitude, self.wavelength_start, self.wavelength_end, self.length, self.start)


@dataclass(frozen=True)
class SineWeave(Manoeuvre):
    """In-lane weaving on a straight road: steering offset ``A sin(2 pi f (t - start))``."""

    amplitude: float = 0.01
    frequency: float = 0.5  # [Hz]
    start: float = 1.0  # [s]
    name: ClassVar[str] = "sine_weave"
    amplitude_unit: ClassVar[str] = "rad"
    amplitude_bounds: ClassVar[tuple[float, float]] = (0.0, 0.05)

    def offset(self, t: float) -> float:
        if t < self.start:
            return 0.0
        return self.amplitude * math.sin(2.0 * math.pi * self.frequency * (t - self.start))


@dataclass(frozen=True)
class ChirpWeave(Manoeuvre):
    """In-lane chirp on a straight road: offset ``A sin(phi(t))``, frequency ``f0 -> f1`` linearly."""

    amplitude: float = 0.01
    f0: float = 0.1  # [Hz]
    f1: float = 1.5  # [Hz]
    duration: float = 59.0  # [s] of the sweep
    start: float = 1.0  # [s]
    name: ClassVar[str] = "chirp_weave"
    amplitude_unit: ClassVar[str] = "rad"
    amplitude_bounds: ClassVar[tuple[float, float]] = (0.0, 0.05)

    def offset(self, t: float) -> float:
        x = t - self.start
        if x < 0 or x > self.duration:
            return 0.0
        k = (self.f1 - self.f0) / self.duration
        return self.amplitude * math.sin(2.0 * math.pi * (self.f0 * x + 0.5 * k * x * x))


MANOEUVRES: dict[str, type[Manoeuvre]] = {
    cls.name: cls
    for cls in (NoExcitation, CorneringRoad, LaneChanges, SineWeavingRoad, ChirpWeavingRoad, SineWeave, ChirpWeave)
}


def make_manoeuvre(name: str, **params: Any) -> Manoeuvre:
    """A manoeuvre of :data:`MANOEUVRES` by name (unknown names or parameters raise)."""
    if name not in MANOEUVRES:
        raise ParameterError(f"unknown manoeuvre {name!r}; manoeuvres are {sorted(MANOEUVRES)}")
    cls = MANOEUVRES[name]
    allowed = set(cls.__dataclass_fields__)
    unknown = sorted(set(params) - allowed)
    if unknown:
        raise ParameterError(f"{cls.__name__}: unknown parameter(s) {unknown}; allowed {sorted(allowed)}")
    return cls(**params)


def run_policy(
    act: ActFn,
    road: Road | str = "straight",
    seed: int = 0,
    duration: float | None = None,
    config: ExcitationConfig | Mapping | None = None,
    randomization: TruthRandomization | Mapping | bool | None = True,
    env: ExcitationWrapper | None = None,
    **env_kwargs: Any,
) -> dict[str, Any]:
    """Drive one episode of the excitation task with ``act`` and score it.

    Parameters
    ----------
    act : callable
        ``(observation, step index) -> normalised action`` in ``[-1, 1]``.
    road : Road or str
        Road of the episode.
    seed : int
        Reset seed (camera noise and, with randomisation, the truth tires).
    duration : float, optional
        Driving time [s] (default ``config.episode_time``).
    config, randomization, **env_kwargs
        As :func:`~tire_learning_env.wrappers.excitation.make_excitation_env`.
    env : ExcitationWrapper, optional
        Reuse this env (``road`` and the other settings are then ignored).

    Returns
    -------
    dict
        :meth:`ExcitationWrapper.episode_metrics` plus ``seed``.
    """
    if env is None:
        env = make_excitation_env(config=config, randomization=randomization, road=road, **env_kwargs)
    duration = env.config.episode_time if duration is None else float(duration)
    n = int(round(duration / env.dt_policy))
    obs, _ = env.reset(seed=int(seed))
    for k in range(n):
        action = np.asarray(act(obs, k), dtype=np.float32).reshape(1)
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    out = env.episode_metrics()
    out["seed"] = int(seed)
    return out


def run_manoeuvre(manoeuvre: Manoeuvre, seed: int = 0, duration: float | None = None, **kwargs: Any) -> dict[str, Any]:
    """:func:`run_policy` of a scripted manoeuvre (its road, its offset as the action)."""
    cfg = kwargs.get("config")
    max_offset = ExcitationConfig().max_steering_offset if cfg is None else (
        cfg.max_steering_offset if isinstance(cfg, ExcitationConfig) else ExcitationConfig.from_dict(cfg).max_steering_offset
    )
    if manoeuvre.amplitude_unit == "rad" and manoeuvre.amplitude > max_offset + 1e-12:
        raise ParameterError(
            f"{manoeuvre.name}: amplitude {manoeuvre.amplitude} rad exceeds max_steering_offset {max_offset} rad"
        )
    dt = 1.0 / 20.0

    def act(obs, k):
        return manoeuvre.offset(k * dt) / max_offset

    return run_policy(act, road=manoeuvre.road(), seed=seed, duration=duration, **kwargs)


@dataclass
class TuningResult:
    """Outcome of :func:`tune_amplitude`."""

    manoeuvre: Manoeuvre
    max_abs_ay: float
    max_abs_e1: float
    history: list[dict[str, float]] = field(default_factory=list)


def tune_amplitude(
    manoeuvre: Manoeuvre,
    seeds: Sequence[int] = (10_000, 10_001, 10_002),
    fraction: float = 0.95,
    lane_fraction: float = 0.95,
    iterations: int = 14,
    duration: float | None = None,
    **kwargs: Any,
) -> TuningResult:
    """Largest amplitude keeping ``max |a_y| <= fraction ay_limit`` and true ``|e1| <= lane_fraction lane_margin``.

    Bisection over :attr:`Manoeuvre.amplitude_bounds` on the tuning ``seeds`` (keep them
    apart from evaluation seeds); every candidate is run on every seed (``**kwargs`` go
    to :func:`run_manoeuvre`; without a ``config`` the manoeuvre runs without the safety
    filter, so that it keeps the limits by itself). A manoeuvre without amplitude is
    returned as is.
    """
    cfg = kwargs.get("config")
    if cfg is None:  # the manoeuvre itself must respect the limits: no safety filter to lean on
        cfg = kwargs["config"] = ExcitationConfig(safety_filter=False)
    cfg = cfg if isinstance(cfg, ExcitationConfig) else ExcitationConfig.from_dict(cfg)
    ay_cap, e1_cap = fraction * cfg.ay_limit, lane_fraction * cfg.lane_margin

    def worst(m: Manoeuvre) -> tuple[float, float]:
        ay = e1 = 0.0
        for s in seeds:
            r = run_manoeuvre(m, seed=s, duration=duration, **kwargs)
            ay = max(ay, r["max_abs_ay"])
            e1 = max(e1, r["max_abs_e1"] if not r["departed"] else math.inf)
        return ay, e1

    history: list[dict[str, float]] = []
    if not manoeuvre.tunable:
        ay, e1 = worst(manoeuvre)
        return TuningResult(manoeuvre, ay, e1, [{"amplitude": manoeuvre.amplitude, "max_abs_ay": ay, "max_abs_e1": e1}])
    lo, hi = manoeuvre.amplitude_bounds
    best = None
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        m = manoeuvre.with_amplitude(mid)
        ay, e1 = worst(m)
        history.append({"amplitude": mid, "max_abs_ay": ay, "max_abs_e1": e1})
        if ay <= ay_cap and e1 <= e1_cap:
            lo, best = mid, (m, ay, e1)
        else:
            hi = mid
    if best is None:
        m = manoeuvre.with_amplitude(manoeuvre.amplitude_bounds[0])
        ay, e1 = worst(m)
        best = (m, ay, e1)
    return TuningResult(best[0], best[1], best[2], history)
