"""Frozen parameter dataclasses in SI units.

Every parameter set is an immutable dataclass validated in ``__post_init__``. Build one
from keyword arguments, from a ``dict`` (:meth:`from_dict`) or from a JSON file
(:meth:`from_json`); an unknown key or an invalid value raises :class:`ParameterError`
naming the field.

Units are stated next to each field (``# [N/rad]``). The defaults are the paper's
CarSim D-class sedan (Jeon et al. 2021, Sec. IV).
"""

from __future__ import annotations

import dataclasses
import json
import math
import numbers
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, ClassVar, Mapping, TypeVar

__all__ = [
    "ParameterError",
    "VehicleParams",
    "TireParams",
    "RoadParams",
    "CameraParams",
    "DriverParams",
    "GRAVITY",
]

GRAVITY = 9.81  # [m/s^2]

P = TypeVar("P", bound="_Params")


class ParameterError(ValueError):
    """An invalid, missing or unknown parameter. The message names the field."""


def check_keys(cls_name: str, given: Mapping[str, Any], allowed: set[str] | list[str] | tuple[str, ...]) -> None:
    """Raise :class:`ParameterError` naming every key of ``given`` not in ``allowed``."""
    unknown = sorted(set(given) - set(allowed))
    if unknown:
        raise ParameterError(
            f"{cls_name}: unknown key(s) {unknown}; allowed keys are {sorted(allowed)}"
        )


def coerce_params(cls: type[P], value: Any, name: str) -> P | None:
    """``value`` as a ``cls`` instance: an instance passes, a mapping goes through
    :meth:`_Params.from_dict` (unknown keys raise), ``None`` stays ``None``; anything else
    raises :class:`ParameterError` naming ``name``."""
    if value is None or isinstance(value, cls):
        return value
    if isinstance(value, Mapping):
        return cls.from_dict(value)
    raise ParameterError(f"{name} must be a {cls.__name__} or a dict, got {type(value).__name__}")


class _Params:
    """Mixin: construction from dict/JSON with strict keys, and field validation helpers."""

    _positive: ClassVar[tuple[str, ...]] = ()
    _non_negative: ClassVar[tuple[str, ...]] = ()

    def __post_init__(self) -> None:
        for f in fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                continue
            if not math.isfinite(value):
                raise ParameterError(f"{type(self).__name__}.{f.name} must be finite, got {value!r}")
        for name in self._positive:
            value = getattr(self, name)
            if not value > 0:
                raise ParameterError(f"{type(self).__name__}.{name} must be > 0, got {value!r}")
        for name in self._non_negative:
            value = getattr(self, name)
            if not value >= 0:
                raise ParameterError(f"{type(self).__name__}.{name} must be >= 0, got {value!r}")

    def _check_types(self) -> None:
        """Raise :class:`ParameterError` naming a field whose value has the wrong type: a
        ``float``/``int`` field takes a real number (a bool is not a number), a ``str`` field
        a string."""
        for f in fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            kind = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", "")
            if kind in ("float", "int"):
                if isinstance(value, bool) or not isinstance(value, numbers.Real):
                    raise ParameterError(
                        f"{type(self).__name__}.{f.name} must be a number, got {value!r} ({type(value).__name__})"
                    )
            elif kind == "str" and not isinstance(value, str):
                raise ParameterError(
                    f"{type(self).__name__}.{f.name} must be a string, got {value!r} ({type(value).__name__})"
                )

    @classmethod
    def from_dict(cls: type[P], data: Mapping[str, Any]) -> P:
        """Build from a mapping; unknown keys raise :class:`ParameterError` naming them."""
        if not isinstance(data, Mapping):
            raise ParameterError(f"{cls.__name__}: expected a mapping, got {type(data).__name__}")
        check_keys(cls.__name__, data, [f.name for f in fields(cls)])  # type: ignore[arg-type]
        try:
            return cls(**dict(data))
        except TypeError as exc:  # wrong types surface as TypeError from arithmetic
            raise ParameterError(f"{cls.__name__}: {exc}") from exc

    @classmethod
    def from_json(cls: type[P], path: str | Path) -> P:
        """Read a JSON object from ``path`` and build with :meth:`from_dict`."""
        path = Path(path)
        try:
            text = path.read_text()
        except OSError as exc:
            raise ParameterError(f"cannot read {cls.__name__} file {path}: {exc}") from exc
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ParameterError(f"{path} is not valid JSON: {exc}") from exc
        return cls.from_dict(data)

    def to_dict(self) -> dict[str, Any]:
        """The fields as a plain dict (JSON serialisable)."""
        return dataclasses.asdict(self)  # type: ignore[call-overload]

    def replace(self: P, **changes: Any) -> P:
        """Copy with some fields changed (validated; unknown names raise)."""
        check_keys(type(self).__name__, changes, [f.name for f in fields(self)])  # type: ignore[arg-type]
        return dataclasses.replace(self, **changes)  # type: ignore[type-var]


