"""The library of candidate effects: physically named augmentations of the bicycle model.

Each :class:`CandidateEffect` has a stable identifier (``name``, used in ``report.json``
and by ``tire-learning simulate --effect``), named parameters with units and bounds, the
value(s) at which it is absent, and the entries of the augmented model's parameter
vector ``theta`` it sets (:mod:`._model`, ``TH_*``). Applying an effect is
:meth:`CandidateEffect.apply`: a pure function ``theta, values -> theta``.

The physics of every entry (what the compiled model does with it):

=============================  =========================  ============================================
name                           parameters [unit]          augmentation
=============================  =========================  ============================================
``tire_relaxation``            ``relaxation_length`` [m]  slip acts through a first-order lag with time
                                                          constant ``relaxation_length / vx`` (both axles)
``camera_latency``             ``latency`` [s]            a frame delivered at ``t`` shows ``e1, e2``
                                                          at ``t - latency``
``road_bank``                  ``bank_angle`` [rad]       lateral force ``-m g sin(bank_angle)``; the IMU
                                                          (specific force) does not see it
``steering_offset``            ``offset`` [rad]           road-wheel angle = logged ``delta + offset``
``camera_heading_bias``        ``bias`` [rad]             measured ``e2`` = true ``e2 + bias``
``cornering_stiffness_scale``  ``front``, ``rear`` [-]    axle forces multiplied by these factors
``load_transfer``              ``strength`` [-]           both axle forces times ``1 - strength r^2 / 2``,
                                                          ``r = |a_y| h_cg / (g track)``
``crosswind``                  ``force`` [N]              constant lateral force at the CG (the IMU sees it)
``speed_dependent_stiffness``  ``coefficient`` [s^2/m^2]  both axle forces times ``1 - coefficient vx^2``
                                                          (e.g. aerodynamic lift unloading the tires);
                                                          tried only when ``vx`` varies in the log
=============================  =========================  ============================================

Not in the library, by necessity: a constant camera *offset* bias on ``e1`` cannot be
told from an initial lateral offset (``e1`` does not enter the dynamics), so no
dynamic-model comparison can see it.

IMU-only logs (:data:`IMU_LIBRARY`, body-frame model :mod:`._body_model`, channels
``yaw_rate`` and ``ay``) have their own list: the tire, steering and load-transfer effects
a race car's IMU log can show, and the IMU's own errors. Entries whose physics is the same
are the same objects (``tire_relaxation``, ``cornering_stiffness_scale``,
``steering_offset``, ``road_bank``); ``speed_dependent_stiffness`` has the same form with
bounds that keep ``1 - c vx^2`` positive up to 70 m/s. Camera effects have no meaning
without a camera, and ``crosswind`` none on a closed track (the car's heading turns through
the wind every lap).

=================================  ===============================  =========================================
name (IMU)                         parameters [unit]                augmentation of the body-frame model
=================================  ===============================  =========================================
``longitudinal_load_transfer``     ``effective_cg_height`` [m]      axle forces times ``F_z / F_z0``:
                                                                    front ``1 - a_x h / (g lr)``, rear
                                                                    ``1 + a_x h / (g lf)``
``lateral_load_transfer``          ``front``, ``rear`` [-]          axle force times ``1 - k (a_y / g)^2``
                                                                    (loss at 1 g per axle)
``steering_compliance``            ``compliance`` [rad/N]           road-wheel angle ``delta - c F_yf``
``steering_ratio_nonlinearity``    ``quickening`` [-]               road-wheel angle
                                                                    ``delta (1 + q (delta / 0.1 rad)^2)``
``steering_delay``                 ``delay`` [s]                    road wheels follow the logged steering
                                                                    ``delay`` seconds later
``yaw_rate_bias``                  ``bias`` [rad/s]                 measured yaw rate = ``r + bias``
``ay_bias``                        ``bias`` [m/s^2]                 measured ``a_y`` = true + ``bias``
``ay_scale``                       ``scale_error`` [-]              measured ``a_y`` = (1 + ``scale_error``) true
                                                                    (body roll: ``g`` times the roll gradient)
``accelerometer_offset``           ``distance`` [m]                 accelerometer ``distance`` ahead of the CG:
                                                                    measured ``a_y`` + ``distance r_dot``
``yaw_inertia_scale``              ``scale`` [-]                    yaw inertia ``Iz`` times ``scale``
=================================  ===============================  =========================================

What an IMU-only log cannot separate (:data:`IMU_CONFOUNDED`; the workflow also measures
the correlation of every pair of candidate signatures on the log itself and reports the
close ones as ``indistinguishable_from``): a bank angle equals an ``a_y`` bias plus a
steering offset in steady state; steering compliance equals a front stiffness scale with
a linear front tire; a yaw-rate bias ``b`` looks like a steering offset ``L b / vx``
(separated only by the speed variation); lateral load transfer is a function of ``a_y``,
which a tire curve learned as a function of slip largely absorbs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
from numpy.typing import NDArray

from ._model import (
    TH_ACC_OFFSET,
    TH_AY_BIAS,
    TH_AY_SCALE,
    TH_IZ_SCALE,
    TH_LAT_LT_F,
    TH_LAT_LT_R,
    TH_LONG_LT,
    TH_STEER_COMP,
    TH_STEER_DELAY,
    TH_STEER_QUICK,
    TH_YAW_BIAS,
    THETA_NOMINAL,
    TH_BANK,
    TH_E2_BIAS,
    TH_LATENCY,
    TH_LOAD_TRANSFER,
    TH_RELAX,
    TH_SCALE_F,
    TH_SCALE_R,
    TH_SPEED_COEF,
    TH_STEER_OFFSET,
    TH_WIND,
    TH_SUPER_RATE,
    TH_SUPER_CAP,
    TH_E2_DRIFT,
    TH_STEER_RATIO,
)

__all__ = [
    "CandidateEffect",
    "LIBRARY",
    "EFFECT_NAMES",
    "IMU_LIBRARY",
    "IMU_EFFECT_NAMES",
    "IMU_CONFOUNDED",
    "library_for",
    "get_effect",
    "theta_of",
]


@dataclass(frozen=True)
class CandidateEffect:
    """One physically named model augmentation.

    Attributes
    ----------
    name : str
        Stable identifier.
    description : str
        What it is, physically.
    parameters : tuple of str
        Parameter names.
    units : tuple of str
        Unit of each parameter.
    theta_index : tuple of int
        Entry of ``theta`` each parameter sets.
    bounds : tuple of (float, float)
        Search bounds of each parameter.
    scale : tuple of float
        Typical size of each parameter (optimizer scaling; also the finite-difference scale).
    absent : tuple of float
        Values at which the effect is absent (the nominal model).
    starts : tuple of tuple of float
        Starting points tried by the fit (the best by cost is refined).
    needs_speed_variation : bool
        Only identifiable when the speed varies in the log.
    kink_start : callable, optional
        ``kink_start(values, data) -> values or None``: for an effect with a limit (a ``min``), a start at
        which the limit is active when the fitted ``values`` leave it inactive on this log (``data``,
        :class:`.data.ModelData`). An inactive limit has no gradient, so the fit cannot find out from there
        whether an active one fits better; :func:`.selection.fit_effects` then fits again from this start and
        keeps the better fit.
    """

    name: str
    description: str
    parameters: tuple[str, ...]
    units: tuple[str, ...]
    theta_index: tuple[int, ...]
    bounds: tuple[tuple[float, float], ...]
    scale: tuple[float, ...]
    absent: tuple[float, ...]
    starts: tuple[tuple[float, ...], ...]
    needs_speed_variation: bool = False
    kink_start: Callable[[NDArray, Any], NDArray | None] | None = None

    @property
    def n_parameters(self) -> int:
        return len(self.parameters)

    def apply(self, theta: NDArray, values) -> NDArray:
        """``theta`` with this effect's parameters set to ``values`` (a copy)."""
        out = np.array(theta, dtype=float)
        values = np.atleast_1d(np.asarray(values, dtype=float))
        if values.shape != (self.n_parameters,):
            raise ValueError(f"{self.name} takes {self.n_parameters} parameter(s), got {values.shape}")
        for i, v in zip(self.theta_index, values):
            out[i] = v
        return out

    def values_in(self, theta: NDArray) -> NDArray:
        """This effect's parameter values in ``theta``."""
        return np.array([theta[i] for i in self.theta_index], dtype=float)

    def as_dict(self, values) -> dict[str, float]:
        return {p: float(v) for p, v in zip(self.parameters, np.atleast_1d(values))}

    def units_dict(self) -> dict[str, str]:
        return dict(zip(self.parameters, self.units))

    def size(self, values) -> NDArray:
        """Deviation from absence per parameter (the 'effect size')."""
        return np.atleast_1d(np.asarray(values, dtype=float)) - np.asarray(self.absent)


