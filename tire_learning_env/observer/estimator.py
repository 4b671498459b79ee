r"""One-call estimation from a log, for every sensor set: calibrate, design, learn, refine, report.

>>> from tire_learning_env import simulate
>>> from tire_learning_env.params import CameraParams
>>> from tire_learning_env.observer import estimate
>>> log = simulate("lane_changes", 40.0, camera=CameraParams.paper_noise(rate=20.0))
>>> result = estimate(log.sensors, log.vehicle.replace(Cf=1.1e5, Cr=0.95e5))  # a wrong nominal stiffness
>>> result.sensors, result.verdict
('camera', 'identified')
>>> cf, cr = result.cornering_stiffness()  # per tire [N/rad], with result.cornering_stiffness_std()
>>> bool(abs(cf / log.vehicle.Cf - 1) < 0.02 and abs(cr / log.vehicle.Cr - 1) < 0.02)
True

Steps of :func:`estimate` (each reported in :attr:`EstimationResult.calibration`):

1. **Sensors**: the camera if the log has one, else the IMU (``config.sensors="both"`` fuses them).
2. **Noise** of every channel from the log (:mod:`.calibration`), unless given.
3. **Gains**: certified for the measured noise, frame period and speed range (:mod:`.gains`).
4. **Latency** of the camera: the prediction-error cost after one Gauss-Newton step is
   profiled over candidate latencies, the minimum refined by a parabola (unless given).
5. **Causal pass** from the nominal curve: what a car learns on line (:attr:`online`).
6. **Offline refinement** over the whole log (:mod:`.offline`): the reported curve and
   stiffness, with their two-sigma bands, the identifiability verdict and the learned
   slip range (:attr:`offline`, :meth:`stiffness_report`).

Nothing of the truth is used; a user who knows their camera or their stiffness can say
so (``camera_noise``, ``latency``, ``stiffness_known``), and the result records what was
estimated and what was assumed.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import ClassVar, Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..params import CameraParams, ParameterError, VehicleParams, _Params
from .basis import SoftClipBasis, imu_basis, make_basis
from .calibration import estimate_noise_std, imu_noise_window, sample_period
from .gains import GainDesign, ObserverGains, synthesize_gains
from .model import MeasurementModel, measurement_model
from .neuro_adaptive import AdaptationParams, HealthParams, NeuroAdaptiveObserver, axle_index
from .offline import (OfflineFit, calibrate_force_error, curve_gradient, pem_cost, refine, select_prior_length,
                      stiffness_readout)
from .sensitivity import steering_hold_sensitivity, yaw_dynamics_check
from .trace import EstimateTrace

__all__ = ["ObserverConfig", "build_observer", "estimate", "EstimationResult", "detect_sensors", "fusion_fallback",
           "NOISE_FLOOR"]

#: smallest noise std used per channel (e1 [m], e2 [rad], a_y [m/s^2], r [rad/s]): resolution
NOISE_FLOOR = np.array([1e-4, 1e-4, 0.01, 1e-4])
#: noise assumed when a channel has too few samples to measure it
NOISE_DEFAULT = np.array([0.01, 0.005, 0.5, 0.005])
AXLES = ("front", "rear")


@dataclass(frozen=True)
class ObserverConfig(_Params):
    """Everything that defines an estimation; the defaults assume nothing about the camera,
    the IMU or the tires beyond the vehicle file.

    Parameters
    ----------
    sensors : {"auto", "camera", "imu", "both"}
        Sensor set; ``auto``: the camera when the log has one, else the IMU (see :data:`FUSION_NOTE`).
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
        Largest latency considered [s].
    steering_hold : {"ramp", "hold"}, optional
        How the steering behaves between log rows: ramping to the next row's value (a sampled
        steering wheel; the default of :func:`estimate`) or held (a simulator's zero-order hold
        at the row rate; the default of :func:`build_observer`, i.e. on line inside the envs,
        whose steering is held over each physics step). The
        log cannot tell (the curve and the latency absorb a wrong hold: the prediction-error
        cost preferred ``hold`` on a log where it read the stiffness +1.8 / +2.6 % off and
        ``ramp`` +0.15 / +0.14 %), so the bands add how much the answer moves under the other
        hold (:func:`.sensitivity.steering_hold_sensitivity`): negligible for rows at 1 kHz,
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
        log's evidence cannot rule out (:func:`.offline.select_prior_length`). Choosing the
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
    identifiable_rel_2sigma : float
        Stiffness reported as identified when its two-sigma band is within this fraction.
    curve_rel_2sigma : float
        Learned slip range: where the curve's two-sigma band is within this fraction.
    """

    sensors: str = "auto"
    basis: str = "two_sided"
    camera_noise: tuple | None = None
    imu_noise: tuple | None = None
    latency: float | None = None
    max_latency: float = 0.15
    steering_hold: str | None = None
    stiffness_known: bool = False
    linear_region_deg: float = 0.5
    offline: bool = True
    decay_rate: float = 0.5
    imu_decay_rate: float = 0.1
    camera_force_error: float = 0.013
    imu_force_error: float = 0.1
    initial_std: float = 0.5
    random_walk: float = 0.0
    max_std: float = 1.0
    prior_length: float = 1.0
    prior_symmetry: float = 0.8
    online_prior_length: float | None = None
    causal_update: str | None = None
    block_s: float = 2.0
    sensor_offsets: bool = True
    nis_factor: float = 3.0
    identifiable_rel_2sigma: float = 0.1
    curve_rel_2sigma: float = 0.1

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
        if self.latency is not None and not (math.isfinite(self.latency) and self.latency >= 0):
            raise ParameterError(f"ObserverConfig.latency must be >= 0 s or None, got {self.latency!r}")

    @classmethod
    def for_camera(cls, camera: CameraParams, stiffness_known: bool = True, **overrides) -> "ObserverConfig":
        """Settings for a camera whose specification is known (noise std and latency given)."""
        kw: dict = {"camera_noise": tuple(camera.noise_std), "latency": camera.latency, "stiffness_known": stiffness_known}
        kw.update(overrides)
        return cls(**kw)

    def adaptation(self) -> AdaptationParams:
        return AdaptationParams(
            initial_std=self.initial_std, random_walk=self.random_walk, max_std=self.max_std,
            prior_length=self.prior_length, prior_symmetry=self.prior_symmetry, sensor_offsets=self.sensor_offsets,
            online_prior_length=self.online_prior_length, causal_update=self.causal_update or "block", block_s=self.block_s,
        )  # fmt: skip

    def gain_design(self) -> GainDesign:
        return GainDesign(camera_decay_rate=self.decay_rate, imu_decay_rate=self.imu_decay_rate,
                          camera_force_error=self.camera_force_error, imu_force_error=self.imu_force_error)  # fmt: skip


#: why ``auto`` does not fuse a log's IMU columns with its camera
FUSION_NOTE = (
    "camera + IMU fusion is available (sensors='both') but not the default: it is only as good as the "
    "agreement of the two sensors' conventions, which a log's columns cannot prove, and it is not better "
    "everywhere: on benchmarks/bench_fusion.py it beats the camera alone (stiffness +0.02/-0.00 % and "
    "-0.17/+0.00 % against -0.13/+0.23 %) and ties the IMU alone, but on the log of `tire-learning simulate "
    "--road lane_changes --camera-rate 20 --noise paper --out LOG` it is worse than the camera alone "
    "(+0.28/+0.60 % against +0.02/+0.30 %)"
)


def detect_sensors(sensors: Mapping[str, ArrayLike]) -> str:
    """``camera`` when the log has camera columns with data, else ``imu`` (``both`` only on
    request, :data:`FUSION_NOTE`)."""

    def has(k):
        return k in sensors and np.any(np.isfinite(np.asarray(sensors[k], dtype=float)))

    cam = has("e1") and has("e2") and (has("kappa") or has("psi_dot_des"))
    imu = has("ay") and has("yaw_rate")
    if cam:  # IMU columns are fused only on request (``sensors="both"``): see FUSION_NOTE
        return "camera"
    if imu:
        return "imu"
    raise ParameterError("the log has neither camera columns (e1, e2, kappa) nor IMU columns (ay, yaw_rate) with data")


def fusion_fallback(sensors: Mapping[str, ArrayLike]) -> tuple[str, str | None]:
    """The sensor set ``sensors="both"`` runs on: ``both``, or the one sensor the log has when the
    other has no sample in the whole log (``camera`` without ``ay``/``yaw_rate`` data, ``imu``
    without ``e1``/``e2`` data), with the reason (``None`` when both are present).

    The fused design is not the single-sensor one with a channel missing: its basis has no
    constant-force member and its gains are certified for the fused output, so a fused pass
    on a log without IMU samples would be a different camera estimator. With a sensor absent
    from the whole log nothing is there to fuse, and the estimate is exactly that of the
    sensor present (``calibration["fusion_fallback"]`` says so). A sensor that drops out for
    a while is handled by the fused design itself (NaN rows)."""

    def has(k):
        return k in sensors and bool(np.any(np.isfinite(np.asarray(sensors[k], dtype=float))))

    cam, imu = has("e1") or has("e2"), has("ay") or has("yaw_rate")
    if cam and not imu:
        return "camera", "sensors='both' requested, but the log has no IMU sample (ay, yaw_rate): the camera estimator ran"
    if imu and not cam:
        return "imu", "sensors='both' requested, but the log has no camera frame (e1, e2): the IMU estimator ran"
    return "both", None


def _basis_for(model: MeasurementModel, config: ObserverConfig, vehicle: VehicleParams) -> SoftClipBasis:
    if model.uses_camera and (not model.uses_imu or config.basis == "paper"):
        return make_basis(config.basis, vehicle)
    # fused: no constant-force member (the IMU's a_y sees the tire forces, not a road's crossfall;
    # with it the fused curve took a force offset of 15 % at 0.1 deg, without it < 0.3 %)
    if config.basis != "two_sided":
        raise ParameterError(
            f"basis {config.basis!r} is not available for IMU-only estimation: the paper's basis is one-sided and "
            "carries bias members that an IMU cannot tell from a sideslip offset; use 'two_sided'"
        )
    return imu_basis(vehicle)


def _quantise(x: float, per_decade: int = 20) -> float:
    """Round to a log grid (cache reuse of gain designs across similar logs)."""
    return float(10 ** (round(math.log10(x) * per_decade) / per_decade))


def _slope_box(basis: SoftClipBasis, vehicle: VehicleParams) -> NDArray:
    nominal = np.array([[2.0 * vehicle.Cf], [2.0 * vehicle.Cr]])
    box = basis.force_slope_bounds(margin=0.0) + nominal
    # the soft clips overlap a little, so the sum of lower bounds can dip below zero; the
    # gain design needs a positive slope (past the peak the certificate does not hold anyway)
    box[:, 0] = np.maximum(box[:, 0], 0.05 * nominal[:, 0])
    return box


def build_observer(
    vehicle: VehicleParams,
    camera: CameraParams | None = None,
    config: ObserverConfig | None = None,
    physics_dt: float = 1e-3,
    basis: SoftClipBasis | None = None,
    initial_weights: NDArray | None = None,
    cache: bool = True,
    sensors: str = "camera",
    noise_std: ArrayLike | None = None,
    latency: float | None = None,
    speed_range: tuple[float, float] | None = None,
    frame_period: float | None = None,
    imu_period: float | None = None,
) -> NeuroAdaptiveObserver:
    """Certified gains (solved or loaded and re-certified) and the observer.

    For use inside an environment (the wrapper): the camera's specification gives the frame
    period, noise and latency unless ``noise_std``/``latency`` say otherwise; the speed range
    defaults to the vehicle's speed with the design margin.
    """
    config = config or ObserverConfig()
    model = measurement_model(sensors)
    camera = camera or CameraParams()
    basis = basis or _basis_for(model, config, vehicle)
    if noise_std is None:
        cam_std = config.camera_noise if config.camera_noise is not None else camera.noise_std
        imu_std = config.imu_noise if config.imu_noise is not None else NOISE_DEFAULT[2:]
        noise_std = np.r_[cam_std, imu_std]
    noise = np.maximum(np.asarray(noise_std, dtype=float), NOISE_FLOOR)
    if latency is None:
        latency = config.latency if config.latency is not None else (camera.latency if model.uses_camera else 0.0)
    if frame_period is None:
        frame_period = max(1.0 / camera.rate, physics_dt) if model.uses_camera else physics_dt
    if speed_range is None:
        speed_range = (vehicle.vx, vehicle.vx)
    box = _slope_box(basis, vehicle)
    noise_design = np.array([_quantise(v) for v in noise])
    gains = synthesize_gains(vehicle, model, float(f"{frame_period:.4g}"), noise_design, speed_range, box,
                             config.gain_design(), imu_period=imu_period, cache=cache)  # fmt: skip
    adaptation = config.adaptation()
    if adaptation.online_prior_length is None and model.uses_camera:
        adaptation = adaptation.replace(online_prior_length=0.0)
    if config.causal_update is None and not model.uses_camera:  # IMU only: see ObserverConfig.causal_update
        adaptation = adaptation.replace(causal_update="rls")
    axle_load = 0.5 * vehicle.m * 9.81
    fe = (config.camera_force_error if model.uses_camera else config.imu_force_error) * axle_load
    obs = NeuroAdaptiveObserver(
        vehicle, basis, gains, noise, latency=float(latency), force_error=fe, force_error_period=frame_period,
        adaptation=adaptation, health=HealthParams(nis_factor=config.nis_factor),
        initial_weights=initial_weights, physics_dt=physics_dt, sample_period=frame_period,
        pinned_slip=math.radians(config.linear_region_deg) if config.stiffness_known else 0.0,
    )  # fmt: skip
    # on line there is no log to choose from: the envs' steering is held over each physics step
    obs.steering_hold = config.steering_hold or "hold"
    return obs


@dataclass
class EstimationResult:
    """What :func:`estimate` returns (the same for camera, IMU and fused estimation).

    Attributes
    ----------
    sensors : {"camera", "imu", "both"}
    online : EstimateTrace
        Causal pass from the nominal curve (what a car learns on line).
    offline : EstimateTrace or None
        Pass with the refined weights held (``None`` without offline refinement).
    observer : NeuroAdaptiveObserver
        Holds the reported weights and their covariance.
    gains : ObserverGains
    fit : OfflineFit or None
    online_weights : ndarray
        Weights at the end of the causal pass.
    calibration : dict
        What was estimated from the log and what was given or assumed.
    runtime_s : dict
        Wall times of the steps [s].
    """

    sensors: str
    online: EstimateTrace
    offline: EstimateTrace | None
    observer: NeuroAdaptiveObserver
    gains: ObserverGains
    fit: OfflineFit | None
    online_weights: NDArray
    calibration: dict
    runtime_s: dict
    config: ObserverConfig = field(default_factory=ObserverConfig)

    @property
    def trace(self) -> EstimateTrace:
        """The reported pass: offline when refined, else the causal one."""
        return self.offline if self.offline is not None else self.online

    @property
    def online_trace(self) -> EstimateTrace:
        return self.online

    @property
    def vehicle(self) -> VehicleParams:
        return self.observer.vehicle

    @property
    def weights(self) -> NDArray:
        return self.fit.weights if self.fit is not None else self.online_weights

    # -- curves -------------------------------------------------------------------------------
    def axle_force(self, alpha: ArrayLike, axle: str) -> NDArray:
        """Learned total axle force [N] (eq. 29): the reported (refined) curve."""
        return self.observer.axle_force(alpha, axle, weights=self.weights)

    def online_axle_force(self, alpha: ArrayLike, axle: str) -> NDArray:
        """The curve at the end of the causal pass [N]."""
        return self.observer.axle_force(alpha, axle, weights=self.online_weights)

    def online_curve_at(self, k: int):
        """The causal curve with the weights held at row ``k`` of the causal pass."""
        w = self.online.weights[k]
        return lambda alpha, axle: self.observer.axle_force(alpha, axle, weights=w)

    def nominal_axle_force(self, alpha: ArrayLike, axle: str) -> NDArray:
        v = self.vehicle
        return 2.0 * (v.Cf if axle_index(axle) == 0 else v.Cr) * np.asarray(alpha, dtype=float)

    def _variance(self, G: NDArray) -> NDArray:
        if self.fit is not None:
            return self.fit.variance(G)
        pw = self.observer.pw
        return np.einsum("ij,jk,ik->i", G, pw, G)

    def axle_force_std(self, alpha: ArrayLike, axle: str) -> NDArray:
        """Standard deviation of the learned axle force at ``alpha`` [N]."""
        a = np.asarray(alpha, dtype=float)
        G = curve_gradient(self.observer, a.ravel(), axle_index(axle))
        return np.sqrt(np.maximum(self._variance(G), 0.0)).reshape(a.shape)

    # -- stiffness ----------------------------------------------------------------------------
    def stiffness_functionals(self) -> tuple[NDArray, list]:
        """``(g (2, nw), info)``: per-tire stiffness ``= C_nominal + g^T w`` read from the linear
        range of the learned curves (:func:`.offline.stiffness_readout`)."""
        if "_readout" not in self.calibration:
            gs, infos = [], []
            for i in (0, 1):
                g, info = stiffness_readout(self.observer, self.weights, self.trace.slip[:, i], i)
                gs.append(g)
                infos.append(info)
            self.calibration["_readout"] = (np.vstack(gs), infos)
        return self.calibration["_readout"]

    def cornering_stiffness(self) -> tuple[float, float]:
        """Per-tire cornering stiffness of the learned curves [N/rad]: half the slope at zero slip
        of a polynomial fitted over their linear range (:func:`.offline.stiffness_readout`)."""
        G, _ = self.stiffness_functionals()
        v = self.vehicle
        k = np.array([v.Cf, v.Cr]) + G @ self.weights
        return float(k[0]), float(k[1])

    def cornering_stiffness_std(self) -> tuple[float, float]:
        """Standard deviation of :meth:`cornering_stiffness` [N/rad] (sandwich covariance)."""
        G, _ = self.stiffness_functionals()
        s = np.sqrt(np.maximum(self._variance(G), 0.0))
        return float(s[0]), float(s[1])

    def stiffness_report(self) -> dict:
        """Per axle: estimate, std, two-sigma band [N/rad] (per tire) and whether it is identified."""
        k = self.cornering_stiffness()
        s = self.cornering_stiffness_std()
        out = {}
        for i, a in enumerate(AXLES):
            ident = bool(2.0 * s[i] <= self.config.identifiable_rel_2sigma * abs(k[i]))
            out[a] = {
                "identified": ident,
                "estimate_N_per_rad": float(k[i]) if ident else None,
                "value_N_per_rad": float(k[i]),
                "std_N_per_rad": float(s[i]),
                "band_2sigma_N_per_rad": [float(k[i] - 2 * s[i]), float(k[i] + 2 * s[i])],
                "relative_2sigma": float(2 * s[i] / abs(k[i])) if k[i] else float("inf"),
            }
        return out

    @property
    def verdict(self) -> str:
        """``identified`` when both axles' stiffness is identified, else ``not_identifiable``."""
        rep = self.stiffness_report()
        return "identified" if all(r["identified"] for r in rep.values()) else "not_identifiable"

    def learned_slip_range(self, n: int = 201) -> dict:
        """Per axle ``[lo, hi]`` [deg]: the contiguous slip range around zero, inside the slip the
        drive covered, where the curve's two-sigma band is within ``curve_rel_2sigma`` of the force."""
        tr = self.trace
        out = {}
        for i, a in enumerate(AXLES):
            s = tr.slip[:, i][np.isfinite(tr.slip[:, i])]
            if len(s) < 10:
                out[a] = None
                continue
            lo, hi = np.percentile(s, [0.5, 99.5])
            grid = np.linspace(min(lo, 0.0), max(hi, 0.0), n)
            F = np.abs(self.axle_force(grid, a))
            sd = self.axle_force_std(grid, a)
            ok = (2.0 * sd <= self.config.curve_rel_2sigma * F) | (np.abs(grid) < math.radians(0.05))
            j0 = int(np.argmin(np.abs(grid)))
            if not ok[j0] or self.stiffness_report()[a]["identified"] is False:
                out[a] = None
                continue
            l = j0
            while l > 0 and ok[l - 1]:
                l -= 1
            h = j0
            while h < n - 1 and ok[h + 1]:
                h += 1
            out[a] = [math.degrees(grid[l]), math.degrees(grid[h])]
        return out

    def summary(self) -> dict:
        """Headline figures (the ``summary`` block of ``metrics.json``)."""
        rep = self.stiffness_report()
        return {
            "sensors": self.sensors,
            "verdict": self.verdict,
            "stiffness_front_N_per_rad": rep["front"]["estimate_N_per_rad"],
            "stiffness_front_2sigma_N_per_rad": rep["front"]["band_2sigma_N_per_rad"],
            "stiffness_rear_N_per_rad": rep["rear"]["estimate_N_per_rad"],
            "stiffness_rear_2sigma_N_per_rad": rep["rear"]["band_2sigma_N_per_rad"],
            "health_final": self.online.final_health,
            "health_ok_fraction": self.online.health_fraction["ok"],
            "runtime_s": float(self.runtime_s.get("total", float("nan"))),
        }