@dataclass(frozen=True)
class VehicleParams(_Params):
    """Rigid-body and nominal-tire parameters of the bicycle model (SPEC §1).

    Defaults: the paper's CarSim D-class sedan.

    Parameters
    ----------
    m : float
        Mass [kg].
    Iz : float
        Yaw moment of inertia [kg m^2].
    lf, lr : float
        Distance from the centre of gravity to the front / rear axle [m].
    vx : float
        Longitudinal speed [m/s] (constant in the low-order model).
    Cf, Cr : float
        Nominal cornering stiffness per tire, front / rear [N/rad]; an axle has ``2 C``.
    width : float
        Overall vehicle width [m] (lane-departure checks, rendering).
    track : float
        Track width [m] (lateral load transfer).
    h_cg : float
        Height of the centre of gravity [m] (load transfer).
    imu_x : float
        Position of the IMU's accelerometer ahead of the centre of gravity [m] (negative:
        behind it). An accelerometer ``x`` ahead of the CG reads ``a_y + x r_dot``; the log
        preparation subtracts it (:func:`tire_learning_env.imu.logs.accelerometer_at_cg`, applied
        by ``imu.clean_imu_log`` (IMU estimate, discrepancy workflow) and by the ``estimate``
        command's fused path); :func:`tire_learning_env.observer.estimate` called directly reads
        ``ay`` as given. Default 0: at the CG.
    camera_x : float
        Where the lane camera's ``e1`` is measured, ahead of the centre of gravity [m] (negative:
        behind it; a windscreen camera is typically 1-2 m ahead). A point ``x`` ahead of the CG is
        ``e1 + x sin(e2) - kappa x^2 / 2`` from the path (the last term: the path's own bend over
        ``x``), and :func:`tire_learning_env.observer.estimate` measures that. ``e2`` is the same
        anywhere on the car. Default 0: ``e1`` is the CG's. The log cannot show it: a camera 1.5 m
        ahead read as the CG's made a 45 s lane-change log not identifiable (bands of +/-22 / 36 %
        against +/-2.4 / 3.1 % with ``camera_x`` given: ``benchmarks/bench_camera_position.py``).
    """

    m: float = 1529.95  # [kg]
    Iz: float = 4607.47  # [kg m^2]
    lf: float = 1.13906  # [m]
    lr: float = 1.63716  # [m]
    vx: float = 30.0  # [m/s]
    Cf: float = 102466.1678  # [N/rad] per tire
    Cr: float = 102466.1678  # [N/rad] per tire
    width: float = 1.85  # [m]
    track: float = 1.6  # [m]
    h_cg: float = 0.55  # [m]
    imu_x: float = 0.0  # [m] accelerometer ahead of the CG
    camera_x: float = 0.0  # [m] where the lane camera's e1 is measured, ahead of the CG

    _positive: ClassVar[tuple[str, ...]] = ("m", "Iz", "lf", "lr", "vx", "Cf", "Cr", "width", "track")
    _non_negative: ClassVar[tuple[str, ...]] = ("h_cg",)

    def __post_init__(self) -> None:
        self._check_types()
        super().__post_init__()

    #: Plausible ranges (checked by :meth:`check_plausible`, i.e. for vehicle files): wide enough
    #: for a 1/10-scale model car up to a loaded truck, narrow enough to catch wrong units and typos.
    PLAUSIBLE: ClassVar[dict[str, tuple[float, float, str]]] = {
        "m": (1.0, 60000.0, "kg"),
        "lf": (0.05, 10.0, "m"),
        "lr": (0.05, 10.0, "m"),
        "vx": (0.5, 120.0, "m/s"),
        "width": (0.1, 4.0, "m"),
        "track": (0.1, 4.0, "m"),
        "h_cg": (0.0, 4.0, "m"),
        "imu_x": (-10.0, 10.0, "m"),
        "camera_x": (-10.0, 10.0, "m"),
    }

    def check_plausible(self) -> "VehicleParams":
        """Raise :class:`ParameterError` naming a value outside its plausible range.

        Absolute ranges for ``m``, ``lf``, ``lr``, ``vx``, ``width``, ``track``, ``h_cg``, ``imu_x``
        (:attr:`PLAUSIBLE`); scale-free checks for the rest: the yaw-inertia ratio
        ``Iz / (m lf lr)`` within 0.2-5 (about 1 for a car), and the per-tire cornering
        stiffness divided by the static load on that tire within 1-100 1/rad (about 10-30
        for road tires). Returns ``self``.
        """
        name = type(self).__name__
        for key, (lo, hi, unit) in self.PLAUSIBLE.items():
            value = getattr(self, key)
            if not lo <= value <= hi:
                raise ParameterError(f"{name}.{key} = {value!r} {unit} is implausible (expected {lo:g}-{hi:g} {unit})")
        ratio = self.Iz / (self.m * self.lf * self.lr)
        if not 0.2 <= ratio <= 5.0:
            raise ParameterError(
                f"{name}.Iz = {self.Iz!r} kg m^2 is implausible for m = {self.m:g} kg, lf = {self.lf:g} m, "
                f"lr = {self.lr:g} m: Iz / (m lf lr) = {ratio:.3g}, expected 0.2-5 (about 1 for a car; "
                f"{0.2 * self.m * self.lf * self.lr:.4g}-{5 * self.m * self.lf * self.lr:.4g} kg m^2)"
            )
        front, rear = self.static_axle_loads
        for key, load in (("Cf", front / 2), ("Cr", rear / 2)):
            value = getattr(self, key)
            coefficient = value / load
            if not 1.0 <= coefficient <= 100.0:
                raise ParameterError(
                    f"{name}.{key} = {value!r} N/rad per tire is implausible for a static tire load of {load:.4g} N: "
                    f"{key} / load = {coefficient:.3g} 1/rad, expected 1-100 (10-30 for road tires; "
                    f"{load:.4g}-{100 * load:.4g} N/rad). {key} is the stiffness of ONE tire in N/rad"
                )
        return self

    @property
    def wheelbase(self) -> float:
        """``L = lf + lr`` [m]."""
        return self.lf + self.lr

    @property
    def static_axle_loads(self) -> tuple[float, float]:
        """Static normal load on the front and rear axle [N]."""
        w = self.m * GRAVITY
        return w * self.lr / self.wheelbase, w * self.lf / self.wheelbase

    @property
    def understeer_gradient(self) -> float:
        """Understeer gradient ``K_us = m (lr/(2Cf) - lf/(2Cr)) / L`` [rad/(m/s^2)]."""
        return self.m * (self.lr / (2 * self.Cf) - self.lf / (2 * self.Cr)) / self.wheelbase


