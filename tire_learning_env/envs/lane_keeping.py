"""Gymnasium environments of a lane-keeping car with a nonlinear (Pacejka) truth tire."""

from __future__ import annotations

from typing import Any, Callable, Mapping

import numpy as np
from numpy.typing import NDArray

from ..dynamics import PlantEffects, StateIndex
from ..params import CameraParams, DriverParams, RoadParams, TireParams, VehicleParams
from ..rendering import TopDownRenderer
from ..roads import Road, make_road
from ..simulation import Plant, SimulationLog, Simulator
from ..tires import TireModel
from ._base import COMMON_CONFIG_KEYS, OBSERVATION_NAMES, TireLearningEnv

__all__ = ["LaneKeepingEnv", "OBSERVATION_NAMES"]


class LaneKeepingEnv(TireLearningEnv):
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
    ``config`` (a dict of any of these; unknown keys raise ``ParameterError``);
    ``plant_factory`` (``VehicleParams -> Plant``: the truth vehicle, built once) and
    ``plant_sampler`` (``np.random.Generator -> Plant``: a truth vehicle drawn at every reset
    from the seed, e.g. the excitation task's truth randomisation; see
    :meth:`~tire_learning_env.envs._base.TireLearningEnv.set_plant_sampler`).

    ## Version History

    * v0: initial release.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    _CONFIG_KEYS = ("road", "road_params") + COMMON_CONFIG_KEYS

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
        plant_sampler: Callable[[np.random.Generator], Plant] | None = None,
    ) -> None:
        args = self._arguments(locals(), config)
        self._init_params(args)
        self.road_params: RoadParams = self._params("road_params", args["road_params"])
        self.road: Road = make_road(args["road"], self.road_params)
        self._init_rates(args["physics_rate"], args["policy_rate"])
        self._init_task(args, lane_width=self.road.lane_width)
        plant = self._init_plant(args, plant_factory, plant_sampler)
        self.sim = Simulator(
            plant, self.road, self.camera_params, self.driver_params, self.vehicle, 1.0 / self.physics_rate
        )
        self._init_spaces()
        self._init_render_mode(render_mode)
        self._renderer: TopDownRenderer | None = None
        self._last_log: SimulationLog | None = None

    # -- gymnasium API --------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self._sample_plant(seed)
        xi0 = self.initial_state_std * self.np_random.standard_normal(4)
        if options and "initial_state" in options:
            xi0 = np.asarray(options["initial_state"], dtype=float).reshape(4)
        self.sim.reset(self.np_random, xi0)
        self._last_log = None
        obs = self._observation()
        return obs, self._info_now()

    def step(self, action):
        requested = self._check_steering_action(action)
        value = self._clip_steering(requested)
        if self.action_mode == "offset":
            log = self.sim.advance(self.ticks_per_step, steering_offset=value)
        else:
            log = self.sim.advance(self.ticks_per_step, steering=value)
        self._last_log = log
        e1_true = self.sim.plant.state[StateIndex.E1]
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
        return self._renderer.render(
            self.sim.s, x[StateIndex.E1], x[StateIndex.E2], self.vehicle.wheelbase + 1.8, self.vehicle.width
        )

    def set_plant(self, plant: Plant) -> None:
        """Use ``plant`` as the truth vehicle (here and in the simulator) from the next :meth:`reset` on."""
        super().set_plant(plant)
        self.sim.plant = plant

    # -- helpers ------------------------------------------------------------------------
    def _observation(self) -> NDArray[np.float32]:
        sim = self.sim
        kappa, _ = sim.table.lookup(sim.s)
        values = self._base_observation(sim.camera, sim.t, sim.speed_at(sim.t)[0], kappa, sim.last_delta)
        return self._clip_observation(values)

    def _info_now(self) -> dict[str, Any]:
        return self._plant_truth({"t": self.sim.t})