def _noise(config: ObserverConfig, rows: Mapping, model: MeasurementModel, camera: CameraParams | None) -> tuple[NDArray, dict]:
    """Noise std of the 4 channels and how each was obtained."""
    out = NOISE_DEFAULT.copy()
    info: dict = {}
    t = np.asarray(rows["t"], dtype=float)
    given = {}
    if config.camera_noise is not None:
        given["camera"] = config.camera_noise
    elif camera is not None:
        given["camera"] = tuple(camera.noise_std)
    if config.imu_noise is not None:
        given["imu"] = config.imu_noise
    for group, chans, idx in (("camera", ("e1", "e2"), (0, 1)), ("imu", ("ay", "yaw_rate"), (2, 3))):
        used = model.uses_camera if group == "camera" else model.uses_imu
        if not used:
            continue
        if group in given:
            out[list(idx)] = given[group]
            info[group] = {"source": "given", "std": [float(v) for v in given[group]]}
            continue
        est = {}
        for c, i in zip(chans, idx):
            window = imu_noise_window(t, rows[c]) if group == "imu" else 9
            e = estimate_noise_std(t, rows[c], window=window)
            est[c] = dict(e.to_dict(), window_samples=window)
            if math.isfinite(e.std):
                out[i] = e.std
        info[group] = {"source": "estimated from the log (local polynomial residuals)", "channels": est}
    floored = np.maximum(out, NOISE_FLOOR)
    info["std_used"] = dict(zip(("e1_m", "e2_rad", "ay_mps2", "yaw_rate_radps"), floored.tolist()))
    info["floor"] = NOISE_FLOOR.tolist()
    return floored, info


