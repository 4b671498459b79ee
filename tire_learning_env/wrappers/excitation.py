"""``ExcitationWrapper``: steer to excite the slip angles the observer still has to learn.

The observer only learns the part of the tire curve that the driving excites. This
wrapper turns a tire-learning environment (already wrapped by
:class:`~tire_learning_env.wrappers.EstimatorWrapper`) into a task for a reinforcement
learning agent: the action is a normalised steering offset on top of the built-in
lane-keeping driver, the reward is the information about the tire curve that the
observer gained during the step, minus penalties for leaving the lane, exceeding a
lateral-acceleration limit and steering fast.

Information reward (computable on a real car)
---------------------------------------------
The observer adapts its weights ``w`` by recursive least squares; its covariance
``P_w`` (``observer.pw``) is the inverse of the information the camera innovations have
carried about ``w`` so far. The task measures that information on fixed **information
segments** of slip, independent of the observer's basis: the segments between
:data:`INFORMATION_EDGES` (``0, 0.005, 0.01, 0.02, 0.04, 0.08, 0.2`` rad) on each side of
zero. The curve over the **target slip range** ``|alpha_i| <= alpha_i*`` is described by

- the mean slope of the learned nonlinear force over each segment that overlaps the
  range, in units of the nominal axle stiffness,
  ``g_s^T w = (f_i(b) - f_i(a)) / ((b - a) 2 C_i)`` for the segment ``[a, b]``;
- the force offset at zero slip, ``f_i(0) / (2 C_i 0.01 rad)``,

all linear in ``w`` (eq. 14), stacked in the rows of ``G`` (:func:`target_functionals`).
Their covariance is ``P_SS = G P_w G^T`` and the information measure is

    J = -log det P_SS            ("logdet", D-optimal; default)
    J = -log lambda_max(P_SS)    ("min_eig", E-optimal: the least-informed direction)

and the step reward is ``information_scale * (J_k - J_{k-1})``, so an episode's return is
the information gained over the drive, minus the penalties. (With a basis of one member
per information segment, such as the two-sided basis with the segment edges as
breakpoints, ``G`` nearly picks the target weights: only the soft corners blur the
segment ends.) Everything in it (``P_w``,
the camera ``e1`` and the observer's ``e1`` estimate, the IMU ``a_y``, the measured
steering angle) is available on a car; ground truth is used for scoring only.

Simulation-only variant: ``reward="truth_nrmse"`` rewards the decrease of the true
tire-curve error over the target range (``100 * (E_{k-1} - E_k)`` with ``E`` the mean
over the axles of :func:`~tire_learning_env.metrics.curve_nrmse`); it reads the
simulator's true tire curves and cannot run on a car.

Penalties (all from what the car measures)
------------------------------------------
With ``s = soft_fraction`` and ``h(x) = max(0, x - s) / (1 - s)`` (zero below ``s``,
one at the limit):

- lateral acceleration, ``x = max |a_y| / ay_limit`` over the IMU samples of the step
  (1 kHz): ``ay_penalty * h(x)^2 + violation_penalty * [x > 1]``;
- lane, ``x = |e1_hat| / lane_margin`` with ``e1_hat`` the observer's estimate of the
  lateral offset at the end of the step: ``lane_penalty * h(x)^2 + violation_penalty * [x > 1]``;
- steering rate: ``steering_rate_penalty * (rate / steering_rate_scale)^2`` with
  ``rate`` the change of the step-mean road-wheel angle between consecutive steps
  divided by the step length [rad/s];
- departure: ``departure_penalty`` once, when the car leaves the lane (the base env
  terminates the episode).

The quadratic ramp lets a policy use the last tenth of a limit at a growing price; the
step penalty beyond it is larger than the information of fifty late-episode steps.

Safety filter (on by default)
-----------------------------
Penalties teach a policy to respect the limits, they do not guarantee it. With
``safety_filter=True`` every requested offset first passes
:class:`~tire_learning_env.wrappers.safety.LateralAccelerationFilter`: the nearest offset
for which the car's own linear model, closed with its lane-keeping driver, predicts
``|a_y|`` below the limit (minus a camera-noise margin) over 2 s at the four corners of the
+/-20 % front/rear cornering-stiffness box, with the offset released or held after the step.
Inside the step, a per-tick guard on the total steering keeps the IMU ``a_y`` within the
limit whatever the driver does with a noisy frame. Both use only the observer's state
estimate, the driver's state, the IMU and the nominal vehicle. ``info["excitation"]``
reports the requested and applied offsets; the observation's "previous action" is the
applied one.

The **fixed target slip range** defaults to the slip the nominal linear bicycle model
needs for steady cornering at the lateral-acceleration limit,
``alpha_f* = a_lim m lr / (L 2 Cf)``, ``alpha_r* = a_lim m lf / (L 2 Cr)``
(1.01 deg front, 0.70 deg rear for the paper's sedan at 4 m/s^2): the slip a car may
reach without exceeding the limit, whatever the policy excites.

Truth randomisation
-------------------
With :class:`TruthRandomization` (default of the registered env) every reset draws a
new truth tire pair (cornering-stiffness scale per axle and friction coefficient) from
the episode seed, while the observer keeps assuming the nominal stiffness: the tire
the car must learn is unknown, and held-out seeds are held-out tires.

>>> import gymnasium as gym
>>> import numpy as np
>>> import tire_learning_env
>>> env = gym.make("TireLearning-Excitation-v0")
>>> obs, info = env.reset(seed=0)
>>> obs.shape == env.observation_space.shape
True
>>> for k in range(100):
...     obs, reward, terminated, truncated, info = env.step(np.array([0.3 * np.sin(0.2 * k)], dtype=np.float32))
>>> bool(info["excitation"]["information"] > info["excitation"]["information_initial"])
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Mapping

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from ..dynamics import BicyclePlant
from ..metrics import AXLES, convergence_time, curve_nrmse, excited_range
from ..observer import ObserverConfig
from ..params import CameraParams, ParameterError, TireParams, VehicleParams, _Params, coerce_params
from ..tires import PacejkaTire
from .estimator import EstimatorWrapper
from .safety import LateralAccelerationFilter

__all__ = [
    "ExcitationConfig",
    "TruthRandomization",
    "ExcitationWrapper",
    "EXCITATION_CAMERA",
    "EXCITATION_OBSERVATION_NAMES",
    "make_excitation_env",
    "make_highway_excitation_env",
    "target_slip_range",
    "target_functionals",
    "INFORMATION_EDGES",
]

#: Camera of the excitation envs: a production-like 30 Hz lane camera with Gaussian noise
#: (2 cm on e1, 0.2 deg on e2).
EXCITATION_CAMERA = CameraParams(rate=30.0, noise="gaussian", e1_noise=0.02, e2_noise=math.radians(0.2))

#: Names of the observation entries before the per-functional information features.
EXCITATION_OBSERVATION_NAMES = (
    "e1_camera / lane_margin",
    "e2_camera / 0.05 rad",
    "e1_hat / lane_margin",
    "e1_dot_hat / 1 m/s",
    "e2_hat / 0.05 rad",
    "e2_dot_hat / 0.2 rad/s",
    "alpha_f_hat / alpha_f*",
    "alpha_r_hat / alpha_r*",
    "a_y (last IMU sample) / ay_limit",
    "max |a_y| over the step / ay_limit",
    "delta (last) / 0.05 rad",
    "previous action",
    "road lateral acceleration vx^2 kappa / ay_limit",
    "vx / 30 m/s",
    "elapsed time / episode_time",
    "J - J0 (information gained) / 10",
)
_OBS_BOUND = 10.0


def target_slip_range(vehicle: VehicleParams, ay_limit: float) -> tuple[float, float]:
    """Front and rear slip [rad] of steady nominal-linear cornering at ``ay_limit`` [m/s^2].

    ``alpha_f* = a m lr / (L 2 Cf)``, ``alpha_r* = a m lf / (L 2 Cr)`` (axle force shares of
    ``m a`` from the moment balance, divided by the nominal axle stiffness).
    """
    if not ay_limit > 0:
        raise ParameterError(f"ay_limit must be > 0, got {ay_limit!r}")
    L = vehicle.wheelbase
    return (
        ay_limit * vehicle.m * vehicle.lr / (L * 2.0 * vehicle.Cf),
        ay_limit * vehicle.m * vehicle.lf / (L * 2.0 * vehicle.Cr),
    )


#: Edges [rad] of the information segments (module docstring), each mirrored to negative slip.
INFORMATION_EDGES = (0.0, 0.005, 0.01, 0.02, 0.04, 0.08, 0.2)
#: Slip [rad] whose nominal force is the unit of the zero-slip force offset functional.
OFFSET_UNIT_SLIP = 0.01


def target_functionals(
    basis, vehicle: VehicleParams, target: tuple[float, float], n_weights: int | None = None
) -> tuple[NDArray[np.float64], tuple[str, ...]]:
    """Rows ``G`` of the linear functionals of ``w`` that describe the curve on the target range.

    Per axle (front first): for each information segment ``[a, b]`` (between consecutive
    :data:`INFORMATION_EDGES`, and its mirror ``[-b, -a]``) that overlaps
    ``(-target_i, target_i)``, the mean slope of the nonlinear force over it relative to
    the nominal axle stiffness, ``(f_i(b) - f_i(a)) / ((b - a) 2 C_i)``; then the force
    offset at zero slip ``f_i(0) / (2 C_i OFFSET_UNIT_SLIP)`` when the basis can represent
    one (eq. 14: ``f_i(alpha) = gamma_i sum_j W_ij sigma_ij(alpha)``).

    Parameters
    ----------
    basis : SoftClipBasis
        The observer's basis.
    vehicle : VehicleParams
        Nominal vehicle (``Cf``, ``Cr`` [N/rad] per tire: the unit of the slopes).
    target : (float, float)
        Target slip half-widths ``(alpha_f*, alpha_r*)`` [rad].
    n_weights : int, optional
        Length of the observer's weight vector (tire weights first, then any sensor
        offsets); default ``basis.n_weights``.

    Returns
    -------
    G : ndarray, shape (m, n_weights)
        One functional per row.
    names : tuple of str
        ``"front slope [0.005, 0.01]"``, ``"front offset"``, ... (slip in rad).
    """
    N = basis.n_per_axle
    nw = basis.n_weights if n_weights is None else int(n_weights)
    rows, names = [], []
    edges = INFORMATION_EDGES
    for axle, name in enumerate(AXLES):
        c2 = 2.0 * (vehicle.Cf if axle == 0 else vehicle.Cr)
        a_t = float(target[axle])
        if not a_t > 0:
            raise ParameterError(f"target slip must be > 0 rad, got {target!r}")

        def act(alpha):
            return basis.scale[axle] * basis.activations(np.asarray(alpha, dtype=float), axle)

        segments = []
        for lo, hi in zip(edges[:-1], edges[1:]):
            if lo < a_t:
                segments += [(-hi, -lo), (lo, hi)]
        segments.sort()
        for lo, hi in segments:
            g = np.zeros(nw)
            g[axle * N : (axle + 1) * N] = (act(hi) - act(lo)) / ((hi - lo) * c2)
            rows.append(g)
            names.append(f"{name} slope [{lo:g}, {hi:g}]")
        g = np.zeros(nw)
        g[axle * N : (axle + 1) * N] = act(0.0) / (c2 * OFFSET_UNIT_SLIP)
        if np.max(np.abs(g)) > 1e-9:  # a basis without bias members pins f(0) = 0
            rows.append(g)
            names.append(f"{name} offset")
    return np.vstack(rows), tuple(names)


@dataclass(frozen=True)
class ExcitationConfig(_Params):
    """Task settings of :class:`ExcitationWrapper` (limits, reward, penalties).

    Parameters
    ----------
    ay_limit : float
        Lateral-acceleration limit [m/s^2]: 4 on public roads (default),
        :meth:`test_track` allows 8.
    lane_margin : float
        Largest allowed ``|e1|`` [m] (a lane violation beyond it; the base env's
        departure threshold, a wheel on the marking, is 0.925 m for the sedan).
    max_steering_offset : float
        Steering offset [rad] that the action ``+/-1`` maps to (added to the driver).
    soft_fraction : float
        The quadratic penalty ramps start at this fraction of a limit [-].
    steering_rate_scale : float
        Steering rate [rad/s] at which the rate penalty equals ``steering_rate_penalty``.
    reward : {"information", "truth_nrmse"}
        Real-car information gain (default) or the simulation-only error decrease.
    information_measure : {"logdet", "min_eig"}
        D- or E-optimal information measure of the target functionals.
    information_scale : float
        Reward per nat of information [-].
    truth_scale : float
        Reward per unit decrease of the true curve NRMSE (``reward="truth_nrmse"``).
    ay_penalty, lane_penalty, steering_rate_penalty : float
        Penalty per step at the limit (end of the quadratic ramp) [-].
    violation_penalty : float
        Penalty per step beyond the lateral-acceleration limit or the lane margin [-].
    departure_penalty : float
        One-off penalty when the car leaves the lane [-].
    episode_time : float
        Driving-time budget [s] (the observation's time feature; the registered id's
        ``TimeLimit`` truncates at the same time).
    target_slip_front, target_slip_rear : float
        Target slip range half-widths [rad]; 0 (default) means :func:`target_slip_range`
        of the nominal vehicle at ``ay_limit``.
    safety_filter : bool
        Pass every requested offset through the predictive ``|a_y|`` filter
        (:class:`~tire_learning_env.wrappers.safety.LateralAccelerationFilter`) before the
        car applies it.
    safety_stiffness_uncertainty : float
        Relative half-width of the per-axle cornering-stiffness box the filter must be
        safe for [-] (0.2: the truth randomisation's +/-20 %).
    safety_horizon : float
        The filter's prediction horizon [s].
    safety_noise_sigmas : float
        The filter's margin below ``ay_limit`` in standard deviations of the ``a_y`` the
        driver's reaction to camera noise causes [-].
    safety_tick_margin : float
        The per-tick IMU guard keeps ``|a_y|`` below ``ay_limit`` minus this [m/s^2] (room
        for the change of ``a_y`` within one physics tick).
    safety_lane : bool
        Let the filter also keep the predicted ``|e1|`` within ``lane_margin`` (off by
        default: the lane is the policy's task, penalised by the reward).

    The filter's margin (``safety_noise_sigmas`` camera-noise standard deviations) must
    stay below ``ay_limit``; the filter raises naming both when it does not.
    """

    ay_limit: float = 4.0  # [m/s^2]
    lane_margin: float = 0.7  # [m]
    max_steering_offset: float = 0.05  # [rad]
    soft_fraction: float = 0.9  # [-]
    steering_rate_scale: float = 0.5  # [rad/s]
    reward: str = "information"
    information_measure: str = "logdet"
    information_scale: float = 10.0  # [1/nat]
    truth_scale: float = 100.0  # [-]
    ay_penalty: float = 1.0
    lane_penalty: float = 1.0
    violation_penalty: float = 10.0
    steering_rate_penalty: float = 0.02
    departure_penalty: float = 100.0
    episode_time: float = 60.0  # [s]
    target_slip_front: float = 0.0  # [rad]
    target_slip_rear: float = 0.0  # [rad]
    safety_filter: bool = True
    safety_stiffness_uncertainty: float = 0.2  # [-]
    safety_horizon: float = 2.0  # [s]
    safety_noise_sigmas: float = 2.0  # [-]
    safety_tick_margin: float = 0.05  # [m/s^2]
    safety_lane: bool = False

    _positive: ClassVar[tuple[str, ...]] = (
        "ay_limit",
        "lane_margin",
        "max_steering_offset",
        "steering_rate_scale",
        "information_scale",
        "truth_scale",
        "episode_time",
        "safety_horizon",
    )
    _non_negative: ClassVar[tuple[str, ...]] = (
        "ay_penalty",
        "lane_penalty",
        "steering_rate_penalty",
        "violation_penalty",
        "departure_penalty",
        "target_slip_front",
        "target_slip_rear",
        "safety_stiffness_uncertainty",
        "safety_noise_sigmas",
        "safety_tick_margin",
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.reward not in ("information", "truth_nrmse"):
            raise ParameterError(f"ExcitationConfig.reward must be 'information' or 'truth_nrmse', got {self.reward!r}")
        if self.information_measure not in ("logdet", "min_eig"):
            raise ParameterError(
                f"ExcitationConfig.information_measure must be 'logdet' or 'min_eig', got {self.information_measure!r}"
            )
        if not self.safety_stiffness_uncertainty < 1.0:
            raise ParameterError(
                f"ExcitationConfig.safety_stiffness_uncertainty must be in [0, 1), got {self.safety_stiffness_uncertainty!r}"
            )
        if not self.safety_tick_margin < self.ay_limit:
            raise ParameterError(
                f"ExcitationConfig.safety_tick_margin ({self.safety_tick_margin}) must be below ay_limit ({self.ay_limit})"
            )
        if not 0.0 <= self.soft_fraction < 1.0:
            raise ParameterError(f"ExcitationConfig.soft_fraction must be in [0, 1), got {self.soft_fraction!r}")

    @classmethod
    def test_track(cls, **changes: Any) -> "ExcitationConfig":
        """A closed test track: 8 m/s^2 allowed (the target slip range grows with it)."""
        return cls(**{"ay_limit": 8.0, **changes})

    def target(self, vehicle: VehicleParams) -> tuple[float, float]:
        """``(alpha_f*, alpha_r*)`` [rad]: the configured values or :func:`target_slip_range`."""
        auto = target_slip_range(vehicle, self.ay_limit)
        return (
            self.target_slip_front if self.target_slip_front > 0 else auto[0],
            self.target_slip_rear if self.target_slip_rear > 0 else auto[1],
        )


@dataclass(frozen=True)
class TruthRandomization(_Params):
    """Per-episode truth tires unknown to the observer (drawn from the reset seed).

    Each reset draws ``scale_f, scale_r ~ U(stiffness_scale_low, stiffness_scale_high)``
    (one shared scale when ``independent_axles`` is false) and
    ``mu ~ U(mu_low, mu_high)``, and builds Pacejka axle tires with cornering stiffness
    ``scale * 2 C`` and peak ``mu F_z``; the observer keeps the nominal ``2 C``.

    Parameters
    ----------
    stiffness_scale_low, stiffness_scale_high : float
        Range of the truth/nominal cornering-stiffness ratio [-].
    mu_low, mu_high : float
        Range of the peak friction coefficient [-].
    shape, curvature : float
        Magic Formula ``C`` and ``E`` (fixed).
    independent_axles : bool
        Draw the front and rear stiffness scales independently.
    """

    stiffness_scale_low: float = 0.8
    stiffness_scale_high: float = 1.2
    mu_low: float = 0.7
    mu_high: float = 1.1
    shape: float = 1.3
    curvature: float = -0.5
    independent_axles: bool = True

    _positive: ClassVar[tuple[str, ...]] = ("stiffness_scale_low", "stiffness_scale_high", "mu_low", "mu_high")

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.stiffness_scale_low > self.stiffness_scale_high or self.mu_low > self.mu_high:
            raise ParameterError("TruthRandomization: each low bound must not exceed its high bound")
        TireParams(shape=self.shape, curvature=self.curvature)  # validates C and E

    def draw(self, rng: np.random.Generator) -> dict[str, float]:
        """One truth: ``{"scale_front", "scale_rear", "mu"}``."""
        lo, hi = self.stiffness_scale_low, self.stiffness_scale_high
        sf = float(rng.uniform(lo, hi))
        sr = float(rng.uniform(lo, hi)) if self.independent_axles else sf
        return {"scale_front": sf, "scale_rear": sr, "mu": float(rng.uniform(self.mu_low, self.mu_high))}

    def build_plant(self, vehicle: VehicleParams, draw: Mapping[str, float], effects=None) -> BicyclePlant:
        """The truth plant of one draw (nominal ``vehicle`` for everything but the tires)."""
        scaled = vehicle.replace(Cf=vehicle.Cf * draw["scale_front"], Cr=vehicle.Cr * draw["scale_rear"])
        tire = TireParams(mu=draw["mu"], shape=self.shape, curvature=self.curvature)
        front = PacejkaTire.for_axle(scaled, tire, "front")
        rear = PacejkaTire.for_axle(scaled, tire, "rear")
        return BicyclePlant(vehicle, front, rear, effects)


class ExcitationWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Excitation task around an :class:`EstimatorWrapper` (see the module docstring).

    ## Action Space

    ``Box(-1, 1, (1,), float32)``: steering offset ``action * max_steering_offset`` [rad]
    added to the built-in driver (values outside are clipped; NaN raises ``ValueError``),
    after the safety filter when ``config.safety_filter`` is on.

    ## Observation Space

    ``Box(-10, 10, (16 + n_target,), float32)``: :data:`EXCITATION_OBSERVATION_NAMES`
    (camera, IMU, steering, road, time and the observer's state/slip estimates, each
    normalised), then for each target functional (:func:`target_functionals`)
    ``0.5 log10(P_SS,ii(0) / P_SS,ii)``, the number of decades its standard deviation has
    shrunk. Only what a car knows.

    ## Rewards

    Information gain minus penalties (module docstring).

    ## Episode End

    The base env terminates when the car leaves the lane; the registered id truncates
    after ``episode_time`` (60 s, 1200 steps at 20 Hz).

    ## Info

    ``info["excitation"]``: ``information``, ``information_initial``, ``reward_information``,
    ``penalty_ay``, ``penalty_lane``, ``penalty_steering_rate``, ``penalty_departure``,
    ``max_abs_ay``, ``steering_rate``, ``e1_hat``, ``offset`` (applied) and ``offset_requested``
    [rad], ``filter_active``, ``filter_predicted_peak`` [m/s^2] and (scoring only) ``true_max_abs_e1``;
    ``info["truth_draw"]`` at reset when the truth is randomised. The base env's per-tick
    ``sensor_log``/``truth_log`` are passed on only with ``info_logs=True``: they are large
    (50 rows per step), and gymnasium's determinism check compares infos with
    ``np.allclose``, for which the logs' NaN "no frame" rows never equal themselves.

    ## Version History

    * v0: initial release (``TireLearning-Excitation-v0``, ``TireLearning-HighwayExcitation-v0``).

    Parameters
    ----------
    env : EstimatorWrapper
        The observer running inside a tire-learning env.
    config : ExcitationConfig or dict, optional
    randomization : TruthRandomization or dict, optional
        Per-episode truth tires (``None``: the env's own fixed truth), handed to the base env
        through its ``set_plant`` (:class:`~tire_learning_env.envs._base.TireLearningEnv`).
    record : bool
        Keep per-step records for :meth:`episode_metrics` (weights, slips, limits).
    info_logs : bool
        Pass the base env's per-tick ``sensor_log`` and ``truth_log`` on in ``info``.
    """

    def __init__(
        self,
        env: gym.Env,
        config: ExcitationConfig | Mapping | None = None,
        randomization: TruthRandomization | Mapping | None = None,
        record: bool = True,
        info_logs: bool = False,
    ) -> None:
        gym.utils.RecordConstructorArgs.__init__(
            self, config=config, randomization=randomization, record=record, info_logs=info_logs
        )
        gym.Wrapper.__init__(self, env)
        if not isinstance(env, EstimatorWrapper):
            raise TypeError(
                f"ExcitationWrapper needs an EstimatorWrapper directly inside it, got {type(env).__name__}; "
                "wrap the env with EstimatorWrapper first (or use make_excitation_env)"
            )
        self.config: ExcitationConfig = coerce_params(ExcitationConfig, config, "config") or ExcitationConfig()
        self.randomization: TruthRandomization | None = (
            None if randomization is None else coerce_params(TruthRandomization, randomization, "randomization")
        )
        self.record = bool(record)
        self.info_logs = bool(info_logs)
        self.estimator: EstimatorWrapper = env
        self.observer = env.observer
        base = env.unwrapped
        self.vehicle: VehicleParams = self.observer.vehicle
        if self.randomization is not None and not hasattr(base, "plant"):
            raise TypeError(f"{type(base).__name__} does not expose its truth plant; truth randomisation needs one")
        self.target: tuple[float, float] = self.config.target(self.vehicle)
        self.target_functionals, self.target_names = target_functionals(
            self.observer.basis, self.vehicle, self.target, self.observer.n_weights
        )
        self.dt_policy = 1.0 / float(getattr(base, "policy_rate", 20.0))
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        n_obs = len(EXCITATION_OBSERVATION_NAMES) + len(self.target_names)
        self.observation_space = spaces.Box(-_OBS_BOUND, _OBS_BOUND, shape=(n_obs,), dtype=np.float32)
        self._truth_rng: np.random.Generator | None = None
        self.truth_draw: dict[str, float] | None = None
        self.safety_filter: LateralAccelerationFilter | None = None
        if self.config.safety_filter:
            self._driver = getattr(getattr(base, "sim", base), "driver", None)
            camera = getattr(base, "estimator_inputs", {}).get("camera")
            if self._driver is None or camera is None:
                raise TypeError(
                    f"{type(base).__name__} exposes no lane-keeping driver or camera; the safety filter needs both"
                )
            cfg = self.config
            self.safety_filter = LateralAccelerationFilter(
                self.vehicle, self._driver.params, cfg.ay_limit, self.dt_policy, camera,
                stiffness_uncertainty=cfg.safety_stiffness_uncertainty, horizon=cfg.safety_horizon,
                noise_sigmas=cfg.safety_noise_sigmas, lane_margin=cfg.lane_margin if cfg.safety_lane else None,
            )  # fmt: skip
            # and every physics tick: the IMU a_y guard on the total steering (catches what the
            # step-level prediction cannot see: the driver's reaction to each noisy camera frame)
            gain = 2.0 * self.vehicle.Cf / self.vehicle.m
            s_unc = cfg.safety_stiffness_uncertainty
            self._driver.set_ay_guard(cfg.ay_limit - cfg.safety_tick_margin, (1.0 - s_unc) * gain, (1.0 + s_unc) * gain)
        self._reset_records()

    # -- information -------------------------------------------------------------------------
    def information(self) -> float:
        """The information measure ``J`` of the target functionals now (module docstring) [nat]."""
        p = self.target_covariance()
        if self.config.information_measure == "logdet":
            sign, logdet = np.linalg.slogdet(p)
            return -float(logdet) if sign > 0 else float("inf")
        return -math.log(float(np.linalg.eigvalsh(p)[-1]))

    def information_features(self) -> NDArray[np.float64]:
        """``0.5 log10(P_SS,ii(0) / P_SS,ii)`` for each target functional: decades of std reduction."""
        d = np.diag(self.target_covariance())
        return 0.5 * np.log10(self._p0_diag / np.maximum(d, 1e-300))

    def target_covariance(self) -> NDArray[np.float64]:
        """``P_SS = G P_w G^T``: covariance of the target functionals now (symmetrised)."""
        G = self.target_functionals
        p = G @ self.observer.pw @ G.T
        return 0.5 * (p + p.T)

    def truth_error(self) -> float:
        """Mean over the axles of the true curve NRMSE on the target range (simulation only)."""
        plant = self.env.unwrapped.plant
        return float(
            np.mean(
                [
                    curve_nrmse(self.observer.axle_force, plant.true_axle_curve, a, -t, t)
                    for a, t in zip(AXLES, self.target)
                ]
            )
        )

    # -- gymnasium API ---------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if self.randomization is not None:
            if seed is not None:
                self._truth_rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x7E1E]))
            elif self._truth_rng is None:
                self._truth_rng = np.random.default_rng()
            self.truth_draw = self.randomization.draw(self._truth_rng)
            base = self.env.unwrapped
            plant = self.randomization.build_plant(self.vehicle, self.truth_draw, getattr(base.plant, "effects", None))
            base.set_plant(plant)
        obs, info = self.env.reset(seed=seed, options=options)
        self._p0_diag = np.diag(self.target_covariance()).copy()
        self._j0 = self._j = self.information()
        self._e0 = self._e = self.truth_error() if self.config.reward == "truth_nrmse" else math.nan
        self._prev_action = 0.0
        self._prev_delta_mean: float | None = None
        self._t = 0.0
        # the base envs observe [e1, e2, frame age, vx, kappa, delta]: start speed and curvature
        # (the highway ego starts slower than the nominal speed)
        self._last = {"e1_cam": 0.0, "e2_cam": 0.0, "ay": 0.0, "ay_max": 0.0, "delta": 0.0,
                      "kappa": float(obs[4]), "vx": float(obs[3])}  # fmt: skip
        self._reset_records()
        if self.truth_draw is not None:
            info["truth_draw"] = dict(self.truth_draw)
        info["excitation"] = {"information": self._j, "information_initial": self._j0}
        return self._observation(info["estimate"]), info

    def step(self, action):
        a = np.asarray(action, dtype=float).reshape(-1)
        if a.size != 1:
            raise ValueError(f"action must hold one normalised steering offset, got shape {np.shape(action)}")
        if not np.isfinite(a[0]):
            raise ValueError(f"action must be finite, got {a[0]!r} (NaN or infinite steering offset)")
        u = float(np.clip(a[0], -1.0, 1.0))
        requested = offset = u * self.config.max_steering_offset
        decision = None
        if self.safety_filter is not None:
            decision = self.safety_filter.decide(
                requested, self.estimator.last_estimate["state"], self._driver.integral, self._last["vx"],
                self._last["kappa"],
                max_offset=self.config.max_steering_offset,
            )  # fmt: skip
            offset = decision.applied
            u = offset / self.config.max_steering_offset
        _, _, terminated, truncated, info = self.env.step(np.array([offset], dtype=np.float32))
        cfg = self.config
        log = info["sensor_log"]
        est = info["estimate"]

        # what the car measured during the step
        ay = np.asarray(log["ay"], dtype=float)
        ay_max = float(np.max(np.abs(ay)))
        delta_mean = float(np.mean(log["delta"]))
        rate = 0.0 if self._prev_delta_mean is None else abs(delta_mean - self._prev_delta_mean) / self.dt_policy
        frames = np.flatnonzero(np.isfinite(log["e1"]))
        if len(frames):
            self._last["e1_cam"] = float(log["e1"][frames[-1]])
            self._last["e2_cam"] = float(log["e2"][frames[-1]])
        self._last.update(ay=float(ay[-1]), ay_max=ay_max, delta=float(log["delta"][-1]),
                          kappa=float(log["kappa"][-1]), vx=float(log["vx"][-1]))  # fmt: skip
        e1_hat = float(est["state"][0])

        # reward: information gained (or, simulation only, true error decrease) minus penalties
        j = self.information()
        if cfg.reward == "information":
            r_info = cfg.information_scale * (j - self._j)
        else:
            e = self.truth_error()
            r_info = cfg.truth_scale * (self._e - e)
            self._e = e
        self._j = j
        p_ay = self._limit_penalty(ay_max / cfg.ay_limit, cfg.ay_penalty)
        p_lane = self._limit_penalty(abs(e1_hat) / cfg.lane_margin, cfg.lane_penalty)
        p_rate = cfg.steering_rate_penalty * (rate / cfg.steering_rate_scale) ** 2
        p_dep = cfg.departure_penalty if terminated else 0.0
        reward = float(r_info - p_ay - p_lane - p_rate - p_dep)

        self._prev_delta_mean = delta_mean
        self._prev_action = u
        self._t = float(info.get("t", self._t + self.dt_policy))
        true_e1 = None
        if "truth_log" in info:
            true_e1 = float(np.max(np.abs(info["truth_log"]["true_state"][:, 0])))
        info["excitation"] = {
            "information": j,
            "information_initial": self._j0,
            "reward_information": float(r_info),
            "penalty_ay": p_ay,
            "penalty_lane": p_lane,
            "penalty_steering_rate": p_rate,
            "penalty_departure": p_dep,
            "max_abs_ay": ay_max,
            "steering_rate": rate,
            "e1_hat": e1_hat,
            "offset": offset,
            "offset_requested": requested,
            "filter_active": bool(decision is not None and decision.active),
            "filter_predicted_peak": math.nan if decision is None else decision.predicted_peak,
            "true_max_abs_e1": true_e1,
        }
        if self.record:
            self._records(info, ay_max, rate, true_e1, reward)
        if not self.info_logs:
            info.pop("sensor_log", None)
            info.pop("truth_log", None)
        return self._observation(est), reward, terminated, truncated, info

    def _limit_penalty(self, x: float, weight: float) -> float:
        """``weight h(x)^2 + violation_penalty [x > 1]`` (module docstring)."""
        cfg = self.config
        h = max(0.0, x - cfg.soft_fraction) / (1.0 - cfg.soft_fraction)
        return weight * h * h + (cfg.violation_penalty if x > 1.0 else 0.0)

    # -- observation -----------------------------------------------------------------------------
    def _observation(self, est: Mapping[str, Any]) -> NDArray[np.float32]:
        cfg, last = self.config, self._last
        x, slip = est["state"], est["slip"]
        head = [
            last["e1_cam"] / cfg.lane_margin,
            last["e2_cam"] / 0.05,
            x[0] / cfg.lane_margin,
            x[1] / 1.0,
            x[2] / 0.05,
            x[3] / 0.2,
            slip[0] / self.target[0],
            slip[1] / self.target[1],
            last["ay"] / cfg.ay_limit,
            last["ay_max"] / cfg.ay_limit,
            last["delta"] / 0.05,
            self._prev_action,
            last["vx"] ** 2 * last["kappa"] / cfg.ay_limit,
            last["vx"] / 30.0,
            self._t / cfg.episode_time,
            (self._j - self._j0) / 10.0,
        ]
        obs = np.concatenate([np.asarray(head, dtype=float), self.information_features()])
        obs = np.nan_to_num(obs, nan=0.0, posinf=_OBS_BOUND, neginf=-_OBS_BOUND)
        return np.clip(obs, -_OBS_BOUND, _OBS_BOUND).astype(np.float32)

    # -- episode records and scoring -----------------------------------------------------------
    def _reset_records(self) -> None:
        self._rec: dict[str, list] = {k: [] for k in ("t", "weights", "max_abs_ay", "steering_rate", "true_max_abs_e1",
                                                      "true_slip", "slip_hat", "reward", "information", "filter_active")}  # fmt: skip
        self._departed = False

    def _records(self, info, ay_max, rate, true_e1, reward) -> None:
        r = self._rec
        r["t"].append(self._t)
        r["weights"].append(info["estimate"]["weights"].copy())
        r["max_abs_ay"].append(ay_max)
        r["steering_rate"].append(rate)
        r["true_max_abs_e1"].append(np.nan if true_e1 is None else true_e1)
        r["reward"].append(reward)
        r["information"].append(self._j)
        r["filter_active"].append(info["excitation"]["filter_active"])
        if "truth_log" in info:
            r["true_slip"].append(info["truth_log"]["true_slip"])
        r["slip_hat"].append(info["estimate"]["slip"].copy())
        if info["excitation"]["penalty_departure"] > 0:
            self._departed = True

    def episode_metrics(self, threshold: float = 0.05) -> dict[str, Any]:
        """Score the episode so far against the truth (needs ``record=True`` and at least one step).

        Returns
        -------
        dict
            ``tire_curve_nrmse`` {front, rear} of the final learned curve over the fixed
            target range, ``tire_curve_nrmse_max`` (worse axle), ``tire_curve_nrmse_nominal``,
            ``target_slip_deg``, ``excited_slip_range_deg`` {front: [lo, hi], rear} (true slip,
            0.5/99.5 % quantiles), ``target_coverage`` {front, rear} (fraction of the target
            range inside the excited range), ``convergence_time_s`` (time after which the
            worse-axle NRMSE stays below ``threshold``; ``None`` if never), ``lane_violation_steps``
            (steps whose true ``|e1|`` exceeded ``lane_margin``), ``departed``, ``max_abs_e1``,
            ``max_abs_ay``, ``ay_violation_steps``, ``filter_active_steps`` (steps whose offset the
            safety filter changed), ``max_steering_rate`` [rad/s],
            ``information_gain``, ``return``, ``duration_s``.
        """
        r = self._rec
        if not r["t"]:
            raise RuntimeError("no records: step the env first (record=True)")
        plant = self.env.unwrapped.plant
        if not hasattr(plant, "true_axle_curve"):
            raise RuntimeError("the env's plant does not expose its true tire curve")
        obs_ = self.observer
        veh = self.vehicle
        tgt = dict(zip(AXLES, self.target))

        def nominal(alpha, axle):
            return 2.0 * (veh.Cf if axle == "front" else veh.Cr) * np.asarray(alpha)

        final = {a: curve_nrmse(obs_.axle_force, plant.true_axle_curve, a, -tgt[a], tgt[a]) for a in AXLES}
        t = np.asarray(r["t"])
        weights = np.asarray(r["weights"])
        errors = np.array(
            [
                max(
                    curve_nrmse(lambda al, ax, w=w: obs_.axle_force(al, ax, weights=w), plant.true_axle_curve, a, -tgt[a], tgt[a])
                    for a in AXLES
                )
                for w in weights
            ]
        )
        out: dict[str, Any] = {
            "tire_curve_nrmse": final,
            "tire_curve_nrmse_max": max(final.values()),
            "tire_curve_nrmse_nominal": {a: curve_nrmse(nominal, plant.true_axle_curve, a, -tgt[a], tgt[a]) for a in AXLES},
            "target_slip_deg": {a: math.degrees(tgt[a]) for a in AXLES},
        }
        if r["true_slip"]:
            slip = np.concatenate(r["true_slip"])
            ranges = {a: excited_range(slip[:, i]) for i, a in enumerate(AXLES)}
            out["excited_slip_range_deg"] = {a: [math.degrees(v) for v in ranges[a]] for a in AXLES}
            out["target_coverage"] = {
                a: max(0.0, min(ranges[a][1], tgt[a]) - max(ranges[a][0], -tgt[a])) / (2 * tgt[a]) for a in AXLES
            }
        slip_hat = np.asarray(r["slip_hat"])
        out["estimated_slip_range_deg"] = {
            a: [math.degrees(float(np.min(slip_hat[:, i]))), math.degrees(float(np.max(slip_hat[:, i])))]
            for i, a in enumerate(AXLES)
        }
        e1 = np.asarray(r["true_max_abs_e1"])
        ay = np.asarray(r["max_abs_ay"])
        out.update(
            convergence_time_s=convergence_time(t, errors, threshold),
            convergence_threshold=threshold,
            lane_violation_steps=int(np.sum(e1 > self.config.lane_margin)),
            departed=bool(self._departed),
            max_abs_e1=float(np.nanmax(e1)),
            max_abs_ay=float(np.max(ay)),
            ay_violation_steps=int(np.sum(ay > self.config.ay_limit)),
            filter_active_steps=int(np.sum(r["filter_active"])),
            max_steering_rate=float(np.max(r["steering_rate"])),
            information_gain=float(r["information"][-1] - self._j0),
            error_history={"t": t.tolist(), "nrmse_max": errors.tolist()},
            duration_s=float(t[-1]),
            steps=len(t),
            truth_draw=None if self.truth_draw is None else dict(self.truth_draw),
        )
        out["return"] = float(np.sum(r["reward"]))
        return out


