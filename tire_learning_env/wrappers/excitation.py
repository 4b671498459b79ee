"""``ExcitationWrapper``: steer to excite the slip angles the observer still has to learn.

:class:`ExcitationWrapper` turns a tire-learning environment (already wrapped by
:class:`~tire_learning_env.wrappers.EstimatorWrapper`) into a task for a reinforcement
learning agent: a normalised steering offset on top of the built-in lane-keeping driver,
rewarded with the information about the tire curve the observer gained, minus penalties.
The task itself (the information reward, penalties, safety filter, target slip range, truth
randomisation) is described and configured in :mod:`.excitation_task`;
:func:`make_excitation_env` and :func:`make_highway_excitation_env` build the registered envs.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from ..dynamics import StateIndex
from ..envs import OBSERVATION_NAMES
from ..metrics import AXLES, convergence_time, curve_nrmse, excited_range
from ..observer import ObserverConfig
from ..params import VehicleParams, coerce_params
from .estimator import EstimatorWrapper
from .excitation_task import (
    EXCITATION_CAMERA,
    INFORMATION_EDGES,
    ExcitationConfig,
    TruthRandomization,
    TruthSampler,
    target_functionals,
    target_slip_range,
)
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
# the base envs' observation entries read at reset
_OBS_VX, _OBS_KAPPA = OBSERVATION_NAMES.index("vx"), OBSERVATION_NAMES.index("kappa")


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
        Per-episode truth tires (``None``: the env's own fixed truth): the base env draws them at
        each reset from the seed, through the :class:`~.excitation_task.TruthSampler` given to its
        ``set_plant_sampler`` (:class:`~tire_learning_env.envs._base.TireLearningEnv`).
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
        self._sampler: TruthSampler | None = None
        if self.randomization is not None:
            if not hasattr(base, "set_plant_sampler"):
                raise TypeError(f"{type(base).__name__} takes no plant sampler; truth randomisation needs one")
            # the env draws the truth at each reset from its seed (TireLearningEnv.set_plant_sampler)
            self._sampler = self.randomization.sampler(self.vehicle, getattr(base, "effects", None))
            base.set_plant_sampler(self._sampler)
        self.target: tuple[float, float] = self.config.target(self.vehicle)
        self.target_functionals, self.target_names = target_functionals(
            self.observer.basis, self.vehicle, self.target, self.observer.n_weights
        )
        self.dt_policy = 1.0 / float(getattr(base, "policy_rate", 20.0))
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        n_obs = len(EXCITATION_OBSERVATION_NAMES) + len(self.target_names)
        self.observation_space = spaces.Box(-_OBS_BOUND, _OBS_BOUND, shape=(n_obs,), dtype=np.float32)
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
        obs, info = self.env.reset(seed=seed, options=options)
        if self._sampler is not None:
            self.truth_draw = self._sampler.last_draw
        self._p0_diag = np.diag(self.target_covariance()).copy()
        self._j0 = self._j = self.information()
        self._e0 = self._e = self.truth_error() if self.config.reward == "truth_nrmse" else math.nan
        self._prev_action = 0.0
        self._prev_delta_mean: float | None = None
        self._t = 0.0
        # the base envs observe [e1, e2, frame age, vx, kappa, delta]: start speed and curvature
        # (the highway ego starts slower than the nominal speed)
        self._last = {"e1_cam": 0.0, "e2_cam": 0.0, "ay": 0.0, "ay_max": 0.0, "delta": 0.0,
                      "kappa": float(obs[_OBS_KAPPA]), "vx": float(obs[_OBS_VX])}  # fmt: skip
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
        e1_hat = float(est["state"][StateIndex.E1])

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
            true_e1 = float(np.max(np.abs(info["truth_log"]["true_state"][:, StateIndex.E1])))
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
            x[StateIndex.E1] / cfg.lane_margin,
            x[StateIndex.E1_DOT] / 1.0,
            x[StateIndex.E2] / 0.05,
            x[StateIndex.E2_DOT] / 0.2,
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

    return _wrap(LaneKeepingEnv, {"road": "straight", "camera": EXCITATION_CAMERA}, config, randomization,
                 observer_config, record, keep_history, info_logs, **env_kwargs)  # fmt: skip


def make_highway_excitation_env(
    config: ExcitationConfig | Mapping | None = None,
    randomization: TruthRandomization | Mapping | bool | None = True,
    **kwargs: Any,
) -> ExcitationWrapper:
    """``HighwayTrafficEnv`` -> :class:`EstimatorWrapper` -> :class:`ExcitationWrapper` (``TireLearning-HighwayExcitation-v0``).

    The ego car weaves in its lane among highway-env traffic. Defaults:
    ``camera=EXCITATION_CAMERA``, ``lane_change="off"`` (a lane change moves the
    reference by a lane width, which the lane penalty would read as a departure),
    ``max_steering_offset`` from ``config``; the other arguments (``observer_config``,
    ``record``, ``keep_history``, ``info_logs`` and the env's) as :func:`make_excitation_env`
    and :class:`~tire_learning_env.envs.highway.HighwayTrafficEnv`.
    """
    from ..envs.highway import HighwayTrafficEnv

    return _wrap(HighwayTrafficEnv, {"camera": EXCITATION_CAMERA, "lane_change": "off"}, config, randomization, **kwargs)


def _wrap(env_cls, defaults, config=None, randomization=True, observer_config=None, record=True, keep_history=False,
          info_logs=False, **env_kwargs):  # fmt: skip
    """Base env (``defaults`` overridden by ``env_kwargs``; the steering-offset range from the
    config) -> :class:`EstimatorWrapper` -> :class:`ExcitationWrapper` (arguments as
    :func:`make_excitation_env`)."""
    cfg = coerce_params(ExcitationConfig, config, "config") or ExcitationConfig()
    base = env_cls(**{**defaults, **env_kwargs, "max_steering_offset": cfg.max_steering_offset})
    rnd = TruthRandomization() if randomization is True else (None if randomization is False else randomization)
    # the reward (information gain of P_w) and the committed policies were designed and trained on the
    # per-measurement law; the block law (AdaptationParams.causal_update, the default elsewhere) awaits a retraining
    obs_cfg = observer_config if observer_config is not None else ObserverConfig(causal_update="rls")
    est = EstimatorWrapper(base, config=obs_cfg, keep_history=keep_history)
    return ExcitationWrapper(est, config=cfg, randomization=rnd, record=record, info_logs=info_logs)