def _superelevation_cap_start(values: NDArray, data) -> NDArray | None:
    """A start whose cap binds in the log's sharpest curves (0.9 x rate x largest |kappa|) when the fitted cap is
    above every bank the fitted rate gives on this log (None when it binds, or without superelevation)."""
    rate, cap = float(values[0]), float(values[1])
    kappa = getattr(data, "kappa", None)
    if kappa is None or not len(kappa) or rate <= 0.0:
        return None
    reach = rate * float(np.max(np.abs(kappa)))
    if not reach > 0.0 or cap < reach:
        return None
    return np.array([rate, max(0.9 * reach, 0.005)])


def _one(name, description, parameter, unit, index, bounds, scale, starts, absent=0.0, speed=False) -> CandidateEffect:
    return CandidateEffect(
        name, description, (parameter,), (unit,), (index,), (bounds,), (scale,), (absent,),
        tuple((s,) for s in starts), speed,
    )  # fmt: skip


#: The candidate library, in the order the report lists them.
LIBRARY: tuple[CandidateEffect, ...] = (
    _one("tire_relaxation", "tire relaxation length: lateral force lags the slip angle by a first-order lag of time "
         "constant relaxation_length / vx (both axles)", "relaxation_length", "m", TH_RELAX, (0.0, 3.0), 0.5,
         (0.3, 1.0)),
    _one("camera_latency", "camera latency: a frame shows e1, e2 this long before it is delivered", "latency", "s",
         TH_LATENCY, (0.0, 0.3), 0.05, (0.03, 0.1, 0.2)),
    _one("road_bank", "road bank angle (positive raises the left edge): gravity pulls the car sideways with "
         "-m g sin(bank_angle); the accelerometer does not feel it", "bank_angle", "rad", TH_BANK, (-0.2, 0.2), 0.01,
         (0.0,)),
    _one("steering_offset", "steering-angle offset: the road wheels point offset rad away from the logged delta",
         "offset", "rad", TH_STEER_OFFSET, (-0.05, 0.05), 0.001, (0.0,)),
    _one("camera_heading_bias", "camera heading bias: the measured heading error is the true one plus bias",
         "bias", "rad", TH_E2_BIAS, (-0.05, 0.05), 0.001, (0.0,)),
    CandidateEffect(
        "cornering_stiffness_scale",
        "cornering-stiffness error: the front and rear axle forces are the nominal ones times these factors",
        ("front", "rear"), ("-", "-"), (TH_SCALE_F, TH_SCALE_R), ((0.3, 2.0), (0.3, 2.0)), (0.1, 0.1), (1.0, 1.0),
        ((1.0, 1.0),),
    ),
    _one("load_transfer", "lateral load transfer with load-sensitive tires: both axle forces drop by "
         "strength r^2 / 2, r = |a_y| h_cg / (g track)", "strength", "-", TH_LOAD_TRANSFER, (0.0, 100.0), 5.0,
         (3.0, 10.0, 30.0)),
    _one("crosswind", "constant lateral disturbance force at the centre of gravity (crosswind; positive to the "
         "left); the accelerometer feels it", "force", "N", TH_WIND, (-5000.0, 5000.0), 100.0, (0.0,)),
    _one("speed_dependent_stiffness", "tire forces that change with speed: both axle forces times "
         "1 - coefficient vx^2 (e.g. aerodynamic lift unloading the tires)", "coefficient", "s^2/m^2",
         TH_SPEED_COEF, (-1e-3, 1e-3), 5e-5, (0.0,), speed=True),
    CandidateEffect(
        "road_superelevation",
        "superelevation of the curves (road design): the outer edge is raised by min(rate |kappa|, cap) with kappa "
        "the path curvature, so gravity pulls the car towards the inside of the curve with m g sin(bank); the "
        "accelerometer does not feel it (adds to a constant crossfall, road_bank)",
        ("rate", "cap"), ("rad m", "rad"), (TH_SUPER_RATE, TH_SUPER_CAP), ((0.0, 60.0), (0.005, 0.15)), (5.0, 0.02),
        (0.0, 0.1),
        # the cap has no gradient where it does not bind: a grid of starts over the road-design range
        # (caps 1.7-6.9 deg, reached from R = 100-2000 m) so the fit starts in the right basin
        tuple((r, c) for r in (6.0, 12.0, 25.0, 50.0) for c in (0.03, 0.045, 0.06, 0.09, 0.12)),
        kink_start=_superelevation_cap_start,
    ),
    _one("camera_heading_drift", "camera heading bias that drifts slowly: measured e2 = true e2 + drift_rate "
         "(t - t_mid), t_mid the middle of the log, on top of any constant camera_heading_bias (e.g. a camera mount "
         "warming up)", "drift_rate", "rad/s", TH_E2_DRIFT, (-1e-3, 1e-3), 2e-5, (0.0,)),
    _one("steering_ratio_error", "steering-ratio error: the road wheels turn (1 + ratio_error) times the logged "
         "delta (a wrong steering-ratio calibration, or compliance proportional to the angle)", "ratio_error", "-",
         TH_STEER_RATIO, (-0.3, 0.3), 0.02, (0.0,)),
)