def make_excitation_env(
    config: ExcitationConfig | Mapping | None = None,
    randomization: TruthRandomization | Mapping | bool | None = True,
    observer_config: ObserverConfig | None = None,
    record: bool = True,
    keep_history: bool = False,
    info_logs: bool = False,
    **env_kwargs: Any,
) -> ExcitationWrapper:
    """``LaneKeepingEnv`` -> :class:`EstimatorWrapper` -> :class:`ExcitationWrapper` (``TireLearning-Excitation-v0``).

    Parameters
    ----------
    config : ExcitationConfig or dict, optional
        Limits, reward and penalties.
    randomization : TruthRandomization, dict, True or None
        ``True`` (default): :class:`TruthRandomization` defaults; ``None``/``False``: the
        env's fixed truth.
    observer_config : ObserverConfig, optional
    record : bool
        Keep per-step records for :meth:`ExcitationWrapper.episode_metrics`.
    keep_history : bool
        Let the :class:`EstimatorWrapper` keep per-tick traces (memory; off for training).
    info_logs : bool
        Pass the per-tick ``sensor_log``/``truth_log`` on in ``info``.
    **env_kwargs
        :class:`~tire_learning_env.envs.LaneKeepingEnv` arguments; defaults here:
        ``road="straight"``, ``camera=EXCITATION_CAMERA``, and ``max_steering_offset``
        from ``config``.
    """
    from ..envs.lane_keeping import LaneKeepingEnv

    defaults = {"road": "straight", "camera": EXCITATION_CAMERA}
    return _wrap(LaneKeepingEnv, defaults, env_kwargs, config, randomization, observer_config, record, keep_history,
                 info_logs)  # fmt: skip


