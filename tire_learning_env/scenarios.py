"""Scenarios for simulated test data: hidden effects, speed profiles and test roads.

``tire-learning simulate --effect NAME=VALUE --speed-profile P --road R`` and the tests use this
to make logs in which an effect is present but hidden from the discrepancy workflow
(:mod:`tire_learning_env.discrepancy`), which reads only the logs. It sits below the analysis
layer (it needs only the plant, the roads and the simulator), so simulating does not depend on
the analysis package. Stable names (:data:`HIDDEN_EFFECTS`) map onto the truth model:

- fields of :class:`~tire_learning_env.dynamics.PlantEffects` (the compiled low-order
  plant): ``tire_relaxation``, ``road_bank``, ``steering_offset``, ``crosswind``,
  ``cornering_stiffness_scale`` (both axles) and ``_front``/``_rear``, ``load_transfer``;
- fields of :class:`~tire_learning_env.params.CameraParams`: ``camera_latency``,
  ``camera_heading_bias``, ``camera_offset_bias``;
- effects of :class:`EffectPlant`, a thin wrapper of the plant (no change to the compiled
  kernels): ``speed_dependent_stiffness`` (both axle forces times ``1 - c vx^2``) and
  ``steering_nonlinearity``, which is deliberately *not* in the candidate library
  (road-wheel angle ``delta + k delta^3``): data for the ``unexplained`` verdict.

The raw field names (``relaxation_length``, ``bank_angle``, ``crosswind_force``, ...,
``camera_latency``) keep working. An unknown name raises :class:`ParameterError` listing
the valid ones. Speed profiles: :data:`SPEED_PROFILES`, :func:`speed_profile`; roads:
:data:`SCENARIO_ROADS` (:class:`IdentificationRoad`, :class:`CurvesRoad`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._kernels import X_BANK, X_SCALE_F, X_SCALE_R, X_WIND_F
from .dynamics import BicyclePlant, PlantEffects
from .params import ParameterError
from .roads import LaneChangeRoad, PiecewiseCurvatureRoad, Road

__all__ = [
    "simulate_hidden",
    "IdentificationRoad",
    "CurvesRoad",
    "SCENARIO_ROADS",
    "HIDDEN_EFFECTS",
    "HiddenEffects",
    "parse_hidden_effects",
    "EffectPlant",
    "SPEED_PROFILES",
    "speed_profile",
]

#: stable name -> (target, field(s), unit, what it does)
HIDDEN_EFFECTS: dict[str, tuple[str, tuple[str, ...], str, str]] = {
    "tire_relaxation": ("plant", ("relaxation_length",), "m", "tire relaxation length"),
    "camera_latency": ("camera", ("latency",), "s", "camera latency"),
    "road_bank": ("plant", ("bank_angle",), "rad", "road bank angle (positive raises the left edge)"),
    "steering_offset": ("plant", ("steering_offset",), "rad", "road-wheel angle offset"),
    "camera_heading_bias": ("camera", ("e2_bias",), "rad", "bias of the measured heading error e2"),
    "camera_offset_bias": ("camera", ("e1_bias",), "m", "bias of the measured lateral offset e1 (unobservable)"),
    "cornering_stiffness_scale": (
        "plant", ("cornering_stiffness_scale_front", "cornering_stiffness_scale_rear"), "-", "both axle forces scaled",
    ),  # fmt: skip
    "cornering_stiffness_scale_front": ("plant", ("cornering_stiffness_scale_front",), "-", "front axle force scaled"),
    "cornering_stiffness_scale_rear": ("plant", ("cornering_stiffness_scale_rear",), "-", "rear axle force scaled"),
    "load_transfer": ("plant", ("load_transfer",), "-", "lateral load transfer strength"),
    "crosswind": ("plant", ("crosswind_force",), "N", "constant lateral force at the CG"),
    "crosswind_arm": ("plant", ("crosswind_arm",), "m", "centre of pressure ahead of the CG"),
    "speed_dependent_stiffness": ("wrapper", ("speed_coefficient",), "s^2/m^2", "axle forces times 1 - c vx^2"),
    "steering_nonlinearity": (
        "wrapper", ("steering_cubic",), "1/rad^2", "road-wheel angle delta + k delta^3 (NOT in the candidate library)",
    ),  # fmt: skip
    # issue 18: effects as roads and sensors have them
    "crossfall": ("plant", ("bank_angle",), "rad", "constant crossfall of the road (= road_bank)"),
    "superelevation_rate": (
        "wrapper", ("superelevation_rate",), "rad m", "curve superelevation per unit path curvature (outer edge up)",
    ),  # fmt: skip
    "superelevation_cap": ("wrapper", ("superelevation_cap",), "rad", "largest curve superelevation (default 0.07)"),
    "steering_ratio_error": ("wrapper", ("steering_ratio",), "-", "road-wheel angle (1 + error) * delta"),
    "camera_heading_drift": (
        "sensor", ("e2_drift",), "rad/s", "camera heading bias drifting at this rate (zero at the log's middle)",
    ),  # fmt: skip
    "crosswind_gust": (
        "wrapper", ("gust_amplitude",), "N", "1-cos crosswind gusts of this peak force, 2 s long, one every 7 s, "
        "alternating side (NOT in the candidate library: not a constant effect)",
    ),  # fmt: skip
}
_CAMERA_FIELDS = {"camera_latency": "latency", "camera_heading_bias": "e2_bias", "camera_offset_bias": "e1_bias"}
_PLANT_FIELDS = tuple(f.name for f in fields(PlantEffects))


@dataclass(frozen=True)
class HiddenEffects:
    """What a set of ``--effect NAME=VALUE`` assignments does to the truth model.

    Attributes
    ----------
    plant : PlantEffects
    camera : dict
        Keyword arguments for :class:`~tire_learning_env.params.CameraParams`.
    speed_coefficient : float
        Both axle forces times ``1 - speed_coefficient vx^2`` [s^2/m^2].
    steering_cubic : float
        Road-wheel angle ``delta + steering_cubic delta^3`` [1/rad^2].
    """

    plant: PlantEffects = field(default_factory=PlantEffects)
    camera: dict = field(default_factory=dict)
    speed_coefficient: float = 0.0
    steering_cubic: float = 0.0
    superelevation_rate: float = 0.0
    superelevation_cap: float = 0.07
    steering_ratio: float = 0.0
    gust_amplitude: float = 0.0
    e2_drift: float = 0.0

    @property
    def needs_wrapper(self) -> bool:
        return any(v != 0.0 for v in (self.speed_coefficient, self.steering_cubic, self.superelevation_rate,
                                      self.steering_ratio, self.gust_amplitude))  # fmt: skip

    def make_plant(self, vehicle, front_tire, rear_tire):
        """The truth plant: a :class:`BicyclePlant`, wrapped in :class:`EffectPlant` if needed."""
        plant = BicyclePlant(vehicle, front_tire, rear_tire, self.plant)
        if self.needs_wrapper:
            return EffectPlant(
                plant, self.speed_coefficient, self.steering_cubic, superelevation_rate=self.superelevation_rate,
                superelevation_cap=self.superelevation_cap, steering_ratio=self.steering_ratio,
                gust_amplitude=self.gust_amplitude,
            )  # fmt: skip
        return plant

    def apply_to_sensors(self, cols: dict) -> dict:
        """Sensor effects applied to the log's columns (the camera heading drift, zero at the log's middle)."""
        if self.e2_drift != 0.0:
            t = cols["t"]
            cols = dict(cols)
            cols["e2"] = cols["e2"] + self.e2_drift * (t - 0.5 * (t[0] + t[-1]))
        return cols


def parse_hidden_effects(assignments: dict[str, float]) -> HiddenEffects:
    """Map ``{name: value}`` (stable names or raw field names) onto the truth model.

    Raises
    ------
    ParameterError
        An unknown name (the message lists the valid ones) or an invalid value.
    """
    plant: dict[str, float] = {}
    camera: dict[str, float] = {}
    wrapper: dict[str, float] = {}
    sensor: dict[str, float] = {}
    for name, value in assignments.items():
        if not math.isfinite(value):
            raise ParameterError(f"--effect {name}: value must be finite, got {value!r}")
        if name in HIDDEN_EFFECTS:
            target, names, _, _ = HIDDEN_EFFECTS[name]
            dest = {"plant": plant, "camera": camera, "wrapper": wrapper, "sensor": sensor}[target]
            for f in names:
                dest[f] = value
        elif name in _CAMERA_FIELDS.values() or name in ("e1_bias", "e2_bias"):
            camera[name] = value
        elif name in _PLANT_FIELDS:
            plant[name] = value
        else:
            known = sorted(set(HIDDEN_EFFECTS) | set(_PLANT_FIELDS) | {"latency", "e1_bias", "e2_bias"})
            raise ParameterError(f"unknown effect {name!r}; known effects: {', '.join(known)}")
    return HiddenEffects(
        plant=PlantEffects.from_dict(plant),
        camera=camera,
        speed_coefficient=wrapper.get("speed_coefficient", 0.0),
        steering_cubic=wrapper.get("steering_cubic", 0.0),
        superelevation_rate=wrapper.get("superelevation_rate", 0.0),
        superelevation_cap=wrapper.get("superelevation_cap", 0.07),
        steering_ratio=wrapper.get("steering_ratio", 0.0),
        gust_amplitude=wrapper.get("gust_amplitude", 0.0),
        e2_drift=sensor.get("e2_drift", 0.0),
    )


class EffectPlant:
    """A :class:`BicyclePlant` with effects its compiled kernel does not have.

    - ``speed_coefficient`` c [s^2/m^2]: before each step the plant's stiffness scales
      are set to ``base * (1 - c vx^2)`` with the step's speed;
    - ``steering_cubic`` k [1/rad^2]: the road wheels turn ``delta + k delta^3``.

    It has no ``kernel_params``, so :class:`~tire_learning_env.simulation.Simulator`
    runs it in its Python loop (same tick sequence).
    """

    def __init__(
        self, plant: BicyclePlant, speed_coefficient: float = 0.0, steering_cubic: float = 0.0, *,
        superelevation_rate: float = 0.0, superelevation_cap: float = 0.07, steering_ratio: float = 0.0,
        gust_amplitude: float = 0.0,
    ) -> None:  # fmt: skip
        self.inner = plant
        self.vehicle = plant.vehicle
        self.speed_coefficient = float(speed_coefficient)
        self.steering_cubic = float(steering_cubic)
        self.superelevation_rate = float(superelevation_rate)  # [rad m]
        self.superelevation_cap = float(superelevation_cap)  # [rad]
        if not self.superelevation_cap > 0:
            raise ParameterError(f"superelevation_cap must be > 0 rad, got {superelevation_cap!r}")
        self.steering_ratio = float(steering_ratio)  # [-]
        self.gust_amplitude = float(gust_amplitude)  # [N]
        self._base = (plant.eff_vec[X_SCALE_F], plant.eff_vec[X_SCALE_R])
        self._crossfall = float(plant.eff_vec[X_BANK])
        self._wind = float(plant.eff_vec[X_WIND_F])
        self._time = 0.0

    def bank(self, kappa: float) -> float:
        """Road bank [rad] at path curvature ``kappa`` [1/m]: crossfall minus the superelevation
        ``sign(kappa) min(rate |kappa|, cap)`` (the outer edge of a curve is raised)."""
        e = min(abs(self.superelevation_rate * kappa), self.superelevation_cap)
        return self._crossfall - math.copysign(e, self.superelevation_rate * kappa)

    def gust(self, t: float) -> float:
        """Gust force [N] at time ``t`` [s]: a 1-cos gust of 2 s every 7 s, alternating side."""
        period, length = 7.0, 2.0
        k = int(t // period)
        phase = t - k * period
        if phase >= length:
            return 0.0
        sign = 1.0 if k % 2 == 0 else -1.0
        return sign * self.gust_amplitude * 0.5 * (1.0 - math.cos(2.0 * math.pi * phase / length))

    @property
    def state(self) -> NDArray:
        return self.inner.state

    def reset(self, xi: ArrayLike | None = None) -> None:
        self.inner.reset(xi)
        self._time = 0.0

    def _gain(self, vx: float) -> float:
        g = 1.0 - self.speed_coefficient * vx * vx
        if not g > 0:
            raise ParameterError(f"speed_dependent_stiffness: 1 - c vx^2 = {g:.3g} <= 0 at vx = {vx:.3g} m/s")
        return g

    def step(self, delta, dt, psi_dot_des, psi_ddot_des, vx=None, ax=0.0):
        vx = self.vehicle.vx if vx is None else vx
        if self.speed_coefficient != 0.0:
            g = self._gain(vx + 0.5 * dt * ax)
            self.inner.eff_vec[X_SCALE_F] = self._base[0] * g
            self.inner.eff_vec[X_SCALE_R] = self._base[1] * g
        if self.superelevation_rate != 0.0:
            v_mid = vx + 0.5 * dt * ax
            # path curvature at the middle of the step (psi_dot_des = (start, middle, end) of the step) [1/m]
            self.inner.eff_vec[X_BANK] = self.bank(psi_dot_des[1] / max(v_mid, 0.1))
        if self.gust_amplitude != 0.0:
            self.inner.eff_vec[X_WIND_F] = self._wind + self.gust(self._time + 0.5 * dt)
        self._time += dt
        actual = delta * (1.0 + self.steering_ratio) + self.steering_cubic * delta**3
        return self.inner.step(actual, dt, psi_dot_des, psi_ddot_des, vx, ax)

    def true_axle_curve(self, alpha: ArrayLike, axle: str, vx: float | None = None) -> NDArray:
        """Steady-state truth axle force [N] at ``vx`` (default the vehicle's)."""
        g = self._gain(self.vehicle.vx if vx is None else vx)
        return self.inner.true_axle_curve(alpha, axle) * g

    def true_cornering_stiffness(self) -> tuple[float, float]:
        g = self._gain(self.vehicle.vx)
        cf, cr = self.inner.true_cornering_stiffness()
        return cf * g, cr * g


def _sine(v0: float, amplitude: float = 0.25, period: float = 40.0) -> Callable[[float], tuple[float, float]]:
    w = 2.0 * math.pi / period

    def profile(t: float) -> tuple[float, float]:
        return v0 * (1.0 + amplitude * math.sin(w * t)), v0 * amplitude * w * math.cos(w * t)

    return profile


def _ramp(v0: float, start: float = 0.6, duration: float = 60.0) -> Callable[[float], tuple[float, float]]:
    slope = v0 * (1.0 - start) / duration

    def profile(t: float) -> tuple[float, float]:
        if t < duration:
            return v0 * start + slope * t, slope
        return v0, 0.0

    return profile


#: speed profiles of ``simulate --speed-profile`` (``v0`` = the vehicle's ``vx``)
SPEED_PROFILES: dict[str, str] = {
    "constant": "vx = v0",
    "sine": "vx = v0 (1 + 0.25 sin(2 pi t / 40 s)): 0.75 v0 .. 1.25 v0, |ax| <= 0.04 v0 1/s",
    "ramp": "vx rises linearly from 0.6 v0 to v0 over 60 s, then stays",
}


def speed_profile(name: str, v0: float) -> Callable[[float], tuple[float, float]] | None:
    """The speed profile ``t -> (vx, ax)`` called ``name`` (``None`` for constant speed)."""
    if name == "constant":
        return None
    if name == "sine":
        return _sine(v0)
    if name == "ramp":
        return _ramp(v0)
    raise ParameterError(f"unknown speed profile {name!r}; known: {sorted(SPEED_PROFILES)}")


def steering_nonlinearity_gain(delta: NDArray, k: float) -> NDArray:
    """Road-wheel angle of the out-of-library steering nonlinearity (for plots and checks)."""
    delta = np.asarray(delta, dtype=float)
    return delta + k * delta**3


class IdentificationRoad(Road):
    """A test drive that excites steady and transient lateral dynamics, repeating every 1800 m.

    One period: 100 m straight, a left curve of R = 250 m (300 m), 100 m straight, a right
    curve of R = 250 m (300 m), 100 m straight (curvature changes blended by 40 m
    clothoids), then six alternating lane changes of 90 m every 150 m, then straight to
    1800 m. At 30 m/s a period lasts 60 s and the lateral acceleration reaches about
    3.6 m/s^2 in the curves; the lane changes move the car by one lane width.

    Parameters
    ----------
    lane_width : float
        Lane width [m] (lateral displacement of a lane change).
    """

    period = 1800.0  # [m]

    def __init__(self, lane_width: float = 3.7) -> None:
        self.lane_width = lane_width
        self._curves = PiecewiseCurvatureRoad.from_segments(
            [(100.0, math.inf), (300.0, 250.0), (100.0, math.inf), (300.0, -250.0), (1000.0, math.inf)],
            transition_length=40.0,
            lane_width=lane_width,
        )
        self._changes = LaneChangeRoad.repeated(first=900.0, spacing=150.0, count=6, lane_width=lane_width)

    def curvature(self, s: ArrayLike) -> NDArray:
        x = np.mod(np.asarray(s, dtype=float), self.period)
        return self._curves.curvature(x) + self._changes.curvature(x)

    def curvature_rate(self, s: ArrayLike) -> NDArray:
        x = np.mod(np.asarray(s, dtype=float), self.period)
        return self._curves.curvature_rate(x) + self._changes.curvature_rate(x)


class CurvesRoad(Road):
    """A winding road of steady curves both ways and nothing else (no lane changes), every 2400 m.

    Curves of R = 300, 400, 250 and 350 m (left, right, left, right; 250-300 m long) between
    straights of 100-150 m, curvature changes blended by 60 m clothoids. At a constant speed
    the car spends most of the time in steady cornering: where a curvature-proportional
    superelevation and a cornering-stiffness error look alike.

    Parameters
    ----------
    lane_width : float
        Lane width [m].
    """

    period = 2400.0  # [m]

    def __init__(self, lane_width: float = 3.7) -> None:
        self.lane_width = lane_width
        self._curves = PiecewiseCurvatureRoad.from_segments(
            [(150.0, math.inf), (300.0, 300.0), (100.0, math.inf), (250.0, -400.0), (150.0, math.inf),
             (300.0, 250.0), (100.0, math.inf), (250.0, -350.0), (800.0, math.inf)],
            transition_length=60.0,
            lane_width=lane_width,
        )  # fmt: skip

    def curvature(self, s: ArrayLike) -> NDArray:
        return self._curves.curvature(np.mod(np.asarray(s, dtype=float), self.period))

    def curvature_rate(self, s: ArrayLike) -> NDArray:
        return self._curves.curvature_rate(np.mod(np.asarray(s, dtype=float), self.period))


#: test roads of ``simulate --road`` besides the built-in ones (name -> factory)
SCENARIO_ROADS: dict[str, Callable[[], Road]] = {"identification": IdentificationRoad, "curves": CurvesRoad}


def simulate_hidden(
    effects: dict[str, float] | None = None,
    road: str | Road = "identification",
    duration: float = 60.0,
    camera_rate: float = 100.0,
    e1_noise: float = 0.01,
    e2_noise: float = math.radians(0.1),
    noise: str = "uniform",
    seed: int = 0,
    speed: str = "constant",
    log_rate: float = 100.0,
    vehicle=None,
    truth_columns: bool = True,
    tire: str = "pacejka",
) -> dict[str, NDArray]:
    """Columns of a shared-format log from the low-order truth with hidden ``effects``.

    The same recipe as ``tire-learning simulate`` (Pacejka truth tires, built-in driver,
    1 kHz physics, rows every ``1 / log_rate`` s plus every row with a camera frame).

    Parameters
    ----------
    effects : dict
        ``{name: value}`` with the names of :data:`HIDDEN_EFFECTS` (or raw field names).
    road : str or Road
        A built-in road, ``"identification"`` (:class:`IdentificationRoad`) or a Road.
    duration : float
        [s].
    camera_rate : float
        Camera frame rate [Hz].
    e1_noise, e2_noise : float
        Noise half-width (uniform) or standard deviation (gaussian) [m], [rad].
    noise : {"uniform", "gaussian", "none"}
    seed : int
        Camera-noise seed.
    speed : str
        Speed profile name (:data:`SPEED_PROFILES`).
    log_rate : float
        Row rate [Hz].
    vehicle : VehicleParams, optional
    truth_columns : bool
        Include the ``true_*`` columns.
    tire : {"pacejka", "linear"}
        Truth tire model.
    """
    from .params import CameraParams, TireParams, VehicleParams
    from .simulation import simulate
    from .tires import axle_tires

    vehicle = vehicle or VehicleParams()
    hidden = parse_hidden_effects(effects or {})
    if noise == "none":
        camera = CameraParams(rate=camera_rate, **hidden.camera)
    else:
        camera = CameraParams(rate=camera_rate, noise=noise, e1_noise=e1_noise, e2_noise=e2_noise, **hidden.camera)
    if isinstance(road, str) and road in SCENARIO_ROADS:
        road = SCENARIO_ROADS[road]()
    plant = hidden.make_plant(vehicle, *axle_tires(vehicle, tire, TireParams()))
    physics_rate = 1000.0
    log = simulate(road, duration, vehicle=vehicle, camera=camera, physics_rate=physics_rate, seed=seed,
                   speed_profile=speed_profile(speed, vehicle.vx), plant=plant)  # fmt: skip
    cols = hidden.apply_to_sensors(log.to_columns(include_truth=truth_columns))
    step = max(int(round(physics_rate / log_rate)), 1)
    keep = np.zeros(len(cols["t"]), dtype=bool)
    keep[::step] = True
    keep |= np.isfinite(cols["e1"])
    return {k: v[keep] for k, v in cols.items()}
