"""highway-env traffic scenes with the nonlinear truth vehicle as the ego car.

The ego car's motion is the truth model of the base environments: the error-coordinate
bicycle model of SPEC §1 with Pacejka axle tires (or any plant, see ``plant_factory``),
integrated with RK4 at the physics rate (1 kHz by default) by the shared compiled
kernels. Its error state ``[e1, e1_dot, e2, e2_dot]`` is kept relative to the ego's
*target lane*, a highway-env lane object; the curvature comes from that lane's geometry
(heading change along the lane), and highway-env's ego vehicle object is placed at
``lane.position(s, e1)`` with heading ``lane.heading_at(s) + e2``, so that IDM/MOBIL
traffic, collisions and rendering all run through highway-env. Traffic is stepped by
highway-env at its own (lower) rate.

When the target lane changes (a lane change, or the hand-over to the next segment of a
road made of several lanes), the physical state (position, heading, lateral velocity,
yaw rate, tire lags) is kept and re-expressed in the new lane: ``e1`` jumps by the
lateral offset of the two lane centres (one lane width at a lane change), ``e2_dot``
jumps by ``-vx (kappa_new - kappa_old)``. Pending camera frames are re-expressed too, so
every frame the car receives refers to its current target lane. ``info["lane_switches"]``
lists each switch with the jumps, which a car knows (its planner decided it, its map
knows the lane offsets).

Two registered environments: :class:`HighwayTrafficEnv` (``TireLearning-Highway-v0``)
and :class:`RacetrackTrafficEnv` (``TireLearning-Racetrack-v0``); design notes and the
endurance result are in ``docs/highway.md``.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from highway_env.road.lane import AbstractLane, CircularLane, StraightLane
from highway_env.road.road import Road as HighwayRoad
from highway_env.road.road import RoadNetwork
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.kinematics import Vehicle as HighwayVehicle

from .._kernels import CAMC_COUNT, CAMC_HEAD, CAMS_LATEST_E1, CAMS_LATEST_E2, LOG_COLUMNS, N_LOG, bicycle_rhs
from ..driver import LaneKeepingDriver
from ..params import ParameterError, VehicleParams, check_keys
from ..sensors import Camera
from ..simulation import SENSOR_KEYS, Plant
from ._base import TireLearningEnv, whole_rate_ratio
from .highway_kernel import (
    STOP_BLOWUP,
    STOP_HANDOVER,
    advance_ego,
    advance_ego_python,
    knot_lookup,
    lane_change_reference,
)

__all__ = [
    "HighwayTrafficEnv",
    "RacetrackTrafficEnv",
    "TruthEgoVehicle",
    "LaneReference",
    "lane_curvature",
    "TRAFFIC_FEATURE_NAMES",
    "LANE_ACTIONS",
]

#: Per-vehicle traffic features appended to the observation when ``traffic_features > 0``.
TRAFFIC_FEATURE_NAMES = ("present", "ds", "dl", "dv")
#: Meaning of the discrete action when ``lane_change="action"`` (highway-env's lane ids).
LANE_ACTIONS = ("keep", "lane_id_minus_1", "lane_id_plus_1")

_COL = {name: i for i, name in enumerate(LOG_COLUMNS)}
_TRAFFIC_HIGH = np.array([1.0, 200.0, 20.0, 50.0], dtype=np.float32)
_TRAFFIC_LOW = np.array([0.0, -200.0, -20.0, -50.0], dtype=np.float32)
_SWITCH_JOIN, _SWITCH_LANE_CHANGE = 0, 1


def _wrap(angle):
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


def lane_curvature(lane: AbstractLane, s: NDArray) -> NDArray:
    """Curvature ``kappa(s)`` [1/m] of a highway-env lane's centre line, positive turning toward +lateral.

    Straight lanes are exactly 0 and circular lanes exactly ``direction / radius``; any other
    lane gets the central difference of ``heading_at`` over +/- 5 cm (the heading change along
    the lane).
    """
    s = np.asarray(s, dtype=float)
    if type(lane) is StraightLane:
        return np.zeros_like(s)
    if type(lane) is CircularLane:
        return np.full_like(s, lane.direction / lane.radius)
    h = 0.05
    try:
        up = np.asarray(lane.heading_at(s + h), dtype=float)
        down = np.asarray(lane.heading_at(s - h), dtype=float)
        if up.shape != s.shape:
            raise ValueError
    except (ValueError, TypeError):
        up = np.array([lane.heading_at(x + h) for x in s.ravel()]).reshape(s.shape)
        down = np.array([lane.heading_at(x - h) for x in s.ravel()]).reshape(s.shape)
    return _wrap(up - down) / (2.0 * h)


@dataclass(frozen=True)
class _Handover:
    """Where a lane hands the ego over to the next segment, and the join's mismatch there."""

    next_index: tuple
    s_switch: float  # [m] on the current lane
    s_next: float  # [m] the same point on the next lane
    lateral: float  # [m] the current lane's centre at the switch, in the next lane's frame
    heading: float  # [rad] next lane heading minus current lane heading there


def _is_constant_curvature(lane: AbstractLane) -> bool:
    return type(lane) in (StraightLane, CircularLane)