EFFECT_NAMES: tuple[str, ...] = tuple(e.name for e in LIBRARY)


def _camera(name: str) -> CandidateEffect:
    return next(e for e in LIBRARY if e.name == name)


#: The candidate library of IMU-only logs (body-frame model), in the order the report lists them.
IMU_LIBRARY: tuple[CandidateEffect, ...] = (
    _camera("tire_relaxation"),
    _camera("cornering_stiffness_scale"),
    _one("longitudinal_load_transfer", "longitudinal load transfer: the axle forces follow the axle loads, front "
         "times 1 - a_x h / (g lr), rear times 1 + a_x h / (g lf) (braking loads the front); h is an effective CG "
         "height: the CG height times the load sensitivity of the axle force (1 = proportional)",
         "effective_cg_height", "m", TH_LONG_LT, (-1.0, 2.0), 0.1, (0.0, 0.3)),
    CandidateEffect(
        "lateral_load_transfer",
        "lateral load transfer with load-sensitive tires: each axle force drops by k (a_y / g)^2 (front and rear k "
        "differ with the roll-stiffness distribution; the loss at 1 g)",
        ("front", "rear"), ("-", "-"), (TH_LAT_LT_F, TH_LAT_LT_R), ((-0.5, 0.9), (-0.5, 0.9)), (0.05, 0.05),
        (0.0, 0.0), ((0.0, 0.0), (0.1, 0.1)),
    ),
    _camera("steering_offset"),
    _one("steering_compliance", "steering compliance: the road wheels turn back by compliance times the front axle "
         "force (aligning moment against a compliant steering column and mounts)", "compliance", "rad/N",
         TH_STEER_COMP, (0.0, 1e-5), 5e-7, (1e-6,)),
    _one("steering_ratio_nonlinearity", "steering-ratio nonlinearity: road-wheel angle delta (1 + quickening "
         "(delta / 0.1 rad)^2), i.e. the ratio is 1 + quickening times quicker at 0.1 rad than on centre",
         "quickening", "-", TH_STEER_QUICK, (-0.5, 1.0), 0.05, (0.0,)),
    _one("steering_delay", "steering signal delay: the road wheels follow the logged steering delay seconds later "
         "(sensor synchronisation; negative: the steering is logged late)", "delay", "s", TH_STEER_DELAY,
         (-0.1, 0.25), 0.01, (0.02, 0.05, -0.02)),
    _one("yaw_rate_bias", "yaw-rate sensor bias: the gyro reads the yaw rate plus bias", "bias", "rad/s",
         TH_YAW_BIAS, (-0.05, 0.05), 0.001, (0.0,)),
    _one("ay_bias", "lateral accelerometer bias (or a sensor roll misalignment on a level road): the accelerometer "
         "reads the lateral specific force plus bias", "bias", "m/s^2", TH_AY_BIAS, (-2.0, 2.0), 0.05, (0.0,)),
    _one("ay_scale", "lateral accelerometer scale error: the accelerometer reads (1 + scale_error) a_y; a body-fixed "
         "accelerometer that rolls with the body by phi = k a_y reads a_y + g sin(phi), i.e. scale_error = g k "
         "(0.03 = a roll gradient of 1.7 deg/g), or a calibration error", "scale_error", "-", TH_AY_SCALE,
         (-0.3, 0.3), 0.01, (0.0,)),
    _camera("road_bank"),
    _one("accelerometer_offset", "accelerometer mounted distance ahead of the CG (or a CG position error): it reads "
         "a_y + distance r_dot", "distance", "m", TH_ACC_OFFSET, (-3.0, 3.0), 0.1, (0.0,)),
    _one("yaw_inertia_scale", "yaw moment of inertia error: Iz times scale", "scale", "-", TH_IZ_SCALE, (0.3, 3.0), 0.1,
         (1.0, 1.5), absent=1.0),
    _one("speed_dependent_stiffness", "tire forces that change with speed: both axle forces times "
         "1 - coefficient vx^2 (aerodynamic lift unloads the tires, downforce (negative coefficient) loads them)",
         "coefficient", "s^2/m^2", TH_SPEED_COEF, (-2e-4, 2e-4), 2e-5, (0.0,), speed=True),
)

