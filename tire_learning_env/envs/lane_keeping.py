"""Gymnasium environments of a lane-keeping car with a nonlinear (Pacejka) truth tire."""

from __future__ import annotations

import math
from typing import Any, Callable, Mapping

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from ..dynamics import BicyclePlant, PlantEffects
from ..params import (
    CameraParams,
    DriverParams,
    ParameterError,
    RoadParams,
    TireParams,
    VehicleParams,
    check_keys,
    coerce_params,
)
from ..rendering import TopDownRenderer
from ..roads import Road, make_road
from ..simulation import Plant, SimulationLog, Simulator
from ..tires import TireModel, axle_tires

__all__ = ["LaneKeepingEnv", "OBSERVATION_NAMES"]

OBSERVATION_NAMES = ("e1", "e2", "frame_age", "vx", "kappa", "last_delta")

_PARAM_TYPES = {
    "vehicle": VehicleParams,
    "tire": TireParams,
    "camera": CameraParams,
    "driver": DriverParams,
    "effects": PlantEffects,
    "road_params": RoadParams,
}


def _as_params(name: str, value: Any):
    """The config entry ``name`` as its parameter dataclass (defaults when ``None``)."""
    cls = _PARAM_TYPES[name]
    return coerce_params(cls, value, name) or cls()


