"""The excitation task: steer to excite the slip angles the observer still has to learn.

The observer only learns the part of the tire curve that the driving excites. The
wrapper (:class:`~.excitation.ExcitationWrapper`) turns a tire-learning environment (already wrapped by
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

This module holds the task's pieces (target slip range, information functionals, config, truth
draws); :class:`~.excitation.ExcitationWrapper` runs it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Mapping

import numpy as np
from numpy.typing import NDArray

from ..dynamics import BicyclePlant
from ..metrics import AXLES
from ..params import CameraParams, ParameterError, TireParams, VehicleParams, _Params
from ..tires import PacejkaTire

__all__ = [
    "ExcitationConfig",
    "TruthRandomization",
    "TruthSampler",
    "EXCITATION_CAMERA",
    "target_slip_range",
    "target_functionals",
    "INFORMATION_EDGES",
    "OFFSET_UNIT_SLIP",
]

#: Camera of the excitation envs: a production-like 30 Hz lane camera with Gaussian noise
#: (2 cm on e1, 0.2 deg on e2).
EXCITATION_CAMERA = CameraParams(rate=30.0, noise="gaussian", e1_noise=0.02, e2_noise=math.radians(0.2))

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

    def sampler(self, vehicle: VehicleParams, effects=None) -> "TruthSampler":
        """An env's ``plant_sampler`` drawing one truth per reset (:class:`TruthSampler`)."""
        return TruthSampler(self, vehicle, effects)


class TruthSampler:
    """``rng -> BicyclePlant``: a new truth of a :class:`TruthRandomization` per call.

    Handed to a tire-learning env as its ``plant_sampler``
    (:meth:`~tire_learning_env.envs._base.TireLearningEnv.set_plant_sampler`), which calls it
    at every reset with its truth generator.

    Parameters
    ----------
    randomization : TruthRandomization
    vehicle : VehicleParams
        Nominal vehicle (everything but the tires).
    effects : PlantEffects, optional
        Hidden effects of the truth plant.

    Attributes
    ----------
    last_draw : dict or None
        The latest draw (:meth:`TruthRandomization.draw`), ``None`` before the first call.
    """

    def __init__(self, randomization: TruthRandomization, vehicle: VehicleParams, effects=None) -> None:
        self.randomization = randomization
        self.vehicle = vehicle
        self.effects = effects
        self.last_draw: dict[str, float] | None = None

    def __call__(self, rng: np.random.Generator) -> BicyclePlant:
        self.last_draw = self.randomization.draw(rng)
        return self.randomization.build_plant(self.vehicle, self.last_draw, self.effects)