def _profile_window(t: NDArray, delta: NDArray, max_s: float = 120.0) -> slice:
    """The ``max_s`` window with the most steering activity (the whole log if shorter)."""
    if t[-1] - t[0] <= 1.25 * max_s:
        return slice(0, len(t))
    dt = float(np.median(np.diff(t)))
    n = max(int(max_s / dt), 10)
    d = np.nan_to_num(np.diff(delta, prepend=delta[0])) ** 2
    c = np.cumsum(d)
    act = c[n:] - c[:-n]
    s = int(np.argmax(act)) if len(act) else 0
    return slice(s, s + n)


def _estimate_latency(obs: NeuroAdaptiveObserver, rows: dict, config: ObserverConfig, weights: NDArray | None = None,
                      around: float | None = None) -> tuple[float, dict]:  # fmt: skip
    """Profile the one-step prediction-error cost over candidate latencies (module docstring).

    First from the nominal curve (``weights=None``: the process noise is calibrated for it),
    then again over the whole grid (and the first estimate) with the refined weights and
    their process noise: a wrong curve biases the first profile (a stiffness error and a
    delay both shift the phase of the response), the refined curve much less (measured in
    the generalisation benchmark: a 91-95 ms latency first found as 30 ms).
    """
    win = _profile_window(rows["t"], rows["delta"])
    sub = {k: v[win] for k, v in rows.items()}
    if weights is None:
        w0 = np.zeros(obs.n_weights)
        load = 0.5 * obs.vehicle.m * 9.81
        calibrate_force_error(obs, sub, w0, float(sub["t"][0]) + obs.settle_s, 25.0, (1e-4 * load, 3e-2 * load))
    else:
        w0 = np.asarray(weights, dtype=float)
    cands = [c for c in (0.0, 0.01, 0.02, 0.035, 0.05, 0.07, 0.1, 0.13) if c <= config.max_latency + 1e-12]
    if around is not None:  # the whole grid again (a biased first profile can be far off) plus the first estimate
        cands = sorted(set(cands) | {round(float(around), 4)})
    costs = {}
    updates = [0]

    def cost(d):
        d = round(float(d), 4)
        if d not in costs:
            obs.latency = d
            obs.reset(weights=w0)
            J, n = pem_cost(obs, sub, w0)
            costs[d] = J / max(n, 1)
            updates[0] = max(updates[0], int(n))
        return costs[d]

    for c in cands:
        cost(c)
    ds = sorted(costs)
    j = int(np.argmin([costs[d] for d in ds]))
    best = ds[j]
    if 0 < j < len(ds) - 1:  # parabola through the minimum and its neighbours
        x0, x1, x2 = ds[j - 1], ds[j], ds[j + 1]
        y0, y1, y2 = costs[x0], costs[x1], costs[x2]
        den = (x0 - x1) * (x0 - x2) * (x1 - x2)
        a = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / den
        b = (x2 * x2 * (y0 - y1) + x1 * x1 * (y2 - y0) + x0 * x0 * (y1 - y2)) / den
        if a > 0:
            xv = float(np.clip(-b / (2 * a), x0, x2))
            if cost(xv) < costs[best]:
                best = round(xv, 4)
    elif j == 0 and len(ds) > 1:
        for xv in (ds[1] / 4, ds[1] / 2):
            if cost(xv) < costs[best]:
                best = round(xv, 4)
    obs.latency = best
    obs.reset()
    return best, {
        "source": "estimated from the log (prediction-error profile)",
        "latency_s": best,
        "profile_s_to_cost_per_update": {f"{k:.4f}": v for k, v in sorted(costs.items())},
        "window_s": [float(sub["t"][0]), float(sub["t"][-1])],
        "updates": updates[0],
    }


