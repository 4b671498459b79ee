"""What every tire-learning env shares: config coercion, rates, the named observation, plant, truth.

:class:`TireLearningEnv` is the base of :class:`~.lane_keeping.LaneKeepingEnv` (and so of
:class:`~.high_order.HighOrderLaneKeepingEnv`) and of the highway-env traffic scenes
(:mod:`.highway`). A subclass parses its own arguments and calls the ``_init_*`` steps in
the order it needs (the traffic scenes build their road network before the default vehicle,
whose speed is the scene's cruise speed); it overrides hooks such as ``_observation`` and
``_info_now`` as highway-env's scenes override ``_reward``.

The truth vehicle is built once (``plant_factory(vehicle)``, default a :class:`BicyclePlant`)
and, with a ``plant_sampler`` (``rng -> plant``, e.g. the excitation task's truth
randomisation), drawn anew at every :meth:`~TireLearningEnv.reset` from the env's own truth
generator (:meth:`TireLearningEnv.truth_rng`), so no wrapper has to swap the plant.
"""

from __future__ import annotations

import math
from typing import Any, Callable, Mapping

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from ..dynamics import BicyclePlant, PlantEffects
from ..params import CameraParams, DriverParams, ParameterError, RoadParams, TireParams, VehicleParams, check_keys, coerce_params
from ..simulation import Plant
from ..tires import axle_tires

__all__ = [
    "TireLearningEnv",
    "OBSERVATION_NAMES",
    "OBSERVATION_BOUNDS",
    "NO_FRAME_AGE",
    "COMMON_CONFIG_KEYS",
    "PARAM_TYPES",
    "observation_bounds",
    "whole_rate_ratio",
    "choice",
    "TRUTH_SEED_TAG",
]

#: The base observation, in order (every env; the traffic scenes may append traffic features).
OBSERVATION_NAMES = ("e1", "e2", "frame_age", "vx", "kappa", "last_delta")

#: ``name -> (low, high)`` of each observation entry [SI units]; ``last_delta`` is bounded by the
#: driver's maximum steering (``None`` here, filled in by :func:`observation_bounds`).
OBSERVATION_BOUNDS: dict[str, tuple[float, float] | None] = {
    "e1": (-10.0, 10.0),  # [m]
    "e2": (-math.pi, math.pi),  # [rad]
    "frame_age": (0.0, 10.0),  # [s]
    "vx": (0.0, 100.0),  # [m/s]
    "kappa": (-0.2, 0.2),  # [1/m]
    "last_delta": None,  # [rad], +/- driver.max_steering
}

#: The order in which :meth:`TireLearningEnv._base_observation` lists its values (positionally,
#: as it runs at every env step); checked here against :data:`OBSERVATION_NAMES`.
_OBSERVATION_ORDER = ("e1", "e2", "frame_age", "vx", "kappa", "last_delta")
if OBSERVATION_NAMES != _OBSERVATION_ORDER:  # a guard for whoever edits the names
    raise ImportError(f"OBSERVATION_NAMES {OBSERVATION_NAMES} differ from _base_observation's order {_OBSERVATION_ORDER}")

#: Frame age observed before the camera delivered its first frame [s] (the bound: saturated).
NO_FRAME_AGE = 10.0

#: Config keys every env accepts (each adds its own: a road, a scene, the multi-body parameters).
COMMON_CONFIG_KEYS = (
    "vehicle",
    "tire",
    "tire_model",
    "tires",
    "camera",
    "driver",
    "effects",
    "physics_rate",
    "policy_rate",
    "action_mode",
    "max_steering_offset",
    "departure_threshold",
    "initial_state_std",
)

#: Mixed into a reset's seed for the truth generator of a ``plant_sampler`` (:meth:`TireLearningEnv.truth_rng`):
#: the truth drawn for a seed is independent of the env's own noise, and the same in every env.
TRUTH_SEED_TAG = 0x7E1E

