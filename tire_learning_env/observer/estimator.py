"""One-call use of the observer: configuration, gain synthesis, warm start, results.

>>> from tire_learning_env import simulate
>>> from tire_learning_env.observer import ObserverConfig, estimate
>>> log = simulate("study1", 20.0)
>>> result = estimate(log.sensors, log.vehicle, config=ObserverConfig())
>>> cf, cr = result.cornering_stiffness()  # per tire [N/rad], slope of the learned curve at zero
>>> bool(abs(cf / log.vehicle.Cf - 1) < 0.02)
True
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from ..params import CameraParams, ParameterError, VehicleParams, _Params
from .basis import SoftClipBasis, make_basis
from .gains import ObserverGains, synthesize_gains
from .neuro_adaptive import AdaptationParams, NeuroAdaptiveObserver, ObserverTrace
from .warm_start import least_squares_weights

__all__ = ["ObserverConfig", "build_observer", "estimate", "EstimationResult"]


@dataclass(frozen=True)
class ObserverConfig(_Params):
    """Everything that defines an observer run (all defaults documented in the README).

    Parameters
    ----------
    basis : {"two_sided", "paper"}
        Activation preset (:mod:`.basis`).
    decay_rate : float
        Required certified decay rate of the state error [1/s].
    force_error_scale : float
        Force error the gain is designed against [N].
    objective : {"h2", "hinf"}
        Gain-synthesis objective (:func:`.gains.synthesize_gains`).
    state_weight : float
        Weight of the state errors in the synthesis objective.
    warm_start : bool
        Run twice: least-squares weights from the first run start the second (SPEC §4).
    linear_region_deg : float
        Warm start: ``f_hat`` is set to zero below this slip [deg] (0 when the nominal
        stiffness is not trusted, e.g. Study 2).
    latency_compensation : bool
        Compensate the camera latency (out-of-sequence correction).
    law, initial_std, random_walk, max_std, step
        Weight adaptation (:class:`.neuro_adaptive.AdaptationParams`).
    warm_start_std : float, optional
        Prior std of the weights in the second run, around the warm-start weights
        (default ``initial_std``).
    """

    basis: str = "two_sided"
    decay_rate: float = 1.0
    force_error_scale: float = 100.0
    objective: str = "h2"
    state_weight: float = 1.0
    warm_start: bool = True
    linear_region_deg: float = 0.5
    latency_compensation: bool = False
    law: str = "rls"
    initial_std: float = 0.25
    random_walk: float = 0.0
    max_std: float = 1.0
    step: float = 0.2
    warm_start_std: float | None = None
    prior_length: float = 1.0
    prior_symmetry: float = 0.0

    _positive: ClassVar[tuple[str, ...]] = ("force_error_scale", "initial_std", "max_std")
    _non_negative: ClassVar[tuple[str, ...]] = ("decay_rate", "state_weight", "linear_region_deg", "random_walk")

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.basis not in ("two_sided", "paper"):
            raise ParameterError(f"ObserverConfig.basis must be 'two_sided' or 'paper', got {self.basis!r}")
        if self.objective not in ("h2", "hinf"):
            raise ParameterError(f"ObserverConfig.objective must be 'h2' or 'hinf', got {self.objective!r}")
        self.adaptation()  # validates the adaptation fields

    @classmethod
    def for_camera(cls, camera: CameraParams, stiffness_known: bool = True, **overrides) -> "ObserverConfig":
        """Settings matched to the camera and to what is known about the tire.

        A noisy camera with a trusted nominal stiffness gets a low-bandwidth design
        (``decay_rate=0.5``, ``force_error_scale=30`` N: the model error left is the tire
        nonlinearity only); otherwise the defaults (1 1/s, 100 N: a wrong stiffness
        makes force errors of a few hundred newtons that the gain must follow while the
        weights learn). An unknown stiffness also drops the warm start's linear-region
        rule (it would pin the slope at zero slip to the wrong nominal value).
        """
        noisy = camera.noise != "none" and (camera.e1_noise > 0 or camera.e2_noise > 0)
        kw: dict = {}
        if noisy and stiffness_known:
            kw.update(decay_rate=0.5, force_error_scale=30.0)
        if not stiffness_known:
            kw.update(linear_region_deg=0.0)
        kw.update(overrides)
        return cls(**kw)

    def adaptation(self) -> AdaptationParams:
        return AdaptationParams(
            law=self.law, initial_std=self.initial_std, random_walk=self.random_walk, max_std=self.max_std,
            step=self.step, prior_length=self.prior_length, prior_symmetry=self.prior_symmetry,
        )  # fmt: skip


def build_observer(
    vehicle: VehicleParams,
    camera: CameraParams | None = None,
    config: ObserverConfig | None = None,
    physics_dt: float = 1e-3,
    basis: SoftClipBasis | None = None,
    initial_weights: NDArray | None = None,
    cache: bool = True,
) -> NeuroAdaptiveObserver:
    """Synthesize (or load) certified gains for the camera and build the observer.

    The frame period is ``1 / camera.rate`` (at least ``physics_dt``) and the noise
    level the camera's.
    """
    camera = camera or CameraParams()
    config = config or ObserverConfig()
    basis = basis or make_basis(config.basis, vehicle)
    frame_period = max(1.0 / camera.rate, physics_dt)
    gains = synthesize_gains(
        vehicle,
        basis,
        frame_period,
        decay_rate=config.decay_rate,
        noise_std=camera.noise_std,
        force_error_scale=config.force_error_scale,
        state_weight=config.state_weight,
        objective=config.objective,
        cache=cache,
    )
    return NeuroAdaptiveObserver(
        vehicle,
        basis,
        gains,
        physics_dt,
        adaptation=config.adaptation(),
        camera=camera,
        latency_compensation=config.latency_compensation,
        initial_weights=initial_weights,
    )


@dataclass
class EstimationResult:
    """What :func:`estimate` returns.

    Attributes
    ----------
    trace : ObserverTrace
        Final run (after the warm start when enabled).
    online_trace : ObserverTrace
        First run, from zero weights: what a car learns causally on its first drive.
    observer : NeuroAdaptiveObserver
        The observer at the end of the final run (its weights are the learned curve).
    gains : ObserverGains
        The certified gain.
    initial_weights : ndarray or None
        Least-squares warm-start weights (``None`` without warm start).
    runtime_s : float
        Wall time of both runs (gain synthesis excluded; see ``gains.solve_s``).
    """

    trace: ObserverTrace
    online_trace: ObserverTrace
    observer: NeuroAdaptiveObserver
    gains: ObserverGains
    initial_weights: NDArray | None
    runtime_s: float

    def axle_force(self, alpha: NDArray, axle: str) -> NDArray:
        """Learned total axle force [N] (eq. 29)."""
        return self.observer.axle_force(alpha, axle)

    def cornering_stiffness(self) -> tuple[float, float]:
        """Per-tire cornering stiffness of the learned curve at zero slip [N/rad]."""
        return self.observer.cornering_stiffness()

    def online_curve_at(self, k: int):
        """The online (first-run) curve with the weights held at row ``k``."""
        w = self.online_trace.weights[k]
        return lambda alpha, axle: self.observer.axle_force(alpha, axle, weights=w)


def estimate(
    sensors: dict[str, NDArray],
    vehicle: VehicleParams,
    camera: CameraParams | None = None,
    config: ObserverConfig | None = None,
    physics_dt: float | None = None,
    cache: bool = True,
) -> EstimationResult:
    """Run the observer over logged sensor rows (optionally twice, with the warm start).

    Parameters
    ----------
    sensors : dict of arrays
        Rows ``t, delta, vx, psi_dot_des, psi_ddot_des, e1, e2`` (no ``true_*``).
    vehicle : VehicleParams
        Nominal vehicle.
    camera : CameraParams, optional
        Rate and noise the gains are designed for (default: inferred rate, no noise).
    config : ObserverConfig, optional
    physics_dt : float, optional
        Row spacing [s]; default the median spacing of ``t``.
    """
    config = config or ObserverConfig()
    t = np.asarray(sensors["t"], dtype=float)
    if len(t) < 2:
        raise ParameterError("need at least two rows to estimate")
    dt = float(np.median(np.diff(t))) if physics_dt is None else float(physics_dt)
    if camera is None:
        frames = np.flatnonzero(np.isfinite(np.asarray(sensors["e1"], dtype=float)))
        rate = 1.0 / (float(np.median(np.diff(t[frames]))) if len(frames) > 1 else dt)
        camera = CameraParams(rate=rate)
    observer = build_observer(vehicle, camera, config, dt, cache=cache)
    t0 = time.perf_counter()
    online = observer.run(sensors)
    w0 = None
    trace = online
    if config.warm_start:
        w0 = least_squares_weights(
            observer.basis, online, linear_region=math.radians(config.linear_region_deg),
            prior=observer.basis.prior_correlation(config.prior_length, config.prior_symmetry),
        )  # fmt: skip
        if config.warm_start_std is not None:
            observer.adaptation = replace(observer.adaptation, initial_std=config.warm_start_std)
        observer.reset(weights=w0)
        trace = observer.run(sensors)
    runtime = time.perf_counter() - t0
    return EstimationResult(trace, online, observer, observer.gains, w0, runtime)