def estimate(
    sensors: Mapping[str, ArrayLike],
    vehicle: VehicleParams,
    camera: CameraParams | None = None,
    config: ObserverConfig | None = None,
    physics_dt: float | None = None,
    cache: bool = True,
) -> EstimationResult:
    """Estimate the states and the tire curves from logged sensor rows (module docstring).

    Parameters
    ----------
    sensors : mapping of str -> array
        ``t, delta, vx`` (``ax`` optional) and the camera (``kappa`` or ``psi_dot_des``,
        ``e1``, ``e2``) and/or IMU (``ay``, ``yaw_rate``) columns; NaN = no sample. No
        ``true_*`` (refused).
    vehicle : VehicleParams
        Nominal vehicle (the vehicle file).
    camera : CameraParams, optional
        A camera specification the user trusts: its noise std and latency are used instead
        of being estimated.
    config : ObserverConfig, optional
    physics_dt : float, optional
        Prediction step after the last row [s]; default the median row spacing.
    """
    config = config or ObserverConfig()
    t_all = time.perf_counter()
    runtime: dict = {}
    name = detect_sensors(sensors) if config.sensors == "auto" else config.sensors
    fallback = None
    if name == "both":  # a sensor absent from the whole log: the other one's estimator, exactly
        name, fallback = fusion_fallback(sensors)
    model = measurement_model(name)
    from .neuro_adaptive import sensor_rows

    rows_k = sensor_rows(sensors, model)  # validates the columns
    t = rows_k["t"]
    if len(t) < 20:
        raise ParameterError(f"need at least 20 rows to estimate, got {len(t)}")
    if not np.all(np.diff(t) > 0):
        raise ParameterError("time must be strictly increasing")
    rows = {"t": t, "delta": rows_k["delta"], "vx": rows_k["vx"], "ax": rows_k["ax"], "kappa": rows_k["kappa"]}
    rows.update(e1=rows_k["z"][:, 0], e2=rows_k["z"][:, 1], ay=rows_k["z"][:, 2], yaw_rate=rows_k["z"][:, 3])
    dt = float(np.median(np.diff(t))) if physics_dt is None else float(physics_dt)
    t0 = time.perf_counter()
    noise, noise_info = _noise(config, rows, model, camera)
    frame_period = sample_period(t, rows["e1"]) if model.uses_camera else sample_period(t, rows["ay"])
    imu_period = sample_period(t, rows["ay"]) if model.uses_imu else None
    meas = np.isfinite(rows["e1"] if model.uses_camera else rows["ay"])
    vx_m = rows["vx"][meas] if meas.any() else rows["vx"]
    speed_range = (float(np.floor(max(np.percentile(vx_m, 0.5), 3.0))), float(np.ceil(np.percentile(vx_m, 99.5)) + 1e-9))
    runtime["calibration_noise"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    latency_given = config.latency if config.latency is not None else (camera.latency if camera is not None else None)
    obs = build_observer(
        vehicle, None, config, dt, cache=cache, sensors=model.name, noise_std=noise,
        latency=latency_given or 0.0, speed_range=speed_range, frame_period=float(f"{frame_period:.4g}"),
        imu_period=None if imu_period is None else float(f"{imu_period:.4g}"),
    )  # fmt: skip
    runtime["gains"] = time.perf_counter() - t0
    calibration = {
        "sensors": model.name,
        "sensors_source": "detected from the log's columns" if config.sensors == "auto" else "given",
        **({"fusion_fallback": {"requested": "both", "ran": model.name, "reason": fallback}} if fallback else {}),
        "noise": noise_info,
        "frame_period_s": frame_period,
        "imu_period_s": imu_period,
        "speed_range_mps": list(speed_range),
        "row_period_median_s": dt,
        "vehicle": vehicle.to_dict(),
        "stiffness": "given (pinned below the linear region)" if config.stiffness_known else "learned (the vehicle "
        "file's Cf, Cr are only the starting point)",
    }
    obs.steering_hold = config.steering_hold or "ramp"
    calibration["steering_hold"] = {"used": obs.steering_hold, "source": "given" if config.steering_hold else "default"}
    if model.uses_camera:
        if latency_given is None:
            t0 = time.perf_counter()
            _, lat_info = _estimate_latency(obs, rows, config)
            runtime["calibration_latency"] = time.perf_counter() - t0
        else:
            lat_info = {"source": "given", "latency_s": float(latency_given)}
        calibration["latency"] = lat_info
    # causal pass from the nominal curve
    t0 = time.perf_counter()
    obs.reset()
    online = obs.run(rows)
    online_w = obs.weights
    runtime["online_pass"] = time.perf_counter() - t0
    fit = None
    offline = None
    if config.offline:
        t0 = time.perf_counter()
        # camera logs: a process-noise stage must also leave the camera innovations white (offline.refine)
        white = model.name == "camera"
        fit = refine(obs, rows, online_w, prior_cov=obs.prior_covariance(offline=True), whiteness=white)
        if model.uses_camera and latency_given is None:  # the latency again, from the refined curve
            first = obs.latency
            obs.set_force_error(fit.force_error)
            lat2, lat2_info = _estimate_latency(obs, rows, config, weights=fit.weights, around=first)
            calibration["latency"] = dict(lat2_info, first_profile=calibration["latency"])
            prof = lat2_info["profile_s_to_cost_per_update"]
            gain = (prof.get(f"{round(float(first), 4):.4f}", np.inf) - prof[f"{lat2:.4f}"]) * lat2_info["updates"]
            lat2_info["cost_decrease_chi2"] = float(gain)
            # refit only when the new latency explains the window significantly better (a chi-square decrease
            # above 4, two sigma): a 30 min log spent a second whole refinement on 2.5 ms (decrease 1.2)
            if abs(lat2 - first) > 0.002 and gain > 4.0:  # refit from the refined weights, from the stage reached
                frac = fit.force_error / (0.5 * vehicle.m * 9.81)
                stages = tuple(f for f in (3e-2, 1e-2, 3e-3, 1e-3, 3e-4, 1e-4) if f <= frac * 1.0001) or (frac,)
                # the stage reached and the next one down (the rest of the continuation was measured to cost
                # a second whole refinement on a 30 min log for no change of the answer)
                fit = refine(obs, rows, fit.weights, prior_cov=obs.prior_covariance(offline=True),
                             force_errors=stages[:2], whiteness=white)  # fmt: skip
            else:
                obs.latency = first
                if abs(lat2 - first) > 1e-9:
                    calibration["latency"]["latency_s"] = float(first)
                    calibration["latency"]["kept_first"] = (f"the refined profile's {lat2 * 1e3:.1f} ms was not "
                                                            "significantly better; the fit kept the first estimate")
                obs.set_force_error(fit.force_error)
                obs.reset(weights=fit.weights)
                obs._state.pw[:] = fit.covariance
        # the prior's length: kept (1 deg unless given), its plausible neighbours' answers in the bands
        fit, calibration["prior_length"] = select_prior_length(obs, rows, fit, choose=False)
        # the other steering hold: how much the answer leans on what the steering did between rows (with
        # an IMU the a_y innovations show the steering's timing and the fit decides between the holds)
        hold_info = steering_hold_sensitivity(obs, rows, fit, decide_by_cost=model.uses_imu)
        if hold_info.get("switch"):
            obs.steering_hold = hold_info["other"]
            frac = fit.force_error / (0.5 * vehicle.m * 9.81)
            fit = refine(obs, rows, fit.weights, prior_cov=obs.prior_covariance(offline=True), force_errors=(frac,))
            fit, calibration["prior_length"] = select_prior_length(obs, rows, fit, choose=False)
            fit.hold_alternatives = []
            hold_info = dict(hold_info, other=calibration["steering_hold"]["used"], refitted=True)
        calibration["steering_hold"].update(hold_info, used=obs.steering_hold)
        if model.name == "camera":  # the yaw dynamics the stiffness leans on: the log may reject the file's
            t1 = time.perf_counter()
            calibration["yaw_dynamics"] = yaw_dynamics_check(obs, rows, fit)
            runtime["yaw_dynamics_check"] = time.perf_counter() - t1
        offline = fit.trace
        runtime["offline_refinement"] = time.perf_counter() - t0
        calibration["offline"] = {
            "method": "prediction-error fit with the Kalman predictor of the same model (Gauss-Newton)",
            "iterations": fit.iterations, "updates": fit.updates, "cost": fit.cost,
            "force_error_calibration": fit.force_error_calibration, "nis_per_dof": fit.nis_per_dof,
        }  # fmt: skip
    else:
        obs.reset(weights=online_w)
    runtime["total"] = time.perf_counter() - t_all
    return EstimationResult(model.name, online, offline, obs, obs.gains, fit, online_w, calibration, runtime, config)