class LaneReference:
    """Lane geometry of a highway-env road network as the ego's reference path.

    For each lane it finds the successor (highway-env's ``next_lane``) and the hand-over
    point: the place near the lane end where the two centre lines agree best (highway-env
    joins some segments with small overlaps, kinks or lateral offsets; switching where the
    headings agree leaves at most the lateral offset of the join, up to 0.22 m on its
    racetrack).

    The reference curvature around the car (:meth:`profile`) is piecewise linear: each
    lane's own curvature (:func:`lane_curvature`), its predecessor's before the entry and
    its successor's after the hand-over, joined by linear ramps of width ``ramp`` centred on
    the hand-over points. A ramp has the same integral (heading change) as the curvature
    step of the join, so the reference heading is exact on both sides of it, and
    ``psi_ddot_des`` stays finite.

    Parameters
    ----------
    network : RoadNetwork
        highway-env road network (its lanes are not modified).
    ramp : float
        Width of the curvature ramp at a join [m].
    """

    _SAMPLE = 0.25  # [m] knot spacing on lanes of varying curvature

    def __init__(self, network: RoadNetwork, ramp: float = 0.1) -> None:
        self.network = network
        self.ramp = float(ramp)
        self._handover: dict[tuple, _Handover | None] = {}
        entering: dict[tuple, list[tuple]] = {}
        for index in network.lanes_dict():
            h = self._find_handover(index)
            self._handover[index] = h
            if h is not None:
                entering.setdefault(h.next_index, []).append(index)
        # the predecessor, when a lane is entered from exactly one other lane
        self._predecessor = {k: v[0] for k, v in entering.items() if len(v) == 1}

    def _find_handover(self, index: tuple) -> _Handover | None:
        lane = self.network.get_lane(index)
        end = lane.position(lane.length, 0.0)
        nxt = tuple(self.network.next_lane(index, position=end))
        if nxt == tuple(index) or nxt[:2] == tuple(index[:2]):
            return None
        nlane = self.network.get_lane(nxt)

        def mismatch(s: float) -> tuple[float, float, float]:
            sn, lat = nlane.local_coordinates(lane.position(s, 0.0))
            return sn, lat, float(_wrap(nlane.heading_at(sn) - lane.heading_at(s)))

        def cost(s: float) -> float:
            _, lat, dh = mismatch(s)
            return abs(lat) + 5.0 * abs(dh) + 1e-3 * abs(s - lane.length)  # tiny preference for the end

        lo = max(0.5 * lane.length, lane.length - 15.0)
        grid = np.arange(lo, lane.length + 3.0, 0.05)
        s0 = grid[int(np.argmin([cost(s) for s in grid]))]
        fine = np.arange(s0 - 0.05, s0 + 0.05, 0.002)
        s_best = float(fine[int(np.argmin([cost(s) for s in fine]))])
        sn, lat, dh = mismatch(s_best)
        return _Handover(nxt, s_best, float(sn), float(lat), dh)

    def handover(self, index: tuple) -> _Handover | None:
        """Successor and hand-over point of lane ``index`` (``None`` if the lane has no successor)."""
        return self._handover[tuple(index)]

    def s_stop(self, index: tuple) -> float:
        """Path coordinate [m] at which the ego is handed over to the next lane, or inf.

        It is the middle of the ramp: the next lane's profile has the same ramp around its
        entry, so curvature and ``psi_dot_des`` are continuous through the hand-over.
        """
        h = self._handover[tuple(index)]
        return math.inf if h is None else h.s_switch

    def _segments(self, index: tuple) -> list[tuple[float, float, AbstractLane, float]]:
        """``(s_from, s_to, lane, offset)``: on ``[s_from, s_to]`` the curvature is ``lane``'s at ``s + offset``."""
        index = tuple(index)
        own = self.network.get_lane(index)
        s_entry, s_exit = -math.inf, math.inf
        segs = []
        pred = self._predecessor.get(index)
        if pred is not None:
            hp = self._handover[pred]
            s_entry = hp.s_next
            segs.append((-math.inf, s_entry, self.network.get_lane(pred), hp.s_switch - hp.s_next))
        h = self._handover[index]
        if h is not None:
            s_exit = h.s_switch
        segs.append((s_entry, s_exit, own, 0.0))
        if h is not None:
            segs.append((s_exit, math.inf, self.network.get_lane(h.next_index), h.s_next - h.s_switch))
        return segs

    def profile(self, index: tuple, s_lo: float, s_hi: float) -> tuple[NDArray, NDArray, NDArray]:
        """Knots ``(ks, kv)`` of the curvature covering ``[s_lo, s_hi]`` and its running integral at the knots."""
        w2 = 0.5 * self.ramp
        lo, hi = s_lo - 1.0, s_hi + 1.0
        ks: list[NDArray] = []
        kv: list[NDArray] = []
        for a, b, lane, off in self._segments(index):
            a_eff = a + w2 if math.isfinite(a) else -math.inf
            b_eff = b - w2 if math.isfinite(b) else math.inf
            a_c, b_c = max(a_eff, lo - self.ramp), min(b_eff, hi + self.ramp)
            if a_c > b_c:
                continue
            if _is_constant_curvature(lane) or b_c - a_c < self._SAMPLE:
                pts = np.array([a_c, b_c]) if b_c - a_c > 1e-9 else np.array([a_c])
            else:
                pts = np.append(np.arange(a_c, b_c, self._SAMPLE), b_c)
                if pts[-1] - pts[-2] < 1e-9:
                    pts = pts[:-1]
            ks.append(pts)
            kv.append(lane_curvature(lane, pts + off))
        s = np.concatenate(ks)
        k = np.concatenate(kv)
        if len(s) == 1:
            s, k = np.array([s[0], s[0] + 1.0]), np.array([k[0], k[0]])
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (k[1:] + k[:-1]) * np.diff(s))])
        return np.ascontiguousarray(s), np.ascontiguousarray(k), cum

    def max_curvature_ahead(self, index: tuple, s: float, distance: float) -> float:
        """Largest ``|kappa|`` [1/m] of the lane centres from ``s`` to ``distance`` metres ahead (following hand-overs)."""
        kmax, cur, s_cur, left = 0.0, tuple(index), float(s), float(distance)
        for _ in range(50):
            lane = self.network.get_lane(cur)
            h = self._handover[cur]
            end = min(h.s_switch if h is not None else math.inf, s_cur + left)
            if end > s_cur:
                pts = np.array([s_cur, end]) if _is_constant_curvature(lane) else np.linspace(s_cur, end, 2 + int((end - s_cur) / self._SAMPLE))
                kmax = max(kmax, float(np.max(np.abs(lane_curvature(lane, pts)))))
                left -= end - s_cur
            if left <= 0.0 or h is None:
                break
            cur, s_cur = h.next_index, h.s_next
        return kmax

    def kappa(self, index: tuple, s: float) -> float:
        """Curvature [1/m] at ``s`` exactly as the physics kernel interpolates it."""
        ks, kv, _ = self.profile(index, s, s)
        return float(knot_lookup(s, ks, kv)[0])


class TruthEgoVehicle(IDMVehicle):
    """highway-env's view of the truth ego car.

    Its pose is set by the environment from the truth error state (:meth:`set_pose`); its
    :meth:`act` and :meth:`step` do not move it. It is an :class:`IDMVehicle` so that the
    environment can use highway-env's IDM (longitudinal) and MOBIL (lane-change) rules for
    it and traffic treats it like any controlled car (lane-change courtesy checks).
    """

    def __init__(self, road: HighwayRoad, position, heading: float, speed: float, length: float, width: float) -> None:
        self.LENGTH = float(length)
        self.WIDTH = float(width)
        super().__init__(road, position, heading, speed, enable_lane_change=False)
        self.color = (50, 200, 0)  # highway-env's ego green

    def act(self, action: Any = None) -> None:
        """Decisions are taken by the environment (see ``_decide``)."""

    def step(self, dt: float) -> None:
        """Only the decision timer advances; the pose comes from the truth physics."""
        self.timer += dt

    def set_pose(self, position: NDArray, heading: float, speed: float) -> None:
        """Place the car (and update highway-env's current lane)."""
        self.position[:] = position
        self.heading = float(heading)
        self.speed = float(speed)
        self.on_state_update()


class _ViewerScene:
    """The few attributes highway-env's ``EnvViewer`` reads from an env."""

    observation_type = None
    action_type = None

    def __init__(self, env: "_TrafficEnv", config: dict) -> None:
        self._env = env
        self.config = config

    @property
    def road(self):
        return self._env.road

    @property
    def vehicle(self):
        return self._env.ego

    def close(self) -> None:
        pass


