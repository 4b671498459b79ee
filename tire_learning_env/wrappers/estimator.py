"""``EstimatorWrapper``: the neuro-adaptive observer running inside any environment.

On every step the wrapper feeds the observer the step's ``info["sensor_log"]`` (what a
car knows: steering, speed, curvature, camera frames, yaw rate and lateral acceleration)
and nothing else, and puts the estimate in ``info["estimate"]``. Ground truth (``true_*``
keys) stays in ``info`` for scoring; the observer never reads it.

Measurement model (``sensors``): ``camera`` (default: ``e1``, ``e2``), ``imu`` (``ay``,
``yaw_rate``; state ``[vy, r]``) or ``both`` (camera and IMU fused), the same observer core
as :func:`~tire_learning_env.observer.estimate` with ``ObserverConfig(sensors=...)``.

>>> import gymnasium as gym
>>> import numpy as np
>>> import tire_learning_env
>>> from tire_learning_env.wrappers import EstimatorWrapper
>>> env = EstimatorWrapper(gym.make("TireLearning-Cornering-v0"))
>>> obs, info = env.reset(seed=0)
>>> for _ in range(200):
...     obs, reward, terminated, truncated, info = env.step(np.zeros(1, dtype=np.float32))
>>> sorted(info["estimate"])
['force', 'force_nonlinear', 'health', 'slip', 'state', 'std', 'weights']
>>> bool(abs(info["estimate"]["slip"][0] - info["true_slip"][0]) < 1e-3)
True
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from ..metrics import compute_metrics
from ..observer import ObserverConfig, build_observer
from ..observer.model import camera_path_bend
from ..observer.trace import EstimateTrace
from ..params import ParameterError
from ..simulation import SENSOR_KEYS

__all__ = ["EstimatorWrapper", "ESTIMATE_OBSERVATION_NAMES", "IMU_ESTIMATE_OBSERVATION_NAMES", "WRAPPER_SENSORS"]

ESTIMATE_OBSERVATION_NAMES = ("e1_hat", "e1_dot_hat", "e2_hat", "e2_dot_hat", "alpha_f_hat", "alpha_r_hat")
#: appended with ``sensors="imu"`` (no path states without a camera)
IMU_ESTIMATE_OBSERVATION_NAMES = ("vy_hat", "yaw_rate_hat", "alpha_f_hat", "alpha_r_hat")
#: measurement models the wrapper runs
WRAPPER_SENSORS = ("camera", "imu", "both")
_EST_HIGH = np.array([10.0, 20.0, np.pi, 10.0, 0.5, 0.5], dtype=np.float32)
_IMU_EST_HIGH = np.array([20.0, 5.0, 0.5, 0.5], dtype=np.float32)


class EstimatorWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Run the neuro-adaptive observer on every step of a tire-learning environment.

    Parameters
    ----------
    env : gymnasium.Env
        Any environment whose ``info`` carries ``sensor_log`` (every registered
        ``TireLearning-*`` id) and whose unwrapped env has ``estimator_inputs``.
    config : ObserverConfig, optional
        Observer settings (gains are synthesised once and cached on disk).
    append_to_observation : bool
        Append ``[e1_hat, e1_dot_hat, e2_hat, e2_dot_hat, alpha_f_hat, alpha_r_hat]`` to the
        observation (the ``Box`` is extended; values clipped to its bounds).
    keep_history : bool
        Keep the per-tick estimates and ground truth of the episode for :meth:`metrics`.
    initial_weights : array, optional
        Weights to start every episode from (e.g. learned on a previous drive).
    sensors : {"camera", "imu", "both"}, optional
        Measurement model; default ``config.sensors`` when it names one, else ``camera``.
        ``imu`` and ``both`` read the sensor log's ``ay`` and ``yaw_rate`` (one sample per
        physics tick in every env: the IMU period is the physics step).

    Notes
    -----
    ``info["estimate"]`` holds, at the end of the step (the instant of the ``true_*``
    keys; the prediction from the last frame): ``state`` (4,), ``slip`` (2,),
    ``force_nonlinear`` (2,), ``force`` (2,), ``weights`` (2N,), ``std`` (one-sigma of the
    internal state ``[v_y, r, e1, e2]``, weights' uncertainty included) and ``health``
    (``ok``, ``settling``, ``no_data``, ``inconsistent``, ``diverged`` or ``recovering``: the
    innovation test of :class:`~tire_learning_env.observer.HealthParams`).

    The camera's noise and latency come from the env's camera specification unless
    ``config`` gives them (the wrapper runs causally and cannot measure them first; the
    offline :func:`~tire_learning_env.observer.estimate` measures them from the log). The
    IMU noise is ``config.imu_noise``, else the core's assumption when nothing is known
    (:data:`~tire_learning_env.observer.estimator.NOISE_DEFAULT`: 0.5 m/s^2, 0.005 rad/s).

    With ``sensors="imu"`` the state is ``[vy, r]`` (``info["estimate"]["state"]`` has two
    entries) and ``append_to_observation`` appends :data:`IMU_ESTIMATE_OBSERVATION_NAMES`.
    With ``sensors="both"`` a step without IMU samples is corrected by the camera alone (and
    the other way round); the fused design stays (its basis and gains are the fused ones, so
    it is not the camera observer: ``tests/test_fusion.py``).
    """

    def __init__(
        self,
        env: gym.Env,
        config: ObserverConfig | None = None,
        append_to_observation: bool = False,
        keep_history: bool = True,
        initial_weights: NDArray | None = None,
        sensors: str | None = None,
    ) -> None:
        gym.utils.RecordConstructorArgs.__init__(
            self,
            config=config,
            append_to_observation=append_to_observation,
            keep_history=keep_history,
            initial_weights=initial_weights,
            sensors=sensors,
        )
        gym.Wrapper.__init__(self, env)
        inputs = getattr(env.unwrapped, "estimator_inputs", None)
        if inputs is None:
            raise TypeError(f"{type(env.unwrapped).__name__} does not expose estimator_inputs; not a tire-learning env")
        # wrappers that drop the per-tick logs to save memory (the excitation task runs its own
        # observer) are asked to pass them on: this wrapper needs them
        inner = env
        while isinstance(inner, gym.Wrapper):
            if hasattr(inner, "info_logs"):
                inner.info_logs = True
            inner = inner.env
        self.config = config or ObserverConfig()
        if sensors is None:
            sensors = self.config.sensors if self.config.sensors in WRAPPER_SENSORS else "camera"
        if sensors not in WRAPPER_SENSORS:
            raise ParameterError(f"sensors must be one of {WRAPPER_SENSORS}, got {sensors!r}")
        self.sensors = sensors
        uses_imu = sensors in ("imu", "both")
        self.observer = build_observer(
            inputs["vehicle"], inputs["camera"], self.config, inputs["physics_dt"], initial_weights=initial_weights,
            sensors=sensors, imu_period=inputs["physics_dt"] if uses_imu else None,
        )  # fmt: skip
        self._camera_x = float(inputs["vehicle"].camera_x)
        self._est_high = _IMU_EST_HIGH if sensors == "imu" else _EST_HIGH
        self.append_to_observation = append_to_observation
        self.keep_history = keep_history
        if append_to_observation:
            base = env.observation_space
            if not isinstance(base, spaces.Box) or len(base.shape) != 1:
                raise TypeError("append_to_observation needs a flat Box observation space")
            self.observation_space = spaces.Box(
                np.concatenate([base.low, -self._est_high]).astype(np.float32),
                np.concatenate([base.high, self._est_high]).astype(np.float32),
                dtype=np.float32,
            )
        self._traces: list[EstimateTrace] = []
        self._truth: list[dict] = []
        self._last: dict[str, Any] | None = None

    # -- gymnasium API ------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self.observer.reset()
        self._traces, self._truth = [], []
        self._last = self._estimate_now()
        info["estimate"] = self._last
        return self._observation(obs), info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if "sensor_log" not in info:
            raise KeyError(f"{self.env} gives no info['sensor_log'] (the per-tick sensor rows the observer needs); "
                           "wrap an env that passes it on")  # fmt: skip
        sensors = {k: info["sensor_log"][k] for k in SENSOR_KEYS}
        if self._camera_x and self.sensors != "imu":
            # a camera camera_x ahead of the CG: the observer measures e1 + camera_x sin(e2); the path's own bend over
            # camera_x goes back onto the logged e1, as estimate() does (observer.model.camera_path_bend)
            sensors["e1"] = np.asarray(sensors["e1"], dtype=float) + camera_path_bend(sensors["kappa"], self._camera_x)
        trace = self.observer.run(sensors)
        if self.keep_history:
            self._traces.append(trace)
            if "truth_log" in info:
                self._truth.append(info["truth_log"])
        # the estimate at the end of the step, the instant of the info's ground truth
        self._last = self.observer.estimate_now(sensors["delta"][-1], sensors["psi_dot_des"][-1], sensors["vx"][-1])
        info["estimate"] = self._last
        return self._observation(obs), reward, terminated, truncated, info

    @property
    def last_estimate(self) -> dict[str, Any] | None:
        """The estimate after the last ``reset``/``step`` (``info["estimate"]``); ``None`` before the first reset."""
        return self._last

    # -- helpers --------------------------------------------------------------------------
    def _estimate_now(self) -> dict[str, Any]:
        return self.observer.estimate_now(0.0, 0.0)

    def _observation(self, obs):
        if not self.append_to_observation:
            return obs
        est = np.concatenate([self._last["state"], self._last["slip"]]).astype(np.float32)
        return np.concatenate([np.asarray(obs, dtype=np.float32), np.clip(est, -self._est_high, self._est_high)])

    def tire_curve(self, slip: NDArray, axle: str = "front") -> NDArray:
        """Learned total axle force [N] at ``slip`` [rad] (eq. 29)."""
        return self.observer.axle_force(slip, axle)

    def cornering_stiffness(self) -> tuple[float, float]:
        """Per-tire cornering stiffness of the learned curve [N/rad]."""
        return self.observer.cornering_stiffness()

    @property
    def trace(self) -> EstimateTrace | None:
        """Per-tick estimates of the episode so far."""
        return EstimateTrace.concatenate(self._traces) if self._traces else None

    def metrics(self, burn_in: float = 2.0) -> dict:
        """Score the episode so far against the env's ground truth (``metrics.json`` keys)."""
        if not self._traces or not self._truth:
            raise RuntimeError("no history: step the env first (and keep keep_history=True)")
        trace = self.trace
        truth = {k: np.concatenate([d[k] for d in self._truth]) for k in self._truth[0]}
        base = self.env.unwrapped
        plant = getattr(base, "plant", None)
        if plant is None or not hasattr(plant, "true_axle_curve"):
            raise RuntimeError("the env's plant does not expose its true tire curve")
        veh = self.observer.vehicle
        # IMU only: no path states, so the e1/e2 scores are NaN (slip, curve and stiffness are scored)
        xi_hat = trace.xi if trace.has_pose else np.full((len(trace.t), 4), np.nan)
        return compute_metrics(
            t=trace.t,
            xi_hat=xi_hat,
            slip_hat=trace.slip,
            force_nonlinear_hat=trace.force_nonlinear,
            truth=truth,
            curve=self.observer.axle_force,
            true_curve=plant.true_axle_curve,
            stiffness_hat=self.observer.cornering_stiffness(),
            stiffness_true=plant.true_cornering_stiffness(),
            nominal_stiffness=(veh.Cf, veh.Cr),
            lmi=self.observer.gains.summary(),
            burn_in=burn_in,
        )