@dataclass(frozen=True)
class TireParams(_Params):
    """Pacejka Magic-Formula lateral tire, per axle, parametrised physically.

    The axle force is ``F_y = D sin(C atan(B a - E (B a - atan(B a))))`` with
    ``D = mu F_z`` (static axle load) and ``B = 2 C_alpha / (C D)`` so that the slope at
    zero slip equals the axle cornering stiffness ``2 C_alpha`` of :class:`VehicleParams`.

    Parameters
    ----------
    mu : float
        Peak friction coefficient [-].
    shape : float
        Magic Formula shape factor ``C`` [-]; ``1 < C < 2`` for lateral force.
    curvature : float
        Magic Formula curvature factor ``E`` [-]; must be ``<= 1``.
    relaxation_length : float
        Tire relaxation length [m]; 0 means slip acts instantly (no lag).
    """

    mu: float = 1.0  # [-]
    shape: float = 1.3  # [-]
    curvature: float = -0.5  # [-]
    relaxation_length: float = 0.0  # [m]

    _positive: ClassVar[tuple[str, ...]] = ("mu",)
    _non_negative: ClassVar[tuple[str, ...]] = ("relaxation_length",)

    def __post_init__(self) -> None:
        super().__post_init__()
        if not 1.0 < self.shape < 2.0:
            raise ParameterError(f"TireParams.shape must be in (1, 2), got {self.shape!r}")
        if not self.curvature <= 1.0:
            raise ParameterError(f"TireParams.curvature must be <= 1, got {self.curvature!r}")