class _TrafficEnv(TireLearningEnv):
    """Shared machinery of the highway-env scenes (see :class:`HighwayTrafficEnv`)."""

    #: Time after a lane change ends before the next may start [s] (stops MOBIL ping-pong).
    LANE_CHANGE_COOLDOWN = 3.0
    #: Steepest heading of a lane-change path [rad]: sets its length at low speed.
    LANE_CHANGE_MAX_HEADING = 0.12
    #: Slowest speed at which the rule-based driver starts a lane change [m/s].
    LANE_CHANGE_MIN_SPEED = 5.0
    #: Strongest braking the ego's IDM may command [m/s^2] (highway-env's IDM clips at 6).
    EGO_MAX_BRAKING = 8.0

    _COMMON_KEYS = (
        "vehicle",
        "tire",
        "tire_model",
        "tires",
        "camera",
        "driver",
        "effects",
        "physics_rate",
        "policy_rate",
        "traffic_frequency",
        "action_mode",
        "max_steering_offset",
        "departure_threshold",
        "initial_state_std",
        "lane_change",
        "lane_change_time",
        "vehicles_count",
        "target_speed",
        "initial_speed",
        "min_speed",
        "longitudinal",
        "traffic_features",
        "traffic_collisions",
        "curvature_preview",
        "max_lateral_acceleration",
    )
    _SCENE_KEYS: tuple[str, ...] = ()
    _DEFAULTS: dict[str, Any] = {}
    _VIEWER: dict[str, Any] = {}

    def __init__(
        self,
        render_mode: str | None = None,
        config: Mapping[str, Any] | None = None,
        plant_factory: Callable[[VehicleParams], Plant] | None = None,
        **kwargs: Any,
    ) -> None:
        allowed = self._COMMON_KEYS + self._SCENE_KEYS
        check_keys(f"{type(self).__name__} arguments", kwargs, allowed)
        args = dict(self._DEFAULTS)
        args.update(kwargs)
        self.config = args = self._merge_config(args, config, allowed)

        # scene first: the default vehicle speed is the scene's cruise speed
        self._build_network(args)
        self.reference = LaneReference(self.network)
        self.target_speed = float(args["target_speed"] if args["target_speed"] is not None else self._speed_limit())
        self.initial_speed = float(args["initial_speed"] if args["initial_speed"] is not None else self.target_speed)
        self.min_speed = float(args["min_speed"])
        if not (self.target_speed > 0 and self.initial_speed > 0 and self.min_speed > 0):
            raise ParameterError("target_speed, initial_speed and min_speed must be > 0 [m/s]")

        self._init_params(args, default_vehicle=VehicleParams(vx=self.target_speed) if args["vehicle"] is None else None)
        self.traffic_frequency = float(args["traffic_frequency"])
        if not self.traffic_frequency > 0:
            raise ParameterError("traffic_frequency must be > 0 [Hz]")
        self._init_rates(args["physics_rate"], args["policy_rate"])
        self.ticks_per_traffic = whole_rate_ratio(
            "physics_rate / traffic_frequency", self.physics_rate, self.traffic_frequency
        )
        self.dt = 1.0 / self.physics_rate

        if args["lane_change"] not in ("rule", "action", "off"):
            raise ParameterError(f"lane_change must be 'rule', 'action' or 'off', got {args['lane_change']!r}")
        self.lane_change = args["lane_change"]
        if args["longitudinal"] not in ("idm", "constant"):
            raise ParameterError(f"longitudinal must be 'idm' or 'constant', got {args['longitudinal']!r}")
        self.longitudinal = args["longitudinal"]
        self.lane_change_time = float(args["lane_change_time"])
        if not self.lane_change_time > 0:
            raise ParameterError("lane_change_time must be > 0 [s]")
        self.vehicles_count = int(args["vehicles_count"])
        if self.vehicles_count < 0:
            raise ParameterError("vehicles_count must be >= 0")
        self.traffic_features = int(args["traffic_features"])
        if self.traffic_features < 0:
            raise ParameterError("traffic_features must be >= 0")
        self.traffic_collisions = bool(args["traffic_collisions"])
        self.curvature_preview = float(args["curvature_preview"])
        self.max_lateral_acceleration = float(args["max_lateral_acceleration"])
        if not self.max_lateral_acceleration > 0:
            raise ParameterError("max_lateral_acceleration must be > 0 [m/s^2]")
        if not self.curvature_preview >= 0:
            raise ParameterError("curvature_preview must be >= 0 [s]")
        lane_width = self.network.get_lane(next(iter(self.network.lanes_dict()))).width_at(0.0)
        self.lane_width = float(lane_width)
        self._init_task(args, lane_width=self.lane_width)

        self._init_plant(args, plant_factory)
        self._compiled = hasattr(self.plant, "kernel_params")
        self.camera = Camera(self.camera_params, self.dt)
        self.driver = LaneKeepingDriver(self.driver_params, self.vehicle)

        self._init_spaces(
            list(_TRAFFIC_LOW) * self.traffic_features,
            list(_TRAFFIC_HIGH) * self.traffic_features,
            action_space=spaces.Discrete(3) if self.lane_change == "action" else None,
        )
        self._init_render_mode(render_mode)
        self._viewer = None
        self.road: HighwayRoad | None = None
        self.ego: TruthEgoVehicle | None = None

    # -- scene hooks (subclasses) ----------------------------------------------------
    def _build_network(self, args: dict) -> None:
        raise NotImplementedError

    def _speed_limit(self) -> float:
        raise NotImplementedError

    def _populate(self, rng: np.random.Generator) -> tuple[tuple, float]:
        """Create traffic on ``self.road``; return the ego's lane index and coordinate [m]."""
        raise NotImplementedError

    def _manage_traffic(self) -> None:
        """Called after each traffic step (e.g. recycle far vehicles)."""

    def _end_of_road(self) -> bool:
        return False

    # -- gymnasium API --------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        cam_seed, traffic_seed = self.np_random.integers(0, 2**63 - 1, size=2)
        self._traffic_rng = np.random.default_rng(int(traffic_seed))
        self.road = HighwayRoad(network=self.network, np_random=self._traffic_rng, record_history=False)
        self.ego = None
        lane_index, s0 = self._populate(self._traffic_rng)
        xi0 = self.initial_state_std * self.np_random.standard_normal(4)
        if options and "initial_state" in options:
            xi0 = np.asarray(options["initial_state"], dtype=float).reshape(4)
        self.plant.reset(xi0)
        self.camera.reset(np.random.default_rng(int(cam_seed)))
        self.driver.reset()
        self.target_lane = tuple(lane_index)
        self.s = float(s0)
        self.vx = self.initial_speed
        self.ax = 0.0
        self.tick_index = 0
        self.last_delta = 0.0
        self._lc = (0.0, 0.0, 1.0)  # lane-change path: offset [m], start s [m], length [m]
        self._corridor_origin = 0.0  # centre of the lane being left, in target-lane e1 [m]
        self._decided = False
        self._pending_lane_action = 0
        self.lane_changes = 0
        self.crashed = False
        self.departed = False
        self._switches: list[tuple] = []
        self._row = 0
        self._last_tick = None
        self._place_ego()
        return self._observation(), self._info_now()

    def step(self, action):
        if self.road is None:
            raise RuntimeError("call reset() before step()")
        offset, steering = self._parse_action(action)
        self._switches = []
        out = np.empty((self.ticks_per_step, N_LOG))
        row = 0
        ended = self.crashed or self.departed
        self._row = 0
        if self.lane_change == "action" and self._pending_lane_action and not ended:
            self._try_lane_change(self._pending_lane_action)
        while row < self.ticks_per_step:
            self._row = row
            phase = self.tick_index % self.ticks_per_traffic
            if phase == 0 and not self._decided and not ended:
                self._decide()
            n = min(self.ticks_per_step - row, self.ticks_per_traffic - phase)
            self._run_physics(n, offset, steering, out, row)
            row += n
            self.tick_index += n
            if self.tick_index % self.ticks_per_traffic == 0:
                self._decided = False
                if not ended:
                    self._place_ego()
                    self.road.step(1.0 / self.traffic_frequency)
                    self.crashed = bool(self.ego.crashed)
                    self._manage_traffic()
            if not ended:
                self._check_departure()
            ended = self.crashed or self.departed
        self._place_ego()
        log = self._as_logs(out)
        terminated = bool(self.crashed or self.departed)
        truncated = bool(self._end_of_road() and not terminated)
        e1 = self.plant.state[0]
        e1_ref = lane_change_reference(self.s, *self._lc)[0]
        reward = -1.0 if self.crashed else float(1.0 - ((e1 - e1_ref) / self.departure_threshold) ** 2)
        info = self._info_now()
        info["sensor_log"], info["truth_log"] = log
        info["lane_switches"] = self._switch_info()
        return self._observation(), reward, terminated, truncated, info

    def render(self):
        if self.render_mode != "rgb_array" or self.road is None:
            return None
        if self._viewer is None:
            self._viewer = self._make_viewer()
        self._viewer.display()
        return self._viewer.get_image()

    def close(self) -> None:
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None

    def set_plant(self, plant: Plant) -> None:
        """Use ``plant`` as the truth vehicle from the next :meth:`reset` on (compiled loop if it can)."""
        super().set_plant(plant)
        self._compiled = hasattr(plant, "kernel_params")

    # -- properties ---------------------------------------------------------------
    @property
    def t(self) -> float:
        """Simulated time [s]."""
        return self.tick_index * self.dt

    @property
    def target_lane_object(self) -> AbstractLane:
        """The highway-env lane the ego currently follows."""
        return self.network.get_lane(self.target_lane)

    # -- actions and decisions ----------------------------------------------------------
    def _parse_action(self, action) -> tuple[float, float]:
        if self.lane_change == "action":
            a = np.asarray(action).reshape(-1)
            if a.size != 1 or not np.isfinite(a[0]) or a[0] != int(a[0]) or not 0 <= int(a[0]) <= 2:
                raise ValueError(f"action must be 0 (keep), 1 (lane id - 1) or 2 (lane id + 1), got {action!r}")
            self._pending_lane_action = int(a[0])
            return 0.0, math.nan
        requested = self._check_steering_action(action)
        value = float(np.clip(requested, self.action_space.low[0], self.action_space.high[0]))
        return (value, math.nan) if self.action_mode == "offset" else (0.0, value)

    def _lane_change_busy(self) -> bool:
        """A new lane change waits for the last one to end (plus a cool-down) and a settled camera."""
        offset, s0, length = self._lc
        if offset != 0.0 and self.s < s0 + length + self.LANE_CHANGE_COOLDOWN * self.vx:
            return True
        e1, e2 = self.camera.latest
        return not (e1 == e1 and abs(e1) < 0.3 and abs(e2) < 0.05)

    def _side_lane(self, direction: int) -> tuple | None:
        _from, _to, _id = self.target_lane
        new_id = _id + direction
        if not 0 <= new_id < len(self.network.graph[_from][_to]):
            return None
        index = (_from, _to, new_id)
        if not self.network.get_lane(index).is_reachable_from(self.ego.position):
            return None
        return index

    def _try_lane_change(self, action: int) -> None:
        self._pending_lane_action = 0
        if self._lane_change_busy():
            return
        index = self._side_lane(-1 if action == 1 else 1)
        if index is not None:
            self._start_lane_change(index)

    def _decide(self) -> None:
        """Decisions at the start of a traffic step: traffic (IDM/MOBIL), ego lane change and speed."""
        self._place_ego()
        self.road.act()
        ego = self.ego
        if self.lane_change == "rule" and not self._lane_change_busy():
            if ego.timer > ego.LANE_CHANGE_DELAY:
                ego.timer = 0.0
                for index in self.network.side_lanes(self.target_lane):
                    if not self.network.get_lane(index).is_reachable_from(ego.position):
                        continue
                    if self.vx < self.LANE_CHANGE_MIN_SPEED:
                        continue
                    if ego.mobil(index):
                        self._start_lane_change(index)
                        break
        if self.longitudinal == "constant":
            self.ax = (self.target_speed - self.vx) * self.traffic_frequency
        else:
            ego.target_speed = self._cruise_speed()
            front, rear = self.road.neighbour_vehicles(ego, ego.lane_index)
            acc = ego.acceleration(ego_vehicle=ego, front_vehicle=front, rear_vehicle=rear)
            if ego.lane_index != ego.target_lane_index:
                front, rear = self.road.neighbour_vehicles(ego, ego.target_lane_index)
                acc = min(acc, ego.acceleration(ego_vehicle=ego, front_vehicle=front, rear_vehicle=rear))
            self.ax = float(np.clip(acc, -self.EGO_MAX_BRAKING, ego.ACC_MAX))
        horizon = 1.0 / self.traffic_frequency
        self.ax = max(self.ax, (self.min_speed - self.vx) / horizon)
        self.ax = min(self.ax, (HighwayVehicle.MAX_SPEED - self.vx) / horizon)
        self._decided = True

    def _cruise_speed(self) -> float:
        """``target_speed``, lowered so that no curve within the braking distance needs more than ``max_lateral_acceleration``."""
        reach = 2.0 * self.vx + self.vx**2 / (2.0 * 2.0)  # 2 s plus braking at 2 m/s^2 [m]
        kmax = self.reference.max_curvature_ahead(self.target_lane, self.s, reach)
        if kmax <= 0.0:
            return self.target_speed
        return min(self.target_speed, math.sqrt(self.max_lateral_acceleration / kmax))

    def _start_lane_change(self, index: tuple) -> None:
        """Switch the target lane now; the driver follows a reference from the old lane centre."""
        d_e1 = self._switch_target(tuple(index), _SWITCH_LANE_CHANGE, self._row)
        length = max(self.vx * self.lane_change_time, 1.875 * abs(d_e1) / self.LANE_CHANGE_MAX_HEADING)
        self._lc = (d_e1, self.s, length)
        self._corridor_origin = d_e1
        self.lane_changes += 1
        self.ego.target_lane_index = self.target_lane

    # -- physics ----------------------------------------------------------------------
    def _run_physics(self, n: int, offset: float, steering: float, out: NDArray, row0: int) -> None:
        done_total = 0
        guard = 0
        while done_total < n:
            left = n - done_total
            vx_hi = max(self.vx, self.vx + left * self.dt * self.ax)
            s_hi = self.s + left * self.dt * vx_hi + self.curvature_preview * vx_hi + 1.0
            ks, kv, kcum = self.reference.profile(self.target_lane, self.s - 0.5 * self.curvature_preview * vx_hi, s_hi)
            s_stop = self.reference.s_stop(self.target_lane)
            tick0 = self.tick_index + done_total
            chunk = out[row0 + done_total : row0 + n]
            lc_offset, lc_s0, lc_len = self._lc
            if self._compiled:
                self.camera.ensure_noise(left)
                s, vx, delta, done, status = advance_ego(
                    left, self.dt, tick0, self.plant.state, self.s, self.vx, self.ax, *self.plant.kernel_params(),
                    ks, kv, kcum, s_stop, self.curvature_preview, *self.camera.kernel_args(),
                    self.driver.param_vec, self.driver.state, self.driver.guard, float(offset), float(steering),
                    self.last_delta, lc_offset, lc_s0, lc_len, chunk,
                )  # fmt: skip
            else:
                s, vx, delta, done, status = advance_ego_python(
                    left, self.dt, tick0, self.plant, self.s, self.vx, self.ax, ks, kv, kcum, s_stop,
                    self.curvature_preview, self.camera, self.driver, float(offset), float(steering), self.last_delta,
                    lc_offset, lc_s0, lc_len, chunk,
                )  # fmt: skip
            self.s, self.vx, self.last_delta = float(s), float(vx), float(delta)
            done_total += done
            if done:
                self._last_tick = (float(delta), float(chunk[done - 1, _COL["ax"]]))
            if status == STOP_BLOWUP:
                t = (tick0 + done) * self.dt
                raise FloatingPointError(
                    f"ego physics blew up at t={t:.4f} s: state {np.asarray(self.plant.state).tolist()}, delta={delta}"
                )
            if status == STOP_HANDOVER:
                guard = guard + 1 if done == 0 else 0
                if guard > 3:
                    raise RuntimeError(f"lane hand-over loop at lane {self.target_lane}, s={self.s:.3f} m")
                h = self.reference.handover(self.target_lane)
                self._switch_target(h.next_index, _SWITCH_JOIN, row0 + done_total)

    def _pose(self) -> tuple[NDArray, float]:
        lane = self.network.get_lane(self.target_lane)
        x = self.plant.state
        return lane.position(self.s, float(x[0])), float(lane.heading_at(self.s) + x[2])

    def _switch_target(self, new_index: tuple, kind: int, row: int) -> float:
        """Re-express the physical state relative to lane ``new_index``; returns the ``e1`` jump [m].

        A lane change re-expresses the car's pose in the new lane. A hand-over to the next
        segment maps along the reference path (which already turned with the next lane's
        curvature over the second half of the ramp): ``s`` continues from the hand-over point
        and ``e1``, ``e2`` change by the join's lateral offset and heading mismatch only.
        """
        x = self.plant.state
        e1, e1d, e2, e2d = (float(v) for v in x[:4])
        k_old = self.reference.kappa(self.target_lane, self.s)
        if kind == _SWITCH_JOIN:
            h = self.reference.handover(self.target_lane)
            s_new = h.s_next + (self.s - h.s_switch)
            e1_new = h.lateral + e1 * math.cos(h.heading)
            e2_new = e2 - h.heading
        else:
            position, heading = self._pose()
            new_lane = self.network.get_lane(new_index)
            s_new, e1_new = new_lane.local_coordinates(position)
            e2_new = float(_wrap(heading - new_lane.heading_at(s_new)))
        k_new = self.reference.kappa(new_index, s_new)
        vy = e1d - self.vx * e2  # lateral velocity: the same in every lane frame
        r = e2d + self.vx * k_old  # yaw rate: idem
        x[0] = e1_new
        x[1] = vy + self.vx * e2_new
        x[2] = e2_new
        x[3] = r - self.vx * k_new
        d_e1, d_e2 = e1_new - e1, e2_new - e2
        self._shift_camera(d_e1, d_e2)
        if kind == _SWITCH_JOIN:  # keep the lane-change path's progress across the hand-over
            offset, s0, length = self._lc
            self._lc = (offset, s0 + (float(s_new) - self.s), length)
        self.target_lane = tuple(new_index)
        self.s = float(s_new)
        if self.ego is not None:
            self.ego.target_lane_index = self.target_lane
        if kind == _SWITCH_JOIN and self._corridor_origin != 0.0:
            self._corridor_origin += d_e1
        self._switches.append((row, kind, d_e1, d_e2, k_old, k_new))
        return d_e1

    def _shift_camera(self, d_e1: float, d_e2: float) -> None:
        """Re-express the held and the queued camera frames in the new target lane."""
        cstate, counters, pending = self.camera.state, self.camera.counters, self.camera.pending
        if cstate[CAMS_LATEST_E1] == cstate[CAMS_LATEST_E1]:
            cstate[CAMS_LATEST_E1] += d_e1
            cstate[CAMS_LATEST_E2] += d_e2
        cap = pending.shape[0]
        for k in range(int(counters[CAMC_COUNT])):
            slot = (int(counters[CAMC_HEAD]) + k) % cap
            pending[slot, 2] += d_e1  # NaN (dropped frame) stays NaN
            pending[slot, 3] += d_e2

    def _check_departure(self) -> None:
        e1 = float(self.plant.state[0])
        d = self.departure_threshold
        o = self._corridor_origin
        if o != 0.0 and self.s >= self._lc[1] + self._lc[2] and abs(e1) < d:
            self._corridor_origin = o = 0.0  # the manoeuvre is over: back to one lane
        if not (min(0.0, o) - d <= e1 <= max(0.0, o) + d):
            self.departed = True

    def _place_ego(self) -> None:
        position, heading = self._pose()
        if self.ego is None:
            v = self.vehicle
            self.ego = TruthEgoVehicle(self.road, position, heading, self.vx, v.wheelbase + 1.8, v.width)
            self.ego.target_speed = self.target_speed
            self.ego.target_lane_index = self.target_lane
            self.road.vehicles.insert(0, self.ego)
        else:
            self.ego.set_pose(position, heading, self.vx)

    # -- observation and info -----------------------------------------------------
    def _observation(self) -> NDArray[np.float32]:
        kappa = self.reference.kappa(self.target_lane, self.s)
        obs = self._base_observation(self.camera, self.t, self.vx, kappa, self.last_delta)
        if self.traffic_features:
            obs += list(self._traffic_observation())
        return self._clip_observation(obs)

    def _traffic_observation(self) -> NDArray:
        """``[present, ds, dl, dv]`` of the nearest vehicles in the target lane's frame."""
        lane = self.network.get_lane(self.target_lane)
        e1 = float(self.plant.state[0])
        rows = []
        for v in self.road.vehicles:
            if v is self.ego:
                continue
            d = float(np.hypot(*(v.position - self.ego.position)))
            if d > 200.0:
                continue
            s_v, l_v = lane.local_coordinates(v.position)
            dv = v.speed * math.cos(v.heading - lane.heading_at(s_v)) - self.vx
            rows.append((d, (1.0, s_v - self.s, l_v - e1, dv)))
        rows.sort(key=lambda r: r[0])
        feats = np.zeros((self.traffic_features, len(TRAFFIC_FEATURE_NAMES)))
        for i, (_, f) in enumerate(rows[: self.traffic_features]):
            feats[i] = f
        return feats.ravel()

    def _truth_now(self) -> dict[str, Any]:
        x = np.asarray(self.plant.state, dtype=float)
        veh = self.vehicle
        if self._compiled:
            delta, ax = self._last_tick if self._last_tick is not None else (self.last_delta, self.ax)
            kappa = self.reference.kappa(self.target_lane, self.s)
            *_, af, ar, Fyf, Fyr = bicycle_rhs(
                x[1], x[2], x[3], x[4], x[5], delta, self.vx, ax, self.vx * kappa, 0.0, *self.plant.kernel_params()
            )
            slip, force = np.array([af, ar]), np.array([Fyf, Fyr])
        elif hasattr(self.plant, "output"):
            out = self.plant.output()
            slip, force = np.asarray(out.slip, dtype=float), np.asarray(out.force, dtype=float)
        else:
            return {}
        return {
            "true_state": x[:4].copy(),
            "true_slip": slip,
            "true_force": force,
            "true_force_nonlinear": force - slip * np.array([2.0 * veh.Cf, 2.0 * veh.Cr]),
        }

    def _info_now(self) -> dict[str, Any]:
        info: dict[str, Any] = {"t": self.t}
        info.update(self._truth_now())
        info.update(
            crashed=bool(self.crashed),
            lane_departure=bool(self.departed),
            target_lane_index=tuple(self.target_lane),
            lane_changes=int(self.lane_changes),
            speed=float(self.vx),
        )
        return info

    def _as_logs(self, out: NDArray) -> tuple[dict, dict]:
        sensors = {key: out[:, _COL[key]].copy() for key in SENSOR_KEYS}
        slip = out[:, _COL["alpha_f"] : _COL["alpha_r"] + 1].copy()
        force = out[:, _COL["Fyf"] : _COL["Fyr"] + 1].copy()
        veh = self.vehicle
        truth = {
            "true_state": out[:, _COL["true_e1"] : _COL["true_e2_dot"] + 1].copy(),
            "true_slip": slip,
            "true_force": force,
            "true_force_nonlinear": force - slip * np.array([2.0 * veh.Cf, 2.0 * veh.Cr]),
            "s": out[:, _COL["s"]].copy(),
        }
        return sensors, truth

    def _switch_info(self) -> dict[str, NDArray]:
        sw = self._switches
        return {
            "row": np.array([w[0] for w in sw], dtype=np.int64),
            "lane_change": np.array([w[1] == _SWITCH_LANE_CHANGE for w in sw], dtype=bool),
            "e1_jump": np.array([w[2] for w in sw], dtype=float),
            "e2_jump": np.array([w[3] for w in sw], dtype=float),
            "kappa_before": np.array([w[4] for w in sw], dtype=float),
            "kappa_after": np.array([w[5] for w in sw], dtype=float),
        }

    # -- rendering ---------------------------------------------------------------------
    def _make_viewer(self):
        if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # headless
        from highway_env.envs.common.graphics import EnvViewer

        config = {
            "screen_width": 600,
            "screen_height": 150,
            "scaling": 5.5,
            "centering_position": [0.3, 0.5],
            "offscreen_rendering": True,
            "render_agent": True,
            "real_time_rendering": False,
            "simulation_frequency": self.traffic_frequency,
        }
        config.update(self._VIEWER)
        viewer = EnvViewer(_ViewerScene(self, config), config=config)
        viewer.enabled = True  # highway-env disables drawing under SDL's dummy driver; offscreen needs no display
        return viewer