#: Config entry -> the parameter dataclass it is coerced to (an instance or a dict).
PARAM_TYPES: dict[str, type] = {
    "vehicle": VehicleParams,
    "tire": TireParams,
    "camera": CameraParams,
    "driver": DriverParams,
    "effects": PlantEffects,
    "road_params": RoadParams,
}


def observation_bounds(max_steering: float) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """``(low, high)`` of the base observation (:data:`OBSERVATION_NAMES` order), float32.

    Parameters
    ----------
    max_steering : float
        Bound of ``last_delta`` [rad].
    """
    bounds = [OBSERVATION_BOUNDS[name] or (-max_steering, max_steering) for name in OBSERVATION_NAMES]
    return (
        np.array([lo for lo, _ in bounds], dtype=np.float32),
        np.array([hi for _, hi in bounds], dtype=np.float32),
    )


def whole_rate_ratio(name: str, fast: float, slow: float) -> int:
    """``fast / slow`` as an int, or :class:`ParameterError` naming ``name`` if it is not whole and >= 1."""
    ratio = fast / slow
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        raise ParameterError(f"{name} must be a whole number >= 1, got {fast}/{slow}")
    return int(round(ratio))


def choice(args: Mapping[str, Any], key: str, options: tuple[str, ...]) -> str:
    """``args[key]``, or :class:`ParameterError` naming ``key`` and ``options`` if it is not one of them."""
    value = args[key]
    if value not in options:
        either = ", ".join(repr(o) for o in options[:-1]) + f" or {options[-1]!r}"
        raise ParameterError(f"{key} must be {either}, got {value!r}")
    return value


