"""Axle lateral tire models: linear and Pacejka Magic Formula.

A tire model here is an *axle* model: it maps the axle slip angle ``alpha`` [rad] to the
axle lateral force ``F_y`` [N] (both tires together, as in SPEC §1 where an axle has
cornering stiffness ``2 C``). Every model offers

- ``lateral_force(alpha)``: vectorised over numpy arrays,
- ``force(alpha)``: a fast scalar path for the simulation loop,
- ``cornering_stiffness``: the axle slope at zero slip [N/rad].

Sign convention: positive slip gives positive (leftward) force.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Callable, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .params import ParameterError, TireParams, VehicleParams

__all__ = ["TireModel", "LinearTire", "PacejkaTire", "CallableTire", "axle_tires", "magic_formula"]

Axle = Literal["front", "rear"]


def magic_formula(alpha, B: float, C: float, D: float, E: float, atan=np.arctan, sin=np.sin):
    """Pacejka Magic Formula ``D sin(C atan(B a - E (B a - atan(B a))))``.

    Works on scalars (pass ``atan=math.atan, sin=math.sin`` for speed) and arrays.
    Slope at zero: ``B C D``.
    """
    x = B * alpha
    return D * sin(C * atan(x - E * (x - atan(x))))


def _scalar_magic_formula(B: float, C: float, D: float, E: float) -> Callable[[float], float]:
    """:func:`magic_formula` for one float, coefficients bound as locals (3x faster)."""
    atan, sin = math.atan, math.sin

    def force(alpha: float) -> float:
        x = B * alpha
        return D * sin(C * atan(x - E * (x - atan(x))))

    return force


class TireModel(ABC):
    """An axle lateral-force model ``F_y(alpha)``."""

    @abstractmethod
    def lateral_force(self, alpha: ArrayLike) -> NDArray[np.float64]:
        """Axle lateral force [N] at slip angle(s) ``alpha`` [rad], vectorised."""

    def force(self, alpha: float) -> float:
        """Scalar axle lateral force [N]; subclasses override for speed."""
        return float(self.lateral_force(alpha))

    @property
    @abstractmethod
    def cornering_stiffness(self) -> float:
        """Axle cornering stiffness ``dF_y/dalpha`` at zero slip [N/rad]."""

    def kernel_vector(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(tire vector, force table)`` for the compiled plant (see :mod:`._kernels`).

        The default tabulates ``lateral_force`` on ``[-1.5, 1.5]`` rad every 1e-4 rad
        (linear interpolation, clamped outside), so any model runs in the fast loop.
        """
        a_min, step = -1.5, 1e-4
        grid = a_min + step * np.arange(30001)
        return np.array([2.0, a_min, step, 0.0, 0.0]), np.ascontiguousarray(self.lateral_force(grid), dtype=float)

    def nonlinear_force(self, alpha: ArrayLike, linear_stiffness: float) -> NDArray[np.float64]:
        """``F_y(alpha) - linear_stiffness * alpha``: the part the observer must learn [N]."""
        a = np.asarray(alpha, dtype=float)
        return self.lateral_force(a) - linear_stiffness * a