class HighwayTrafficEnv(_TrafficEnv):
    """Multi-lane highway with IDM/MOBIL traffic; the ego car is the nonlinear truth vehicle.

    ## Description

    highway-env's straight multi-lane highway (``RoadNetwork.straight_road_network``, lanes
    4 m wide) with ``vehicles_count`` IDM/MOBIL vehicles created as in highway-env's
    ``highway-v0`` (``vehicles_density`` sets their spacing, speeds drawn from
    ``traffic_speed_range``). The ego car's lateral motion is the truth bicycle model with
    Pacejka tires at ``physics_rate`` (1 kHz), steered by the built-in lane-keeping driver
    from the lane camera (its curvature feed-forward eased over ``curvature_preview``); its
    speed follows highway-env's IDM toward ``target_speed`` (``longitudinal="idm"``),
    lowered before curves so that ``a_y <= max_lateral_acceleration``.

    Lane changes happen when MOBIL finds them worthwhile (``lane_change="rule"``: checked
    every second once the previous manoeuvre is over plus a 3 s cool-down, above 5 m/s) or
    on a discrete action (``lane_change="action"``). At the decision the target lane
    switches (``e1`` jumps by one lane width) and the lane-keeping driver flies the car to
    the new lane along a minimum-jerk lateral path from the old lane centre, of length
    ``max(vx * lane_change_time, 1.875 * width / 0.12)`` m (heading at most 0.12 rad).

    Traffic is stepped by highway-env at ``traffic_frequency``; the ego car decides (lane
    change, acceleration) at the start of each traffic step. Vehicles more than 200 m
    behind (or 400 m ahead of) the ego car are moved to the other side of it
    (``recycle_traffic``), so the traffic density around it holds on long runs.

    ## Action Space

    ``Box(-a_max, a_max, (1,), float32)``: steering [rad] added to the driver
    (``action_mode="offset"``, ``a_max = max_steering_offset``, default 0.05 rad) or
    replacing it (``"full"``), clipped; NaN/inf raises ``ValueError``. With
    ``lane_change="action"`` the action space is ``Discrete(3)`` instead: 0 keep lane,
    1 change to lane id - 1, 2 change to lane id + 1 (highway-env's ``LANE_LEFT`` /
    ``LANE_RIGHT`` as drawn on its screen), applied at the start of the step when no
    manoeuvre is under way; the driver steers without offset.

    ## Observation Space

    ``Box(6 + 4 K,)`` float32. The first six entries are those of
    :class:`~tire_learning_env.envs.lane_keeping.LaneKeepingEnv` (``e1, e2, frame_age,
    vx, kappa, last_delta``, same bounds), relative to the target lane. With
    ``traffic_features = K > 0``, ``K`` rows ``[present, ds, dl, dv]`` follow for the
    nearest vehicles within 200 m: longitudinal [m] and lateral [m] offset from the ego car
    in the target lane's frame and speed difference [m/s] (zeros when absent).

    Sign convention: ``e1`` is positive toward highway-env's +lateral direction (higher lane
    ids), the SPEC's "left" in a right-handed frame; ``kappa > 0`` turns that way.
    highway-env draws its y axis downward, so its pictures are mirror images.

    ## Rewards

    ``1 - ((e1 - e1_ref) / d)^2`` per step with ``e1_ref`` the lane-change path (0 when not
    changing lanes) and ``d`` the departure threshold; ``-1`` on a collision.

    ## Starting State

    Ego placed as highway-env's ``highway-v0`` places its ego (random lane unless
    ``initial_lane_id``), on the lane centre (``xi = 0`` plus ``initial_state_std`` noise,
    or ``options["initial_state"]``) at ``initial_speed`` (25 m/s); traffic ahead, the
    nearest car in its lane at least its IDM gap away.

    ## Episode End

    Terminated on a collision (highway-env's polygon test at the traffic rate) or a lane
    departure: the true ``e1`` leaves the corridor of the target lane (``|e1| <= d``, ``d``
    = half the lane width minus half the car width), widened during a lane change to include
    the lane being left. Truncated 100 m before the end of the road (``road_length``) and
    by the ``TimeLimit`` of the registered id (60 s). On termination the step still returns
    the full per-tick logs (traffic stops being stepped).

    ## Info

    The base env's keys (``t``, ``true_state``, ``true_slip``, ``true_force``,
    ``true_force_nonlinear``; per physics tick ``sensor_log`` with keys exactly
    ``simulation.SENSOR_KEYS`` and ``truth_log`` with ``simulation.TRUTH_KEYS``), plus
    ``crashed``, ``lane_departure``, ``target_lane_index``, ``lane_changes``, ``speed``
    [m/s] and ``lane_switches``: per switch of the target lane during the step, the log
    ``row`` from which the new lane applies, ``lane_change`` (False: hand-over between road
    segments), ``e1_jump`` [m], ``e2_jump`` [rad], ``kappa_before``/``kappa_after`` [1/m].
    ``e1_dot`` jumps by ``vx * e2_jump`` and ``e2_dot`` by ``-vx (kappa_after -
    kappa_before)`` at the same row (lateral velocity and yaw rate are continuous).

    ## Arguments

    ``vehicle``, ``tire``, ``tire_model``, ``tires``, ``camera``, ``driver``, ``effects``,
    ``physics_rate`` (1000 Hz), ``policy_rate`` (20 Hz), ``action_mode``,
    ``max_steering_offset``, ``departure_threshold``, ``initial_state_std`` as in
    :class:`~tire_learning_env.envs.lane_keeping.LaneKeepingEnv`; ``traffic_frequency``
    [Hz] (10), ``lane_change`` (``"rule"``, ``"action"`` or ``"off"``),
    ``lane_change_time`` [s] (3), ``vehicles_count`` (20), ``vehicles_density`` (1),
    ``traffic_speed_range`` [m/s] ((18, 27): wider than highway-env's 21-24 so that
    overtaking pays), ``lanes_count`` (3), ``road_length`` [m] (20000), ``initial_lane_id``,
    ``target_speed`` [m/s] (the speed limit, 30), ``initial_speed`` [m/s] (25), ``min_speed``
    [m/s] (1: the error-coordinate model is singular at standstill, so the ego never stops;
    it cannot wait behind a stopped obstacle), ``longitudinal`` (``"idm"`` or
    ``"constant"``: hold ``target_speed``), ``max_lateral_acceleration`` [m/s^2] (7),
    ``curvature_preview`` [s] (0.5; 0 = feed-forward of the current curvature, as the base
    envs), ``traffic_features`` (0), ``traffic_collisions`` (False: as in highway-env's
    ``highway-fast-v0`` only the ego car checks collisions), ``recycle_traffic`` (True),
    ``render_mode`` (``"rgb_array"``), ``config`` (a dict of any of these; unknown keys
    raise ``ParameterError``) and ``plant_factory`` (``VehicleParams -> Plant``: any plant
    of the :class:`~tire_learning_env.simulation.Plant` protocol whose ``state[:4]`` is the
    error state; plants without compiled parameters run in the Python twin of the loop).
    The default vehicle is the paper's sedan with ``vx = target_speed``.

    ## Version History

    * v0: initial release.
    """

    _SCENE_KEYS = (
        "lanes_count",
        "vehicles_density",
        "road_length",
        "initial_lane_id",
        "recycle_traffic",
        "traffic_speed_range",
    )
    _DEFAULTS = dict(
        vehicle=None,
        tire=None,
        tire_model="pacejka",
        tires=None,
        camera=None,
        driver=None,
        effects=None,
        physics_rate=1000.0,
        policy_rate=20.0,
        traffic_frequency=10.0,
        action_mode="offset",
        max_steering_offset=0.05,
        departure_threshold=None,
        initial_state_std=None,
        lane_change="rule",
        lane_change_time=3.0,
        vehicles_count=20,
        target_speed=None,
        initial_speed=25.0,
        min_speed=1.0,
        longitudinal="idm",
        traffic_features=0,
        traffic_collisions=False,
        curvature_preview=0.5,
        max_lateral_acceleration=7.0,
        lanes_count=3,
        vehicles_density=1.0,
        road_length=20000.0,
        initial_lane_id=None,
        recycle_traffic=True,
        traffic_speed_range=(18.0, 27.0),
    )
    _VIEWER = {"screen_width": 600, "screen_height": 150, "centering_position": [0.3, 0.5], "scaling": 5.5}
    _RECYCLE_BEHIND = 200.0  # [m]
    _RECYCLE_AHEAD = 400.0  # [m]

    def _build_network(self, args: dict) -> None:
        lanes = int(args["lanes_count"])
        if lanes < 1:
            raise ParameterError("lanes_count must be >= 1")
        self.road_length = float(args["road_length"])
        if not self.road_length > 500.0:
            raise ParameterError("road_length must be > 500 m")
        self.vehicles_density = float(args["vehicles_density"])
        if not self.vehicles_density > 0:
            raise ParameterError("vehicles_density must be > 0")
        self.initial_lane_id = args["initial_lane_id"]
        if self.initial_lane_id is not None and not 0 <= int(self.initial_lane_id) < lanes:
            raise ParameterError(f"initial_lane_id must be in [0, {lanes - 1}], got {self.initial_lane_id!r}")
        self.recycle_traffic = bool(args["recycle_traffic"])
        lo, hi = (float(v) for v in args["traffic_speed_range"])
        if not 0 < lo <= hi:
            raise ParameterError(f"traffic_speed_range must be (low, high) with 0 < low <= high [m/s], got {(lo, hi)}")
        self.traffic_speed_range = (lo, hi)
        self.network = RoadNetwork.straight_road_network(lanes, length=self.road_length, speed_limit=30.0)

    def _speed_limit(self) -> float:
        return 30.0

    def _populate(self, rng: np.random.Generator) -> tuple[tuple, float]:
        # the ego's place, as highway-env's highway-v0 chooses it (ego_spacing = 2)
        lane_id = None if self.initial_lane_id is None else int(self.initial_lane_id)
        probe = HighwayVehicle.create_random(self.road, speed=self.initial_speed, lane_id=lane_id, spacing=2.0)
        lane_index = probe.lane_index
        s0, _ = self.network.get_lane(lane_index).local_coordinates(probe.position)
        self.target_lane, self.s, self.vx = tuple(lane_index), float(s0), self.initial_speed
        self.plant.reset(None)
        self._place_ego()  # others are created ahead of it
        for _ in range(self.vehicles_count):
            speed = float(rng.uniform(*self.traffic_speed_range))
            v = IDMVehicle.create_random(self.road, speed=speed, spacing=1.0 / self.vehicles_density)
            v.randomize_behavior()
            v.check_collisions = self.traffic_collisions
            self.road.vehicles.append(v)
        # highway-env puts the first cars a dense-spacing gap ahead of its ego (about 11 m at
        # density 2), closer than any driver would start: move the traffic ahead so that the
        # ego starts at its IDM gap behind a car in its lane and 15 m from cars beside it.
        x_ego, y_ego = self.ego.position
        need = 0.0
        for v in self.road.vehicles[1:]:
            dx = v.position[0] - x_ego
            gap = IDMVehicle.DISTANCE_WANTED + IDMVehicle.TIME_WANTED * self.initial_speed
            need = max(need, (gap if abs(v.position[1] - y_ego) < 1.0 else 15.0) - dx)
        for v in self.road.vehicles[1:]:
            v.position[0] += need
            v.on_state_update()
        return lane_index, float(s0)

    def _longitudinal(self, v) -> float:
        return float(v.position[0])  # the road runs along +x

    def _manage_traffic(self) -> None:
        if not self.recycle_traffic:
            return
        x_ego = self._longitudinal(self.ego)
        others = [v for v in self.road.vehicles if v is not self.ego]
        for i, v in enumerate(self.road.vehicles):
            if v is self.ego:
                continue
            dx = self._longitudinal(v) - x_ego
            if dx < -self._RECYCLE_BEHIND:
                lo, hi = x_ego + 0.5 * self._RECYCLE_AHEAD, x_ego + 0.9 * self._RECYCLE_AHEAD
            elif dx > self._RECYCLE_AHEAD:
                lo, hi = x_ego - 0.9 * self._RECYCLE_BEHIND, x_ego - 0.5 * self._RECYCLE_BEHIND
            else:
                continue
            new = self._spawn(lo, hi, others)
            if new is not None:
                others.remove(v)
                others.append(new)
                self.road.vehicles[i] = new

    def _spawn(self, lo: float, hi: float, others: list) -> IDMVehicle | None:
        """A new IDM vehicle in ``[lo, hi]`` (x [m]) at least 30 m from any other in its lane, or None."""
        rng = self._traffic_rng
        lo, hi = max(lo, 10.0), min(hi, self.road_length - 10.0)
        if hi <= lo:
            return None
        n_lanes = len(self.network.graph["0"]["1"])
        for _ in range(10):
            lane_index = ("0", "1", int(rng.integers(n_lanes)))
            lane = self.network.get_lane(lane_index)
            x = float(rng.uniform(lo, hi))
            if any(abs(o.position[0] - x) < 30.0 and abs(o.position[1] - lane.position(x, 0)[1]) < 3.0 for o in others):
                continue
            if abs(self.ego.position[0] - x) < 30.0:
                continue
            speed = float(rng.uniform(*self.traffic_speed_range))
            v = IDMVehicle(self.road, lane.position(x, 0.0), lane.heading_at(x), speed)
            v.randomize_behavior()
            v.check_collisions = self.traffic_collisions
            return v
        return None

    def _end_of_road(self) -> bool:
        return self.s > self.road_length - 100.0


