"""The settings of an estimation: :class:`ObserverConfig` (re-exported by :mod:`.estimator`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..params import CameraParams, ParameterError, _Params
from .gains import GainDesign
from .settings import AdaptationParams, HealthParams

__all__ = ["ObserverConfig"]

#: The fields :meth:`ObserverConfig.adaptation` hands to :class:`AdaptationParams` as they are;
#: their defaults are its defaults (a dataclass' class attribute), as are the gain design's and the health test's.
ADAPTATION_FIELDS = ("initial_std", "random_walk", "max_std", "prior_length", "prior_symmetry", "online_prior_length",
                     "block_s", "sensor_offsets")  # fmt: skip


@dataclass(frozen=True)
class ObserverConfig(_Params):
    """Everything that defines an estimation; the defaults assume nothing about the camera,
    the IMU or the tires beyond the vehicle file.

    Parameters
    ----------
    sensors : {"auto", "camera", "imu", "both"}
        Sensor set; ``auto``: the camera when the log has one, else the IMU (see :data:`.estimator.FUSION_NOTE`).
    basis : {"two_sided", "paper"}
        Tire-curve basis (camera and fused; IMU-only uses the two-sided basis without its
        bias member).
    camera_noise : (float, float), optional
        Camera noise std ``(e1 [m], e2 [rad])``; default: measured from the log.
    imu_noise : (float, float), optional
        IMU noise std ``(a_y [m/s^2], r [rad/s])``; default: measured from the log.
    latency : float, optional
        Camera latency [s]; default: estimated from the log (``max_latency`` at most).
    max_latency : float
        Largest latency considered [s]. The profile's grid (:data:`.latency.LATENCY_GRID`) ends at 130 ms and goes
        on to ``max_latency`` only when its best is there (an independent generator's cameras 120-150 ms late
        were all found at 130 ms when the grid ended there).
    steering_hold : {"ramp", "hold"}, optional
        How the steering behaves between log rows: ramping to the next row's value (a sampled
        steering wheel; the default of :func:`estimate`) or held (a simulator's zero-order hold
        at the row rate; the default of :func:`build_observer`, i.e. on line inside the envs,
        whose steering is held over each physics step). The
        log cannot tell (the curve and the latency absorb a wrong hold: the prediction-error
        cost preferred ``hold`` on a log where it read the stiffness +1.8 / +2.6 % off and
        ``ramp`` +0.15 / +0.14 %), so the bands add how much the answer moves under the other
        hold (:func:`.sensitivity.steering_hold_sensitivity`), and a camera log whose frames
        are sparser than its rows reports the midpoint of the two: 0.1-0.5 % apart at 1 kHz
        rows (two simulators that both hold the steering preferred opposite holds there),
        large when the rows are sparse (a closed-loop log at 20 Hz rows: +11 / +18 % held,
        +1.2 / +1.8 % ramped).
    stiffness_known : bool
        The vehicle file's cornering stiffness is trusted: the curve is pinned to it below
        ``linear_region_deg`` (the paper's Study 1 and 3 setting). Default: learned.
    linear_region_deg : float
        [deg], with ``stiffness_known``.
    offline : bool
        Refine over the whole log after the causal pass (the reported curve).
    decay_rate, imu_decay_rate, camera_force_error, imu_force_error
        Gain design (:class:`~.gains.GainDesign`).
    initial_std, random_walk, max_std, prior_symmetry, sensor_offsets
        Weight prior and adaptation (:class:`~.neuro_adaptive.AdaptationParams`).
    prior_length : float
        Length scale [deg] of the smooth-curve prior of the offline fit. The bands add how much
        the answer moves at the neighbouring lengths of the grid 0.25, 0.5, 1, 2 deg that the
        log's evidence cannot rule out (:func:`.prior_length.select_prior_length`). Choosing the
        length by the evidence was measured worse on the generalisation benchmark's tuning
        family (median stiffness error 0.93 % against 0.51 %).
    online_prior_length : float, optional
        Prior length scale [deg] of the causal pass' ``"rls"`` law; default 0 with a camera,
        ``prior_length`` for IMU-only (:class:`~.neuro_adaptive.AdaptationParams` says why).
    causal_update, block_s
        The causal pass' learning law and its block length [s]
        (:class:`~.neuro_adaptive.AdaptationParams`). Default: ``"block"`` with a camera,
        ``"rls"`` for IMU only: on the real Ferrari log the block law's causal sideslip RMSE
        was 0.43 / 0.55 deg per half against 0.38 / 0.30 deg for the per-measurement law (on
        a simulated noisy-a_y log it was the other way round, 0.072 against 0.119 deg; the
        real car decides).
    nis_factor : float
        Health test margin (:class:`~.neuro_adaptive.HealthParams`).
    lane_reexpressions : bool
        Offline estimates (:func:`.estimator.estimate`) of camera logs: find the steps of ``e1``
        no motion explains (a lane change re-expresses ``e1`` in the new lane) and remove them
        before the estimate (:mod:`.reexpression`; ``calibration["e1_reexpressions"]``). A log
        without such steps is untouched.
    identifiable_rel_2sigma : float
        Stiffness reported as identified when its two-sigma band is within this fraction.
    curve_rel_2sigma : float
        Learned slip range: where the curve's two-sigma band is within this fraction.
    recentre_max : int
        How many times :func:`.estimator.estimate` re-centres the basis on the fit's stiffness
        when the weights the stiffness read-out leans on end at their bound (a vehicle file far
        from the truth); an axle still at its bound is not identified. ``0``: never (the bound
        is still detected and named).
    bound_tolerance : float
        Distance to a weight bound, as a fraction of the box width, that counts as at the bound
        (:func:`.readout.weights_at_bound`).
    """

    sensors: str = "auto"
    basis: str = "two_sided"
    camera_noise: tuple | None = None
    imu_noise: tuple | None = None
    latency: float | None = None
    max_latency: float = 0.25
    steering_hold: str | None = None
    stiffness_known: bool = False
    linear_region_deg: float = 0.5
    offline: bool = True
    decay_rate: float = GainDesign.camera_decay_rate
    imu_decay_rate: float = GainDesign.imu_decay_rate
    camera_force_error: float = GainDesign.camera_force_error
    imu_force_error: float = GainDesign.imu_force_error
    initial_std: float = AdaptationParams.initial_std
    random_walk: float = AdaptationParams.random_walk
    max_std: float = AdaptationParams.max_std
    prior_length: float = AdaptationParams.prior_length
    prior_symmetry: float = AdaptationParams.prior_symmetry
    online_prior_length: float | None = AdaptationParams.online_prior_length
    causal_update: str | None = None  # None: by the sensors (above), not AdaptationParams' default
    block_s: float = AdaptationParams.block_s
    sensor_offsets: bool = AdaptationParams.sensor_offsets
    nis_factor: float = HealthParams.nis_factor
    lane_reexpressions: bool = True
    identifiable_rel_2sigma: float = 0.1
    curve_rel_2sigma: float = 0.1
    recentre_max: int = 2
    bound_tolerance: float = 0.05

    _positive: ClassVar[tuple[str, ...]] = ("initial_std", "max_std", "nis_factor", "identifiable_rel_2sigma",
                                            "curve_rel_2sigma", "camera_force_error", "imu_force_error")  # fmt: skip
    _non_negative: ClassVar[tuple[str, ...]] = ("max_latency", "linear_region_deg", "decay_rate", "imu_decay_rate",
                                                "random_walk", "prior_length", "prior_symmetry")  # fmt: skip

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.sensors not in ("auto", "camera", "imu", "both"):
            raise ParameterError(f"ObserverConfig.sensors must be auto, camera, imu or both, got {self.sensors!r}")
        if self.steering_hold not in (None, "hold", "ramp"):
            raise ParameterError(f"ObserverConfig.steering_hold must be 'hold', 'ramp' or None, got {self.steering_hold!r}")
        if self.basis not in ("two_sided", "paper"):
            raise ParameterError(f"ObserverConfig.basis must be 'two_sided' or 'paper', got {self.basis!r}")
        for name in ("camera_noise", "imu_noise"):
            v = getattr(self, name)
            if v is not None:
                arr = np.asarray(v, dtype=float)
                if arr.shape != (2,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
                    raise ParameterError(f"ObserverConfig.{name} must be two std values >= 0, got {v!r}")
                object.__setattr__(self, name, tuple(float(x) for x in arr))
        r = self.recentre_max
        if isinstance(r, bool) or not isinstance(r, (int, np.integer)) or r < 0:
            raise ParameterError(f"ObserverConfig.recentre_max must be an integer >= 0, got {self.recentre_max!r}")
        if not (isinstance(self.bound_tolerance, (int, float)) and 0.0 <= self.bound_tolerance < 0.5):
            raise ParameterError(f"ObserverConfig.bound_tolerance must be in [0, 0.5), got {self.bound_tolerance!r}")
        if self.latency is not None and not (math.isfinite(self.latency) and self.latency >= 0):
            raise ParameterError(f"ObserverConfig.latency must be >= 0 s or None, got {self.latency!r}")

    @classmethod
    def for_camera(cls, camera: CameraParams, stiffness_known: bool = True, **overrides) -> "ObserverConfig":
        """Settings for a camera whose specification is known (noise std and latency given)."""
        kw: dict = {"camera_noise": tuple(camera.noise_std), "latency": camera.latency, "stiffness_known": stiffness_known}
        kw.update(overrides)
        return cls(**kw)

    def adaptation(self) -> AdaptationParams:
        """The weight prior and learning law (:data:`ADAPTATION_FIELDS`; ``causal_update`` None: the block law)."""
        return AdaptationParams(**{name: getattr(self, name) for name in ADAPTATION_FIELDS},
                                causal_update=self.causal_update or AdaptationParams.causal_update)  # fmt: skip

    def gain_design(self) -> GainDesign:
        return GainDesign(camera_decay_rate=self.decay_rate, imu_decay_rate=self.imu_decay_rate,
                          camera_force_error=self.camera_force_error, imu_force_error=self.imu_force_error)  # fmt: skip