@dataclass(frozen=True)
class LinearTire(TireModel):
    """Linear axle tire ``F_y = k alpha``.

    Parameters
    ----------
    stiffness : float
        Axle cornering stiffness ``k = 2 C`` [N/rad].
    """

    stiffness: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.stiffness) and self.stiffness > 0):
            raise ParameterError(f"LinearTire.stiffness must be a finite value > 0, got {self.stiffness!r}")

    def lateral_force(self, alpha: ArrayLike) -> NDArray[np.float64]:
        return self.stiffness * np.asarray(alpha, dtype=float)

    def force(self, alpha: float) -> float:
        return self.stiffness * alpha

    @property
    def cornering_stiffness(self) -> float:
        return self.stiffness

    def kernel_vector(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return np.array([0.0, self.stiffness, 0.0, 0.0, 0.0]), np.zeros(2)


@dataclass(frozen=True)
class PacejkaTire(TireModel):
    """Pacejka Magic Formula axle tire ``F_y = D sin(C atan(B a - E (B a - atan(B a))))``.

    Build it with :meth:`for_axle` so that ``D = mu F_z`` (static axle load) and the
    slope at zero slip ``B C D`` equals the axle cornering stiffness ``2 C_alpha``.

    Parameters
    ----------
    B : float
        Stiffness factor [1/rad].
    C : float
        Shape factor [-].
    D : float
        Peak force [N].
    E : float
        Curvature factor [-].
    """

    B: float
    C: float
    D: float
    E: float

    def __post_init__(self) -> None:
        for name in ("B", "C", "D"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ParameterError(f"PacejkaTire.{name} must be a finite value > 0, got {value!r}")
        if not (math.isfinite(self.E) and self.E <= 1.0):
            raise ParameterError(f"PacejkaTire.E must be finite and <= 1, got {self.E!r}")

    @classmethod
    def for_axle(cls, vehicle: VehicleParams, tire: TireParams, axle: Axle) -> "PacejkaTire":
        """Magic Formula for one axle with ``D = mu F_z`` and slope ``2 C`` at zero slip."""
        if axle not in ("front", "rear"):
            raise ParameterError(f"axle must be 'front' or 'rear', got {axle!r}")
        fz_front, fz_rear = vehicle.static_axle_loads
        fz = fz_front if axle == "front" else fz_rear
        stiffness = 2.0 * (vehicle.Cf if axle == "front" else vehicle.Cr)  # [N/rad] axle
        D = tire.mu * fz
        B = stiffness / (tire.shape * D)
        return cls(B=B, C=tire.shape, D=D, E=tire.curvature)

    def lateral_force(self, alpha: ArrayLike) -> NDArray[np.float64]:
        return magic_formula(np.asarray(alpha, dtype=float), self.B, self.C, self.D, self.E)

    @property
    def force(self) -> Callable[[float], float]:  # type: ignore[override]
        """Scalar force function with the coefficients bound (hot path of the plant)."""
        return _scalar_magic_formula(self.B, self.C, self.D, self.E)

    @property
    def cornering_stiffness(self) -> float:
        return self.B * self.C * self.D

    def kernel_vector(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return np.array([1.0, self.B, self.C, self.D, self.E]), np.zeros(2)

    @property
    def peak_force(self) -> float:
        """Peak lateral force ``D`` [N]."""
        return self.D

    @property
    def peak_slip(self) -> float:
        """Slip angle at the force peak [rad] (numerically, on a fine grid)."""
        grid = np.linspace(0.0, 1.0, 20001)
        return float(grid[np.argmax(self.lateral_force(grid))])


class CallableTire(TireModel):
    """Any user function ``F_y = fn(alpha)`` (vectorised over numpy arrays) as a tire.

    Parameters
    ----------
    fn : callable
        Axle lateral force [N] as a function of slip [rad].
    name : str
        Label used in reports.
    """

    def __init__(self, fn: Callable[[NDArray[np.float64]], NDArray[np.float64]], name: str = "custom") -> None:
        if not callable(fn):
            raise ParameterError("CallableTire.fn must be callable")
        self.fn = fn
        self.name = name

    def lateral_force(self, alpha: ArrayLike) -> NDArray[np.float64]:
        return np.asarray(self.fn(np.asarray(alpha, dtype=float)), dtype=float)

    @property
    def cornering_stiffness(self) -> float:
        h = 1e-6
        return float((self.lateral_force(h) - self.lateral_force(-h)) / (2 * h))

    def __repr__(self) -> str:
        return f"CallableTire(name={self.name!r})"


def axle_tires(
    vehicle: VehicleParams,
    model: Literal["linear", "pacejka"] = "pacejka",
    tire: TireParams | None = None,
) -> tuple[TireModel, TireModel]:
    """Front and rear axle tires for ``vehicle`` of the given kind.

    Both are built from the vehicle's per-tire cornering stiffness ``Cf``, ``Cr`` (an axle
    has twice that) and, for Pacejka, the static axle loads and ``tire``.
    """
    if model == "linear":
        return LinearTire(2.0 * vehicle.Cf), LinearTire(2.0 * vehicle.Cr)
    if model == "pacejka":
        tire = tire or TireParams()
        return PacejkaTire.for_axle(vehicle, tire, "front"), PacejkaTire.for_axle(vehicle, tire, "rear")
    raise ParameterError(f"tire model must be 'linear' or 'pacejka', got {model!r}")