class RacetrackTrafficEnv(_TrafficEnv):
    """highway-env's racetrack (curves of several radii) with optional IDM/MOBIL traffic.

    ## Description

    The road network of highway-env's ``racetrack-v0`` (``track="racetrack"``: two 5 m
    lanes, 348 m, arcs of 15-30 m radius in both directions) or of its large variant
    (``track="racetrack-large"``: three lanes, 554 m). The ego car is the truth vehicle as
    in :class:`HighwayTrafficEnv` (same physics, driver, camera, lane changes, actions,
    observation, info and termination), cruising at the track's speed limit (10 m/s, so
    ``a_y`` reaches about 6.7 m/s^2 on the 15 m arcs: the tires work well into their
    nonlinear range; slower where ``max_lateral_acceleration`` requires it, e.g. the 10 m
    arc of the large track's inner lane). ``vehicles_count`` IDM vehicles (default 2)
    start at random places at least 20 m apart at 6-9 m/s, as in highway-env.

    Road segments are handed over where consecutive lanes agree best (see
    :class:`LaneReference`): headings agree there to 5e-4 rad, but highway-env's track
    has lateral offsets of up to 0.22 m at some joins, which appear as steps of ``e1`` at
    the hand-over rows listed in ``info["lane_switches"]`` (``lane_change = False``).
    Curvature steps between segments (no transition curves on this track) are ramps of
    0.1 m: ``psi_ddot_des`` is large but finite there.

    ## Arguments

    As :class:`HighwayTrafficEnv` without ``lanes_count``, ``vehicles_density``,
    ``road_length``, ``initial_lane_id``, ``recycle_traffic``, ``traffic_speed_range``;
    plus ``track`` (``"racetrack"`` or ``"racetrack-large"``). Defaults:
    ``vehicles_count=2``, ``target_speed`` and ``initial_speed`` = 10 m/s.

    ## Version History

    * v0: initial release.
    """

    _SCENE_KEYS = ("track",)
    _DEFAULTS = dict(HighwayTrafficEnv._DEFAULTS)
    for _k in HighwayTrafficEnv._SCENE_KEYS:
        _DEFAULTS.pop(_k)
    del _k
    _DEFAULTS.update(vehicles_count=2, initial_speed=None, track="racetrack")
    _VIEWER = {"screen_width": 600, "screen_height": 600, "centering_position": [0.5, 0.5], "scaling": 5.5}

    def _build_network(self, args: dict) -> None:
        import types

        from highway_env.envs.racetrack_env import RacetrackEnv, RacetrackEnvLarge

        tracks = {"racetrack": RacetrackEnv, "racetrack-large": RacetrackEnvLarge}
        if args["track"] not in tracks:
            raise ParameterError(f"track must be one of {sorted(tracks)}, got {args['track']!r}")
        self.track = args["track"]
        # highway-env builds the road in a method of its env; run it on a stand-in
        stand_in = types.SimpleNamespace(
            config={"show_trajectories": False, "neighbour_vehicles_connected_lanes": False, "speed_limit": 10.0},
            np_random=np.random.default_rng(0),
        )
        tracks[self.track]._make_road(stand_in)
        self.network = stand_in.road.network

    def _speed_limit(self) -> float:
        return 10.0

    def _populate(self, rng: np.random.Generator) -> tuple[tuple, float]:
        n_lanes = len(self.network.graph["a"]["b"])
        lane_index = ("a", "b", int(rng.integers(n_lanes)))
        s0 = float(rng.uniform(20.0, 50.0))
        self.target_lane, self.s, self.vx = lane_index, s0, self.initial_speed
        self.plant.reset(None)
        self._place_ego()
        lanes = list(self.network.lanes_dict())
        placed = 0
        for _ in range(50 * max(self.vehicles_count, 1)):
            if placed >= self.vehicles_count:
                break
            index = lanes[int(rng.integers(len(lanes)))]
            lane = self.network.get_lane(index)
            v = IDMVehicle.make_on_lane(
                self.road, index, longitudinal=float(rng.uniform(0.0, lane.length)), speed=6.0 + float(rng.uniform(0.0, 3.0))
            )
            if any(np.linalg.norm(v.position - o.position) < 20.0 for o in self.road.vehicles):
                continue
            v.check_collisions = self.traffic_collisions
            self.road.vehicles.append(v)
            placed += 1
        return lane_index, s0
