"""Parameter sets of the high-order (multi-body) truth vehicle, in SI units.

The vehicle is CommonRoad's multi-body model (Althoff & Würsching, *CommonRoad: Vehicle
Models*, 2020, Sec. 5 and Tab. 6-7; package ``commonroad-vehicle-models`` 3.0.2,
``vehiclemodels/parameters/parameters_vehicle2.yaml`` and ``parameters_tire.yaml``).
Field names follow CommonRoad's (``a``, ``b``, ``K_zt``, ``p_ky1``, ...) so a set can be
read from CommonRoad's own objects (:meth:`MultiBodyParams.from_commonroad`).

Every field is required: building a set from a mapping with a field missing, unknown or
inconsistent (e.g. ``m != m_s + m_uf + m_ur``) raises
:class:`~tire_learning_env.params.ParameterError` naming the field.

:data:`COMMONROAD_VEHICLE2` / :data:`COMMONROAD_TIRE` are CommonRoad's vehicle 2 (a BMW 320i,
a D-segment sedan) and its ADAMS-handbook PAC2002 tire, copied verbatim (a test checks
them against the installed package); :func:`bmw_320i` builds them.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, fields
from typing import Any, ClassVar, Mapping

from ..params import ParameterError, _Params, check_keys

__all__ = [
    "SteeringLimits",
    "LongitudinalLimits",
    "Pac2002Tire",
    "MultiBodyParams",
    "HighOrderConfig",
    "COMMONROAD_VEHICLE2",
    "COMMONROAD_TIRE",
    "bmw_320i",
]


def _required(cls: type, data: Mapping[str, Any]) -> None:
    """Raise :class:`ParameterError` naming every required field of ``cls`` missing from ``data``."""
    missing = [f.name for f in fields(cls) if f.name not in data]
    if missing:
        raise ParameterError(f"{cls.__name__}: missing field(s) {missing}")


class _StrictParams(_Params):
    """:class:`_Params` whose ``from_dict`` names missing fields and accepts nested dicts."""

    _nested: ClassVar[dict[str, type]] = {}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]):  # type: ignore[override]
        if not isinstance(data, Mapping):
            raise ParameterError(f"{cls.__name__}: expected a mapping, got {type(data).__name__}")
        check_keys(cls.__name__, data, [f.name for f in fields(cls)])  # type: ignore[arg-type]
        _required(cls, data)
        values = dict(data)
        for name, sub in cls._nested.items():
            if isinstance(values[name], Mapping):
                try:
                    values[name] = sub.from_dict(values[name])
                except ParameterError as exc:
                    raise ParameterError(f"{cls.__name__}.{name}: {exc}") from exc
            elif not isinstance(values[name], sub):
                raise ParameterError(f"{cls.__name__}.{name} must be a {sub.__name__} or a mapping")
        for f in fields(cls):  # type: ignore[arg-type]
            if f.name in cls._nested:
                continue
            v = values[f.name]
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ParameterError(f"{cls.__name__}.{f.name} must be a number, got {v!r}")
        return cls(**values)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)  # type: ignore[call-overload]


@dataclass(frozen=True)
class SteeringLimits(_StrictParams):
    """Road-wheel steering limits (CommonRoad ``steering``).

    Parameters
    ----------
    min, max : float
        Steering angle limits [rad].
    v_min, v_max : float
        Steering rate limits [rad/s] (used by the steering servo only).
    """

    min: float  # [rad]
    max: float  # [rad]
    v_min: float  # [rad/s]
    v_max: float  # [rad/s]

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.min < 0.0 < self.max:
            raise ParameterError(f"SteeringLimits: need min < 0 < max, got min={self.min!r}, max={self.max!r}")
        if not self.v_min < 0.0 < self.v_max:
            raise ParameterError(f"SteeringLimits: need v_min < 0 < v_max, got v_min={self.v_min!r}, v_max={self.v_max!r}")


@dataclass(frozen=True)
class LongitudinalLimits(_StrictParams):
    """Longitudinal limits (CommonRoad ``longitudinal``; its acceleration constraint).

    Parameters
    ----------
    v_min, v_max : float
        Speed limits [m/s].
    v_switch : float
        Speed above which the drive acceleration limit falls as ``a_max v_switch / v`` [m/s].
    a_max : float
        Maximum absolute acceleration [m/s^2].
    """

    v_min: float  # [m/s]
    v_max: float  # [m/s]
    v_switch: float  # [m/s]
    a_max: float  # [m/s^2]

    _positive: ClassVar[tuple[str, ...]] = ("v_switch", "a_max", "v_max")

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.v_min < self.v_max:
            raise ParameterError(f"LongitudinalLimits: need v_min < v_max, got {self.v_min!r}, {self.v_max!r}")


@dataclass(frozen=True)
class Pac2002Tire(_StrictParams):
    """The PAC2002 subset of CommonRoad's tire model (``utils/tire_model.py``), per tire.

    Scaling factors are 1 and turn slip is neglected, as in CommonRoad. Sign convention
    (CommonRoad/ISO): slip angle ``alpha = atan(v_y / v_x) - delta`` and the lateral force
    ``F_y`` is negative for positive ``alpha``, hence ``p_ky1 < 0``. Longitudinal slip
    ``s = 1 - R_w omega / u`` (negative when driving). Cornering stiffness and peak force
    are proportional to load (``K_y = p_ky1 F_z``, ``D_y = mu_y F_z``): CommonRoad's
    simplification of PAC2002.

    Coefficients (all [-] unless stated): longitudinal ``p_cx1, p_dx1, p_dx3 [1/rad^2],
    p_ex1, p_kx1, p_hx1, p_vx1, r_bx1, r_bx2, r_cx1, r_ex1, r_hx1 [rad]``; lateral
    ``p_cy1, p_dy1, p_dy3 [1/rad^2], p_ey1, p_ky1 [1/rad], p_hy1 [rad], p_hy3, p_vy1,
    p_vy3 [1/rad], r_by1, r_by2, r_by3 [rad], r_cy1, r_ey1, r_hy1, r_vy1, r_vy3 [1/rad],
    r_vy4, r_vy5, r_vy6``. See CommonRoad Tab. 7 for their meaning.
    """

    p_cx1: float
    p_dx1: float
    p_dx3: float
    p_ex1: float
    p_kx1: float
    p_hx1: float
    p_vx1: float
    r_bx1: float
    r_bx2: float
    r_cx1: float
    r_ex1: float
    r_hx1: float
    p_cy1: float
    p_dy1: float
    p_dy3: float
    p_ey1: float
    p_ky1: float
    p_hy1: float
    p_hy3: float
    p_vy1: float
    p_vy3: float
    r_by1: float
    r_by2: float
    r_by3: float
    r_cy1: float
    r_ey1: float
    r_hy1: float
    r_vy1: float
    r_vy3: float
    r_vy4: float
    r_vy5: float
    r_vy6: float

    _positive: ClassVar[tuple[str, ...]] = ("p_cx1", "p_dx1", "p_kx1", "p_cy1", "p_dy1", "r_cx1", "r_cy1")

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.p_ky1 < 0:
            raise ParameterError(
                f"Pac2002Tire.p_ky1 must be < 0 (CommonRoad's sign convention: F_y < 0 for alpha > 0), got {self.p_ky1!r}"
            )
        for name in ("p_ex1", "p_ey1"):
            if not getattr(self, name) <= 1.0:
                raise ParameterError(f"Pac2002Tire.{name} must be <= 1 (Magic Formula curvature), got {getattr(self, name)!r}")
        if not self.p_cy1 < 2.0:
            raise ParameterError(f"Pac2002Tire.p_cy1 must be < 2 (lateral shape factor), got {self.p_cy1!r}")


@dataclass(frozen=True)
class MultiBodyParams(_StrictParams):
    """CommonRoad multi-body vehicle (their ``VehicleParameters`` used by ``vehicle_dynamics_mb``).

    Reference point: the sprung-mass centre of gravity. Units: SI (see the field
    comments; CommonRoad's own documentation names each field, e.g. ``K_zt`` = vertical
    tire spring rate [N/m]).
    """

    l: float  # vehicle length [m]
    w: float  # vehicle width [m]
    m: float  # total mass [kg]
    m_s: float  # sprung mass [kg]
    m_uf: float  # unsprung mass front [kg]
    m_ur: float  # unsprung mass rear [kg]
    a: float  # sprung-mass CG to front axle [m]
    b: float  # sprung-mass CG to rear axle [m]
    I_Phi_s: float  # sprung-mass roll inertia [kg m^2]
    I_y_s: float  # sprung-mass pitch inertia [kg m^2]
    I_z: float  # yaw inertia [kg m^2]
    I_xz_s: float  # roll-yaw product of inertia [kg m^2]
    K_sf: float  # suspension spring rate front [N/m]
    K_sdf: float  # suspension damping rate front [N s/m]
    K_sr: float  # suspension spring rate rear [N/m]
    K_sdr: float  # suspension damping rate rear [N s/m]
    T_f: float  # track width front [m]
    T_r: float  # track width rear [m]
    K_ras: float  # lateral spring rate of the compliant pin joint sprung/unsprung [N/m]
    K_tsf: float  # auxiliary torsion roll stiffness front [N m/rad]
    K_tsr: float  # auxiliary torsion roll stiffness rear [N m/rad]
    K_rad: float  # damping rate of the compliant pin joint [N s/m]
    K_zt: float  # vertical tire spring rate [N/m]
    h_cg: float  # CG height of the total mass [m]
    h_raf: float  # roll-axis height front [m]
    h_rar: float  # roll-axis height rear [m]
    h_s: float  # sprung-mass CG height [m]
    I_uf: float  # unsprung-mass roll inertia front [kg m^2]
    I_ur: float  # unsprung-mass roll inertia rear [kg m^2]
    I_y_w: float  # wheel spin inertia [kg m^2]
    K_lt: float  # lateral compliance of tire, wheel and suspension, per tire [m/N]
    R_w: float  # effective wheel radius [m]
    T_sb: float  # brake torque share of the front axle [-]
    T_se: float  # engine torque share of the front axle [-]
    D_f: float  # roll-camber coefficient front [rad/m]
    D_r: float  # roll-camber coefficient rear [rad/m]
    E_f: float  # quadratic camber coefficient front [rad/m^2]
    E_r: float  # quadratic camber coefficient rear [rad/m^2]
    steering: SteeringLimits
    longitudinal: LongitudinalLimits
    tire: Pac2002Tire

    _nested: ClassVar[dict[str, type]] = {
        "steering": SteeringLimits,
        "longitudinal": LongitudinalLimits,
        "tire": Pac2002Tire,
    }
    _positive: ClassVar[tuple[str, ...]] = (
        "l", "w", "m", "m_s", "m_uf", "m_ur", "a", "b", "I_Phi_s", "I_y_s", "I_z", "K_sf", "K_sr",
        "T_f", "T_r", "K_ras", "K_zt", "h_cg", "h_s", "I_uf", "I_ur", "I_y_w", "R_w",
    )  # fmt: skip
    _non_negative: ClassVar[tuple[str, ...]] = ("K_sdf", "K_sdr", "K_rad", "K_lt")

    def __post_init__(self) -> None:
        super().__post_init__()
        for name, sub in self._nested.items():
            if not isinstance(getattr(self, name), sub):
                raise ParameterError(f"MultiBodyParams.{name} must be a {sub.__name__}, got {type(getattr(self, name)).__name__}")
        total = self.m_s + self.m_uf + self.m_ur
        if not math.isclose(self.m, total, rel_tol=1e-6):
            raise ParameterError(
                f"MultiBodyParams.m = {self.m!r} kg is inconsistent with m_s + m_uf + m_ur = {total!r} kg"
            )
        if not self.I_xz_s**2 < self.I_Phi_s * self.I_z:
            raise ParameterError("MultiBodyParams.I_xz_s: need I_xz_s^2 < I_Phi_s I_z (positive definite inertia)")
        for name in ("T_sb", "T_se"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ParameterError(f"MultiBodyParams.{name} is a torque share and must be in [0, 1], got {getattr(self, name)!r}")
        if not self.l > self.a + self.b:
            raise ParameterError(f"MultiBodyParams.l = {self.l!r} m must exceed the wheelbase a + b = {self.a + self.b!r} m")
        if not self.w > max(self.T_f, self.T_r):
            raise ParameterError(f"MultiBodyParams.w = {self.w!r} m must exceed the track widths T_f, T_r")
        if not self.h_s > self.R_w:
            raise ParameterError(f"MultiBodyParams.h_s = {self.h_s!r} m must exceed the wheel radius R_w = {self.R_w!r} m")

    @property
    def wheelbase(self) -> float:
        """``a + b`` [m]."""
        return self.a + self.b

    @classmethod
    def from_commonroad(cls, source: Any = 2) -> "MultiBodyParams":
        """Read a CommonRoad parameter object, or vehicle id ``1``-``3`` (needs ``commonroad-vehicle-models``).

        Only the fields ``vehicle_dynamics_mb`` uses are read; a missing or ``None``
        field raises :class:`ParameterError` naming it.
        """
        if isinstance(source, int):
            try:
                from vehiclemodels.vehicle_parameters import setup_vehicle_parameters
            except ImportError as exc:  # pragma: no cover - optional dependency
                raise ParameterError("reading a CommonRoad vehicle id needs `pip install commonroad-vehicle-models`") from exc
            source = setup_vehicle_parameters(vehicle_id=source)

        def pick(obj: Any, sub: type, prefix: str) -> dict[str, Any]:
            out = {}
            for f in fields(sub):
                value = getattr(obj, f.name, None)
                if value is None:
                    raise ParameterError(f"CommonRoad parameters: missing field {prefix}{f.name}")
                out[f.name] = float(value)
            return out

        data: dict[str, Any] = {}
        for f in fields(cls):
            if f.name in cls._nested:
                data[f.name] = pick(getattr(source, f.name, None), cls._nested[f.name], f"{f.name}.")
            else:
                value = getattr(source, f.name, None)
                if value is None:
                    raise ParameterError(f"CommonRoad parameters: missing field {f.name}")
                data[f.name] = float(value)
        return cls.from_dict(data)


@dataclass(frozen=True)
class HighOrderConfig(_Params):
    """Options of the high-order truth plant that are not part of CommonRoad's model.

    Parameters
    ----------
    relaxation_length : float
        Tire relaxation length [m]: each wheel's slip angle acts on its force through a
        first-order lag ``sigma dalpha'/dt = |u_w| (alpha - alpha')`` (``u_w`` the wheel's
        longitudinal speed). 0 disables it (CommonRoad's original, instantaneous slip).
    steering_time_constant : float
        Steering servo time constant [s]. 0 (default): the road-wheel angle equals the
        commanded angle, held over each step (like the bicycle plant). > 0: CommonRoad's
        steering-rate input is ``(delta_cmd - delta) / T`` within its rate limits.
    speed_kp : float
        Proportional gain of the PI speed controller [1/s] (acceleration command per m/s).
    speed_ki : float
        Integral gain of the PI speed controller [1/s^2].
    symmetric_tire : bool
        Zero CommonRoad's ``p_hy1`` and ``p_vy1`` (see :mod:`tire_learning_env.high_order`):
        CommonRoad multiplies these constant PAC2002 shifts by ``sign(camber)``, which puts
        a jump of ``2 p_vy1 F_z`` per axle into the lateral force at zero camber, i.e. at
        the static equilibrium. ``False`` keeps CommonRoad's formula exactly.
    """

    relaxation_length: float = 0.45  # [m]
    steering_time_constant: float = 0.0  # [s]
    speed_kp: float = 1.0  # [1/s]
    speed_ki: float = 0.25  # [1/s^2]
    symmetric_tire: bool = True

    _positive: ClassVar[tuple[str, ...]] = ("speed_kp",)
    _non_negative: ClassVar[tuple[str, ...]] = ("relaxation_length", "steering_time_constant", "speed_ki")

    def __post_init__(self) -> None:
        super().__post_init__()
        if not isinstance(self.symmetric_tire, bool):
            raise ParameterError(f"HighOrderConfig.symmetric_tire must be a bool, got {self.symmetric_tire!r}")


#: CommonRoad ``parameters_vehicle2.yaml`` (BMW 320i), fields used by the multi-body model.
COMMONROAD_VEHICLE2: dict[str, Any] = {
    "l": 4.508,
    "w": 1.61,
    "m": 1093.2952334674046,
    "m_s": 965.7108098804363,
    "m_uf": 63.7921826056784,
    "m_ur": 63.7921826056784,
    "a": 1.1561957064,
    "b": 1.4227170936,
    "I_Phi_s": 207.26524557936952,
    "I_y_s": 1565.8178787125541,
    "I_z": 1791.5995300122856,
    "I_xz_s": 0.0,
    "K_sf": 24453.137879749014,
    "K_sdf": 1786.2441002440723,
    "K_sr": 19635.504745231297,
    "K_sdr": 1649.0833034887382,
    "T_f": 1.38684,
    "T_r": 1.36398,
    "K_ras": 175186.65943700788,
    "K_tsf": -6914.881688272133,
    "K_tsr": -2643.6009520155308,
    "K_rad": 10215.732056044453,
    "K_zt": 158294.1398119115,
    "h_cg": 0.5748689544000001,
    "h_raf": 0.0,
    "h_rar": 0.0,
    "h_s": 0.61373004,
    "I_uf": 30.673279563178017,
    "I_ur": 29.670408143156248,
    "I_y_w": 1.7,
    "K_lt": 1.6430724599974725e-05,
    "R_w": 0.344,
    "T_sb": 0.66,
    "T_se": 0.0,
    "D_f": -0.39370078740157477,
    "D_r": -0.905511811023622,
    "E_f": 0.0,
    "E_r": 0.0,
    "steering": {"min": -1.066, "max": 1.066, "v_min": -0.4, "v_max": 0.4},
    "longitudinal": {"v_min": -13.9, "v_max": 50.8, "v_switch": 7.319, "a_max": 11.5},
}

#: CommonRoad ``parameters_tire.yaml`` (PAC2002 coefficients from the ADAMS handbook).
COMMONROAD_TIRE: dict[str, float] = {
    "p_cx1": 1.6411,
    "p_dx1": 1.1739,
    "p_dx3": 0.0,
    "p_ex1": 0.46403,
    "p_kx1": 22.303,
    "p_hx1": 0.0012297,
    "p_vx1": -8.8098e-06,
    "r_bx1": 13.276,
    "r_bx2": -13.778,
    "r_cx1": 1.2568,
    "r_ex1": 0.65225,
    "r_hx1": 0.0050722,
    "p_cy1": 1.3507,
    "p_dy1": 1.0489,
    "p_dy3": -2.8821,
    "p_ey1": -0.0074722,
    "p_ky1": -21.92,
    "p_hy1": 0.0026747,
    "p_hy3": 0.031415,
    "p_vy1": 0.037318,
    "p_vy3": -0.32931,
    "r_by1": 7.1433,
    "r_by2": 9.1916,
    "r_by3": -0.027856,
    "r_cy1": 1.0719,
    "r_ey1": -0.27572,
    "r_hy1": 5.7448e-06,
    "r_vy1": -0.027825,
    "r_vy3": -0.27568,
    "r_vy4": 12.12,
    "r_vy5": 1.9,
    "r_vy6": -10.704,
}


def bmw_320i() -> MultiBodyParams:
    """CommonRoad vehicle 2 (BMW 320i, D-segment sedan) with CommonRoad's PAC2002 tire."""
    return MultiBodyParams.from_dict(dict(COMMONROAD_VEHICLE2, tire=dict(COMMONROAD_TIRE)))
