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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ._model import (
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
)

__all__ = ["CandidateEffect", "LIBRARY", "EFFECT_NAMES", "get_effect", "theta_of"]


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
)

EFFECT_NAMES: tuple[str, ...] = tuple(e.name for e in LIBRARY)


def get_effect(name: str) -> CandidateEffect:
    """The library entry called ``name`` (``KeyError`` naming the known ones otherwise)."""
    for e in LIBRARY:
        if e.name == name:
            return e
    raise KeyError(f"unknown effect {name!r}; the library has {list(EFFECT_NAMES)}")


def theta_of(effects: dict[str, NDArray] | None = None) -> NDArray:
    """``theta`` of the nominal model with the given ``{name: values}`` effects applied."""
    theta = THETA_NOMINAL.copy()
    for name, values in (effects or {}).items():
        theta = get_effect(name).apply(theta, values)
    return theta