class TireLearningEnv(gym.Env):
    """Base of the tire-learning envs: the parts their constructors and infos share.

    Attributes set by the ``_init_*`` steps: ``vehicle``, ``tire_params``, ``camera_params``,
    ``driver_params``, ``effects`` (:meth:`_init_params`); ``physics_rate``, ``policy_rate``,
    ``ticks_per_step`` (:meth:`_init_rates`); ``action_mode``, ``max_steering_offset``,
    ``departure_threshold``, ``initial_state_std`` (:meth:`_init_task`); ``plant``,
    ``plant_sampler`` (:meth:`_init_plant`); ``action_space``, ``observation_space``
    (:meth:`_init_spaces`); ``render_mode`` (:meth:`_init_render_mode`).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    #: Keys a ``config`` dict may hold (each subclass lists its own).
    _CONFIG_KEYS: tuple[str, ...] = ()

    # -- construction steps ----------------------------------------------------------------
    def _arguments(self, given: Mapping[str, Any], config: Mapping[str, Any] | None) -> dict[str, Any]:
        """The constructor's arguments: the entries of ``given`` (its ``locals()``) that are
        :attr:`_CONFIG_KEYS`, updated by ``config`` (:meth:`_merge_config`)."""
        return self._merge_config({k: v for k, v in given.items() if k in self._CONFIG_KEYS}, config)

    def _merge_config(self, args: dict[str, Any], config: Mapping[str, Any] | None, allowed=None) -> dict[str, Any]:
        """``args`` updated by ``config``; an unknown key raises :class:`ParameterError` naming it."""
        if config is not None:
            if not isinstance(config, Mapping):
                raise ParameterError(f"config must be a dict, got {type(config).__name__}")
            check_keys(f"{type(self).__name__} config", config, self._CONFIG_KEYS if allowed is None else allowed)
            args.update(config)
        return args

    @staticmethod
    def _params(name: str, value: Any, default: Any = None):
        """The config entry ``name`` as its :data:`PARAM_TYPES` dataclass; ``default`` (or the
        dataclass' defaults) when ``value`` is ``None``."""
        cls = PARAM_TYPES[name]
        coerced = coerce_params(cls, value, name)
        if coerced is not None:
            return coerced
        return cls() if default is None else default

    def _init_params(self, args: Mapping[str, Any], default_vehicle: VehicleParams | None = None) -> None:
        """``vehicle``, ``tire_params``, ``camera_params``, ``driver_params``, ``effects`` from ``args``."""
        self.vehicle: VehicleParams = self._params("vehicle", args["vehicle"], default_vehicle)
        self.tire_params: TireParams = self._params("tire", args.get("tire"))
        self.camera_params: CameraParams = self._params("camera", args["camera"])
        self.driver_params: DriverParams = self._params("driver", args["driver"])
        self.effects: PlantEffects = self._params("effects", args.get("effects"))

    def _init_rates(self, physics_rate: float, policy_rate: float) -> None:
        """``physics_rate``, ``policy_rate`` [Hz] and ``ticks_per_step`` (their whole ratio)."""
        self.physics_rate = float(physics_rate)
        self.policy_rate = float(policy_rate)
        if not (self.physics_rate > 0 and self.policy_rate > 0):
            raise ParameterError("physics_rate and policy_rate must be > 0 [Hz]")
        self.ticks_per_step = whole_rate_ratio("physics_rate / policy_rate", self.physics_rate, self.policy_rate)

    def _init_task(self, args: Mapping[str, Any], lane_width: float) -> None:
        """Action mode, steering-offset bound, departure threshold (default: a wheel on the
        marking of a ``lane_width`` [m] lane) and initial-state noise."""
        self.action_mode = choice(args, "action_mode", ("offset", "full"))
        self.max_steering_offset = float(args["max_steering_offset"])
        if not self.max_steering_offset > 0:
            raise ParameterError("max_steering_offset must be > 0 [rad]")
        thr = args["departure_threshold"]
        self.departure_threshold = 0.5 * (lane_width - self.vehicle.width) if thr is None else float(thr)
        if not self.departure_threshold > 0:
            raise ParameterError(f"departure_threshold must be > 0, got {self.departure_threshold!r}")
        std = args["initial_state_std"]
        self.initial_state_std = np.zeros(4) if std is None else np.asarray(std, dtype=float).reshape(4)

    def _init_plant(
        self,
        args: Mapping[str, Any],
        plant_factory: Callable[[VehicleParams], Plant] | None = None,
        plant_sampler: Callable[[np.random.Generator], Plant] | None = None,
    ) -> Plant:
        """The truth plant: ``plant_factory(vehicle)``, else a :class:`BicyclePlant` on the
        ``tires`` pair or on ``axle_tires(vehicle, tire_model, tire_params)``; and the
        per-episode ``plant_sampler`` (:meth:`set_plant_sampler`)."""
        self._truth_rng: np.random.Generator | None = None
        self.set_plant_sampler(plant_sampler)
        if plant_factory is not None:
            plant = plant_factory(self.vehicle)
        else:
            front, rear = (
                args["tires"] if args["tires"] is not None else axle_tires(self.vehicle, args["tire_model"], self.tire_params)
            )
            plant = BicyclePlant(self.vehicle, front, rear, self.effects)
        self.plant = plant
        return plant

    def _init_spaces(self, extra_low=(), extra_high=(), action_space: spaces.Space | None = None) -> None:
        """The observation space (:data:`OBSERVATION_NAMES` then ``extra_*``) and the action space
        (default: a steering offset within ``max_steering_offset``, or the full angle)."""
        max_steer = self.driver_params.max_steering
        if action_space is None:
            a_max = self.max_steering_offset if self.action_mode == "offset" else max_steer
            action_space = spaces.Box(-a_max, a_max, shape=(1,), dtype=np.float32)
        self.action_space = action_space
        low, high = observation_bounds(max_steer)
        low = np.concatenate([low, np.asarray(extra_low, dtype=np.float32)])
        high = np.concatenate([high, np.asarray(extra_high, dtype=np.float32)])
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self._obs_low, self._obs_high = low, high

    def _init_render_mode(self, render_mode: str | None) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ParameterError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode = render_mode
        self.metadata = dict(self.metadata, render_fps=int(round(self.policy_rate)))

    def set_plant(self, plant: Plant) -> None:
        """Use ``plant`` as the truth vehicle from the next :meth:`reset` on. Subclasses that hand
        the plant on (a simulator) override this."""
        self.plant = plant

    def set_plant_sampler(self, sampler: Callable[[np.random.Generator], Plant] | None) -> None:
        """Draw the truth vehicle at every :meth:`reset` as ``sampler(rng)`` (``None``: keep the plant).

        ``rng`` is :meth:`truth_rng`: seeded by the reset's seed (mixed with
        :data:`TRUTH_SEED_TAG`), continued by a reset without one, so the truth of a seed does
        not depend on the env's other random streams.
        """
        if sampler is not None and not callable(sampler):
            raise ParameterError(f"plant_sampler must be a callable rng -> plant, got {type(sampler).__name__}")
        self.plant_sampler = sampler

    def truth_rng(self, seed: int | None) -> np.random.Generator:
        """The truth generator of a reset with ``seed``: a new one for a seed, else the current one
        (a fresh unseeded one the first time)."""
        if seed is not None:
            self._truth_rng = np.random.default_rng(np.random.SeedSequence([int(seed), TRUTH_SEED_TAG]))
        elif self._truth_rng is None:
            self._truth_rng = np.random.default_rng()
        return self._truth_rng

    def _sample_plant(self, seed: int | None) -> None:
        """At the start of :meth:`reset`: the episode's truth vehicle from the ``plant_sampler``, if any."""
        if self.plant_sampler is not None:
            self.set_plant(self.plant_sampler(self.truth_rng(seed)))

    # -- shared step pieces --------------------------------------------------------------------
    @staticmethod
    def _check_steering_action(action) -> float:
        """The one finite steering value of ``action`` [rad]; ``ValueError`` otherwise."""
        a = np.asarray(action, dtype=float).reshape(-1)
        if a.size != 1:
            raise ValueError(f"action must hold one steering value [rad], got shape {np.shape(action)}")
        if not np.isfinite(a[0]):
            raise ValueError(f"action must be finite, got {a[0]!r} (NaN or infinite steering)")
        return float(a[0])

    def _clip_steering(self, value: float) -> float:
        """``value`` [rad] clipped to the action box, as ``np.clip`` clips it (a float between
        the box's float32 bounds), without numpy's dispatch for one number."""
        space = self.action_space
        return min(max(value, float(space.low[0])), float(space.high[0]))

    def _base_observation(self, camera, t: float, vx: float, kappa: float, last_delta: float) -> list[float]:
        """The :data:`OBSERVATION_NAMES` values (unclipped): the camera's latest frame and its age at ``t``.

        Listed positionally in :data:`OBSERVATION_NAMES` order (``_OBSERVATION_ORDER``, checked
        against the names on import): a dict by name and a lookup per name cost about 0.5 us of an
        env step (issue 20, ``benchmarks/results/env_step_ab_issue20.json``).
        """
        e1, e2 = camera.latest
        if e1 != e1:  # no frame delivered yet (at reset): zeros with the saturated age
            e1, e2, age = 0.0, 0.0, NO_FRAME_AGE
        else:
            age = t - camera.latest_time
        return [e1, e2, age, vx, kappa, last_delta]

    def _clip_observation(self, values) -> NDArray[np.float32]:
        """``values`` as float32, clipped to the observation bounds (``ndarray.clip``, which ``np.clip`` calls)."""
        return np.array(values, dtype=np.float32).clip(self._obs_low, self._obs_high)

    def _plant_truth(self, info: dict[str, Any]) -> dict[str, Any]:
        """``info`` with the ground truth at the plant's current state from its ``output()`` added
        (nothing without one); returns ``info``."""
        out = self.plant.output() if hasattr(self.plant, "output") else None
        if out is not None:
            info["true_state"] = out.xi
            info["true_slip"] = out.slip
            info["true_force"] = out.force
            info["true_force_nonlinear"] = out.force_nonlinear
        return info

    @property
    def estimator_inputs(self) -> dict[str, Any]:
        """What an estimator may know about this env: vehicle nominal params, rates, camera noise."""
        return {"vehicle": self.vehicle, "physics_dt": 1.0 / self.physics_rate, "camera": self.camera_params}