def make_highway_excitation_env(
    config: ExcitationConfig | Mapping | None = None,
    randomization: TruthRandomization | Mapping | bool | None = True,
    observer_config: ObserverConfig | None = None,
    record: bool = True,
    keep_history: bool = False,
    info_logs: bool = False,
    **env_kwargs: Any,
) -> ExcitationWrapper:
    """``HighwayTrafficEnv`` -> :class:`EstimatorWrapper` -> :class:`ExcitationWrapper` (``TireLearning-HighwayExcitation-v0``).

    The ego car weaves in its lane among highway-env traffic. Defaults:
    ``camera=EXCITATION_CAMERA``, ``lane_change="off"`` (a lane change moves the
    reference by a lane width, which the lane penalty would read as a departure),
    ``max_steering_offset`` from ``config``; other arguments as
    :func:`make_excitation_env` and :class:`~tire_learning_env.envs.highway.HighwayTrafficEnv`.
    """
    from ..envs.highway import HighwayTrafficEnv

    defaults = {"camera": EXCITATION_CAMERA, "lane_change": "off"}
    return _wrap(HighwayTrafficEnv, defaults, env_kwargs, config, randomization, observer_config, record, keep_history,
                 info_logs)  # fmt: skip


def _wrap(env_cls, defaults, env_kwargs, config, randomization, observer_config, record, keep_history, info_logs):
    """Base env (``defaults`` overridden by ``env_kwargs``; the steering-offset range from the
    config) -> :class:`EstimatorWrapper` -> :class:`ExcitationWrapper`."""
    cfg = coerce_params(ExcitationConfig, config, "config") or ExcitationConfig()
    base = env_cls(**{**defaults, **env_kwargs, "max_steering_offset": cfg.max_steering_offset})
    rnd = TruthRandomization() if randomization is True else (None if randomization is False else randomization)
    # the reward (information gain of P_w) and the committed policies were designed and trained on the
    # per-measurement law; the block law (AdaptationParams.causal_update, the default elsewhere) awaits a retraining
    obs_cfg = observer_config if observer_config is not None else ObserverConfig(causal_update="rls")
    est = EstimatorWrapper(base, config=obs_cfg, keep_history=keep_history)
    return ExcitationWrapper(est, config=cfg, randomization=rnd, record=record, info_logs=info_logs)