IMU_EFFECT_NAMES: tuple[str, ...] = tuple(e.name for e in IMU_LIBRARY)

#: effect pairs an IMU-only log cannot (or can hardly) tell apart, and why
IMU_CONFOUNDED: dict[frozenset, str] = {
    frozenset({"ay_bias", "road_bank"}): (
        "in steady state a bank angle acts as an a_y bias of -g sin(bank) plus a steering offset of -K g sin(bank) "
        "(K the understeer gradient); only transients at varying speed and the tire nonlinearity separate them"
    ),
    frozenset({"steering_offset", "road_bank"}): (
        "a bank angle shifts the slip balance like a steering offset (and the a_y level like an a_y bias)"
    ),
    frozenset({"steering_compliance", "cornering_stiffness_scale"}): (
        "with a linear front tire a steering compliance c is exactly a front stiffness scale 1 / (1 + 2 Cf c); "
        "only the tire nonlinearity separates them"
    ),
    frozenset({"yaw_rate_bias", "steering_offset"}): (
        "a yaw-rate bias b shifts the kinematic steering delta - L r / vx like a steering offset L b / vx; only the "
        "speed variation separates them"
    ),
}


def library_for(kind: str) -> tuple[CandidateEffect, ...]:
    """The candidate library of a log kind: ``"camera"`` (:data:`LIBRARY`) or ``"imu"`` (:data:`IMU_LIBRARY`)."""
    if kind == "camera":
        return LIBRARY
    if kind == "imu":
        return IMU_LIBRARY
    raise ValueError(f"log kind must be 'camera' or 'imu', got {kind!r}")


def get_effect(name: str, kind: str | None = None) -> CandidateEffect:
    """The library entry called ``name`` (``KeyError`` naming the known ones otherwise).

    ``kind`` (``"camera"`` / ``"imu"``) picks the library; by default the camera library
    is searched first, then the IMU library.
    """
    libraries = (LIBRARY, IMU_LIBRARY) if kind is None else (library_for(kind),)
    for lib in libraries:
        for e in lib:
            if e.name == name:
                return e
    known = list(EFFECT_NAMES) if kind == "camera" else list(IMU_EFFECT_NAMES) if kind == "imu" else list(
        dict.fromkeys(EFFECT_NAMES + IMU_EFFECT_NAMES)
    )
    raise KeyError(f"unknown effect {name!r}; the library has {known}")


def theta_of(effects: dict[str, NDArray] | None = None, kind: str | None = None) -> NDArray:
    """``theta`` of the nominal model with the given ``{name: values}`` effects applied."""
    theta = THETA_NOMINAL.copy()
    for name, values in (effects or {}).items():
        theta = get_effect(name, kind).apply(theta, values)
    return theta