@dataclass(frozen=True)
class RoadParams(_Params):
    """Geometry shared by the built-in roads.

    Parameters
    ----------
    lane_width : float
        Lane width [m].
    transition_length : float
        Length of the clothoid that blends curvature changes [m]; it keeps
        ``psi_ddot_des = vx^2 dkappa/ds`` finite.
    """

    lane_width: float = 3.7  # [m]
    transition_length: float = 30.0  # [m]

    _positive: ClassVar[tuple[str, ...]] = ("lane_width", "transition_length")


_NOISE_KINDS = ("none", "uniform", "gaussian")


@dataclass(frozen=True)
class CameraParams(_Params):
    """Lane-camera measurement model of ``z = [e1, e2]``.

    Parameters
    ----------
    rate : float
        Frame rate [Hz]. Frames arrive at ``t = k / rate``. The paper assumes 1 kHz;
        production cameras deliver 10-30 Hz.
    latency : float
        Delay between the instant a frame shows and the instant it is delivered [s].
    noise : {"none", "uniform", "gaussian"}
        Noise distribution.
    e1_noise : float
        Half-width (uniform) or standard deviation (gaussian) of the ``e1`` noise [m].
    e2_noise : float
        Half-width (uniform) or standard deviation (gaussian) of the ``e2`` noise [rad].
    dropout_probability : float
        Probability that a frame is lost (delivered as NaN) [-].
    e1_bias, e2_bias : float
        Constant measurement offsets [m], [rad] (a mis-calibrated camera).
    """

    rate: float = 1000.0  # [Hz]
    latency: float = 0.0  # [s]
    noise: str = "none"
    e1_noise: float = 0.0  # [m]
    e2_noise: float = 0.0  # [rad]
    dropout_probability: float = 0.0  # [-]
    e1_bias: float = 0.0  # [m]
    e2_bias: float = 0.0  # [rad]

    _positive: ClassVar[tuple[str, ...]] = ("rate",)
    _non_negative: ClassVar[tuple[str, ...]] = ("latency", "e1_noise", "e2_noise", "dropout_probability")

    def __post_init__(self) -> None:
        self._check_types()
        super().__post_init__()
        if self.noise not in _NOISE_KINDS:
            raise ParameterError(f"CameraParams.noise must be one of {_NOISE_KINDS}, got {self.noise!r}")
        if not self.dropout_probability < 1.0:
            raise ParameterError(
                f"CameraParams.dropout_probability must be < 1, got {self.dropout_probability!r}"
            )

    @classmethod
    def paper_noise(cls, rate: float = 1000.0, **kwargs: Any) -> "CameraParams":
        """The paper's Study 3 noise: uniform +/-1 cm on ``e1`` and +/-1 deg on ``e2``."""
        return cls(rate=rate, noise="uniform", e1_noise=0.01, e2_noise=math.radians(1.0), **kwargs)

    @property
    def noise_std(self) -> tuple[float, float]:
        """Standard deviation of the ``e1`` [m] and ``e2`` [rad] noise."""
        if self.noise == "none":
            return 0.0, 0.0
        if self.noise == "uniform":
            return self.e1_noise / math.sqrt(3.0), self.e2_noise / math.sqrt(3.0)
        return self.e1_noise, self.e2_noise


@dataclass(frozen=True)
class DriverParams(_Params):
    """Built-in lane-keeping steering controller (see :mod:`tire_learning_env.driver`).

    ``delta = g_ff(vx) kappa - k (e1 + vx T_la e2) - k_i integral(e1)`` on the *measured*
    ``e1``, ``e2`` (held between frames), with the curvature feed-forward ``g_ff``
    computed from the nominal vehicle so that the steady-state offset on a circle is zero.

    Parameters
    ----------
    gain : float
        Steering per metre of look-ahead offset ``k`` [rad/m].
    lookahead_time : float
        Look-ahead time ``T_la`` [s]; the look-ahead distance is ``vx T_la``.
    integral_gain : float
        Integral gain on ``e1`` [rad/(m s)].
    max_steering : float
        Road-wheel steering saturation [rad].
    """

    gain: float = 0.03  # [rad/m]
    lookahead_time: float = 0.6  # [s]
    integral_gain: float = 0.005  # [rad/(m s)]
    max_steering: float = 0.5  # [rad]

    _positive: ClassVar[tuple[str, ...]] = ("gain", "max_steering")
    _non_negative: ClassVar[tuple[str, ...]] = ("lookahead_time", "integral_gain")