class LaneKeepingEnv(gym.Env):
    """A car keeping its lane at constant speed; the truth tire is nonlinear.

    ## Description

    The truth vehicle is the error-coordinate bicycle model of SPEC §1 with Pacejka
    Magic-Formula axle tires (or linear, or any :class:`~tire_learning_env.tires.TireModel`),
    integrated with RK4 at ``physics_rate`` (default 1 kHz). A lane camera measures
    ``e1`` (lateral offset) and ``e2`` (heading error) at its own rate, latency and noise.
    A built-in lane-keeping driver steers from the camera; the agent's action is added to
    it (``action_mode="offset"``) or replaces it (``action_mode="full"``). The agent acts
    at ``policy_rate`` (default 20 Hz); each step runs ``physics_rate / policy_rate``
    physics ticks.

    ## Action Space

    ``Box(-a_max, a_max, (1,), float32)``: road-wheel steering [rad]; an offset on top of
    the driver (``a_max = max_steering_offset``, default 0.05 rad) or the full angle
    (``a_max = driver.max_steering``). Actions outside the box are clipped; a NaN or
    infinite action raises ``ValueError``.

    ## Observation Space

    ``Box(6,)`` float32, what a car knows (at reset, before the first frame, ``e1 = e2 = 0``
    and ``frame_age = 10``):

    | index | name | unit | bounds |
    |---|---|---|---|
    | 0 | ``e1``: latest camera lateral offset | m | +/- 10 |
    | 1 | ``e2``: latest camera heading error | rad | +/- pi |
    | 2 | ``frame_age``: time since that frame showed | s | [0, 10] |
    | 3 | ``vx``: speed | m/s | [0, 100] |
    | 4 | ``kappa``: path curvature | 1/m | +/- 0.2 |
    | 5 | ``last_delta``: steering applied last tick | rad | +/- max steering |

    Values are clipped to the bounds (frame age saturates at 10 s).

    ## Rewards

    ``1 - (e1_true / d)^2`` per step, ``d`` the lane-departure threshold: a lane-keeping
    score in ``(0, 1]`` while in lane. Task-specific wrappers (excitation) replace it.

    ## Starting State

    ``xi = 0`` (on the path, aligned), as in the paper, plus Gaussian noise of
    ``initial_state_std`` (default zero) drawn from ``np_random``.

    ## Episode End

    Terminated when the true ``|e1|`` exceeds the departure threshold (default: half the
    lane width minus half the car width, i.e. a wheel on the marking). Truncation by the
    ``TimeLimit`` wrapper of the registered id (60 s by default).

    ## Info

    At the end of each step: ``t`` [s]; ground truth ``true_state`` (4,) ``[e1, e1_dot,
    e2, e2_dot]``, ``true_slip`` (2,) [rad], ``true_force`` (2,) axle lateral force [N],
    ``true_force_nonlinear`` (2,) ``F_y - 2 C alpha`` [N]; and per physics tick of the
    step: ``sensor_log`` (what a car knows: ``t, delta, vx, ax, kappa, psi_dot_des,
    psi_ddot_des, e1, e2`` (NaN without a frame), ``yaw_rate, ay``) and ``truth_log``
    (``true_state, true_slip, true_force, true_force_nonlinear, s``). Estimators read
    ``sensor_log`` only.

    ## Arguments

    ``road`` (name or :class:`~tire_learning_env.roads.Road`), ``vehicle``, ``tire``,
    ``tire_model`` (``"pacejka"``/``"linear"``), ``tires`` (explicit pair),
    ``camera``, ``driver``, ``effects``, ``road_params`` (dataclass or dict),
    ``physics_rate`` [Hz], ``policy_rate`` [Hz], ``action_mode``, ``max_steering_offset``
    [rad], ``departure_threshold`` [m], ``initial_state_std`` (4,), ``render_mode``,
    ``config`` (a dict of any of these; unknown keys raise ``ParameterError``).

    ## Version History

    * v0: initial release.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    _CONFIG_KEYS = (
        "road",
        "vehicle",
        "tire",
        "tire_model",
        "tires",
        "camera",
        "driver",
        "effects",
        "road_params",
        "physics_rate",
        "policy_rate",
        "action_mode",
        "max_steering_offset",
        "departure_threshold",
        "initial_state_std",
    )

    def __init__(
        self,
        road: str | Road = "study1",
        vehicle: VehicleParams | Mapping | None = None,
        tire: TireParams | Mapping | None = None,
        tire_model: str = "pacejka",
        tires: tuple[TireModel, TireModel] | None = None,
        camera: CameraParams | Mapping | None = None,
        driver: DriverParams | Mapping | None = None,
        effects: PlantEffects | Mapping | None = None,
        road_params: RoadParams | Mapping | None = None,
        physics_rate: float = 1000.0,
        policy_rate: float = 20.0,
        action_mode: str = "offset",
        max_steering_offset: float = 0.05,
        departure_threshold: float | None = None,
        initial_state_std: tuple[float, float, float, float] | None = None,
        render_mode: str | None = None,
        config: Mapping[str, Any] | None = None,
        plant_factory: Callable[[VehicleParams], Plant] | None = None,
    ) -> None:
        args = dict(
            road=road,
            vehicle=vehicle,
            tire=tire,
            tire_model=tire_model,
            tires=tires,
            camera=camera,
            driver=driver,
            effects=effects,
            road_params=road_params,
            physics_rate=physics_rate,
            policy_rate=policy_rate,
            action_mode=action_mode,
            max_steering_offset=max_steering_offset,
            departure_threshold=departure_threshold,
            initial_state_std=initial_state_std,
        )
        if config is not None:
            check_keys(f"{type(self).__name__} config", config, self._CONFIG_KEYS)
            args.update(config)
        self.vehicle: VehicleParams = _as_params("vehicle", args["vehicle"])
        self.tire_params: TireParams = _as_params("tire", args["tire"])
        self.camera_params: CameraParams = _as_params("camera", args["camera"])
        self.driver_params: DriverParams = _as_params("driver", args["driver"])
        self.effects: PlantEffects = _as_params("effects", args["effects"])
        self.road_params: RoadParams = _as_params("road_params", args["road_params"])
        self.road: Road = make_road(args["road"], self.road_params)
        self.physics_rate = float(args["physics_rate"])
        self.policy_rate = float(args["policy_rate"])
        if not (self.physics_rate > 0 and self.policy_rate > 0):
            raise ParameterError("physics_rate and policy_rate must be > 0")
        ratio = self.physics_rate / self.policy_rate
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ParameterError(
                f"physics_rate / policy_rate must be a whole number >= 1, got {self.physics_rate}/{self.policy_rate}"
            )
        self.ticks_per_step = int(round(ratio))
        if args["action_mode"] not in ("offset", "full"):
            raise ParameterError(f"action_mode must be 'offset' or 'full', got {args['action_mode']!r}")
        self.action_mode = args["action_mode"]
        self.max_steering_offset = float(args["max_steering_offset"])
        if not self.max_steering_offset > 0:
            raise ParameterError("max_steering_offset must be > 0")
        thr = args["departure_threshold"]
        self.departure_threshold = (
            0.5 * (self.road.lane_width - self.vehicle.width) if thr is None else float(thr)
        )
        if not self.departure_threshold > 0:
            raise ParameterError(f"departure_threshold must be > 0, got {self.departure_threshold!r}")
        std = args["initial_state_std"]
        self.initial_state_std = np.zeros(4) if std is None else np.asarray(std, dtype=float).reshape(4)

        if plant_factory is not None:
            plant = plant_factory(self.vehicle)
        else:
            front, rear = args["tires"] if args["tires"] is not None else axle_tires(
                self.vehicle, args["tire_model"], self.tire_params
            )
            plant = BicyclePlant(self.vehicle, front, rear, self.effects)
        self.plant = plant
        self.sim = Simulator(
            plant, self.road, self.camera_params, self.driver_params, self.vehicle, 1.0 / self.physics_rate
        )

        max_steer = self.driver_params.max_steering
        a_max = self.max_steering_offset if self.action_mode == "offset" else max_steer
        self.action_space = spaces.Box(-a_max, a_max, shape=(1,), dtype=np.float32)
        high = np.array([10.0, math.pi, 10.0, 100.0, 0.2, max_steer], dtype=np.float32)
        low = np.array([-10.0, -math.pi, 0.0, 0.0, -0.2, -max_steer], dtype=np.float32)
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self._obs_low, self._obs_high = low, high

        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ParameterError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode = render_mode
        self.metadata = dict(self.metadata, render_fps=int(round(self.policy_rate)))
        self._renderer: TopDownRenderer | None = None
        self._last_log: SimulationLog | None = None

    # -- gymnasium API --------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        xi0 = self.initial_state_std * self.np_random.standard_normal(4)
        if options and "initial_state" in options:
            xi0 = np.asarray(options["initial_state"], dtype=float).reshape(4)
        self.sim.reset(self.np_random, xi0)
        self._last_log = None
        obs = self._observation()
        return obs, self._info_now()

    def step(self, action):
        a = np.asarray(action, dtype=float).reshape(-1)
        if a.size != 1:
            raise ValueError(f"action must hold one steering value [rad], got shape {np.shape(action)}")
        if not np.isfinite(a[0]):
            raise ValueError(f"action must be finite, got {a[0]!r} (NaN or infinite steering)")
        value = float(np.clip(a[0], self.action_space.low[0], self.action_space.high[0]))
        if self.action_mode == "offset":
            log = self.sim.advance(self.ticks_per_step, steering_offset=value)
        else:
            log = self.sim.advance(self.ticks_per_step, steering=value)
        self._last_log = log
        e1_true = self.sim.plant.state[0]
        terminated = bool(abs(e1_true) > self.departure_threshold)
        reward = float(1.0 - (e1_true / self.departure_threshold) ** 2)
        info = self._info_now()
        info["sensor_log"] = log.sensors
        info["truth_log"] = log.truth
        return self._observation(), reward, terminated, False, info

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self._renderer is None:
            self._renderer = TopDownRenderer(self.road)
        x = self.sim.plant.state
        return self._renderer.render(self.sim.s, x[0], x[2], self.vehicle.wheelbase + 1.8, self.vehicle.width)

    # -- helpers ------------------------------------------------------------------------
    def _observation(self) -> NDArray[np.float32]:
        cam = self.sim.camera
        e1, e2 = cam.latest
        if e1 != e1:  # no frame delivered yet (at reset): zeros with the saturated age
            e1, e2, age = 0.0, 0.0, 10.0
        else:
            age = self.sim.t - cam.latest_time
        kappa, _ = self.sim.table.lookup(self.sim.s)
        obs = np.array([e1, e2, age, self.sim._speed(self.sim.t)[0], kappa, self.sim.last_delta], dtype=np.float32)
        return np.clip(obs, self._obs_low, self._obs_high)

    def _info_now(self) -> dict[str, Any]:
        out = self.sim.plant.output() if hasattr(self.sim.plant, "output") else None
        info: dict[str, Any] = {"t": self.sim.t}
        if out is not None:
            info.update(
                true_state=out.xi,
                true_slip=out.slip,
                true_force=out.force,
                true_force_nonlinear=out.force_nonlinear,
            )
        return info

    @property
    def estimator_inputs(self) -> dict[str, Any]:
        """What an estimator may know about this env: vehicle nominal params, rates, camera noise."""
        return {
            "vehicle": self.vehicle,
            "physics_dt": 1.0 / self.physics_rate,
            "camera": self.camera_params,
        }
