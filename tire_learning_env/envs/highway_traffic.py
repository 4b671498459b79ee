"""The traffic env core: the truth ego car's physics in a highway-env scene (design: :mod:`.highway`)."""

from __future__ import annotations

import math
from typing import Any, Callable, Mapping, NamedTuple

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from highway_env.road.lane import AbstractLane
from highway_env.road.road import Road as HighwayRoad

from .._kernels import (
    CAMC_COUNT,
    CAMC_HEAD,
    CAMS_LATEST_E1,
    CAMS_LATEST_E2,
    CURVATURE_KNOTS,
    LOG_AX,
    N_LOG,
    NO_LANE_CHANGE,
    PEND_E1,
    PEND_E2,
    S_E1,
    S_E1_DOT,
    S_E2,
    S_E2_DOT,
    S_LAG_F,
    S_LAG_R,
    STOP_BLOWUP,
    STOP_HANDOVER,
    advance_ticks,
    bicycle_rhs,
    knot_lookup,
    lane_change_reference,
    preview_curvature,
)
from ..driver import LaneKeepingDriver
from ..params import ParameterError, VehicleParams, check_keys
from ..sensors import Camera
from ..simulation import Plant, advance_ticks_python, log_from_rows
from ._base import COMMON_CONFIG_KEYS, TireLearningEnv, choice, whole_rate_ratio
from .highway_decisions import LANE_ID_MINUS_1, LANE_ID_PLUS_1, LANE_KEEP, EgoDecisions
from .highway_ego import TruthEgoVehicle
from .highway_lanes import SWITCH_JOIN, SWITCH_LANE_CHANGE, LaneReference, wrap_angle
from .highway_rendering import make_viewer

__all__ = ["TrafficEnv", "TRAFFIC_FEATURE_NAMES", "LANE_ACTIONS"]

#: Per-vehicle traffic features appended to the observation when ``traffic_features > 0``.
TRAFFIC_FEATURE_NAMES = ("present", "ds", "dl", "dv")
#: Meaning of the discrete action when ``lane_change="action"`` (highway-env's lane ids).
LANE_ACTIONS = ("keep", "lane_id_minus_1", "lane_id_plus_1")
assert (LANE_ACTIONS.index("keep"), LANE_ACTIONS.index("lane_id_minus_1"), LANE_ACTIONS.index("lane_id_plus_1")) == (
    LANE_KEEP,
    LANE_ID_MINUS_1,
    LANE_ID_PLUS_1,
)

class LaneSwitch(NamedTuple):
    """A switch of the target lane during a step (``info["lane_switches"]``)."""

    row: int  # first log row relative to the new lane
    kind: int  # SWITCH_JOIN (hand-over between road segments) or SWITCH_LANE_CHANGE
    e1_jump: float  # [m]
    e2_jump: float  # [rad]
    kappa_before: float  # [1/m]
    kappa_after: float  # [1/m]


_TRAFFIC_HIGH = np.array([1.0, 200.0, 20.0, 50.0], dtype=np.float32)
_TRAFFIC_LOW = np.array([0.0, -200.0, -20.0, -50.0], dtype=np.float32)


class TrafficEnv(EgoDecisions, TireLearningEnv):
    """Shared machinery of the highway-env scenes (:mod:`.highway_scenes`; the design is in :mod:`.highway`).

    A scene overrides ``_build_network``, ``_speed_limit``, ``_populate`` and, optionally,
    ``_manage_traffic`` and ``_end_of_road``, as highway-env's scenes do.
    """

    #: Steepest heading of a lane-change path [rad]: sets its length at low speed.
    LANE_CHANGE_MAX_HEADING = 0.12

    _COMMON_KEYS = COMMON_CONFIG_KEYS + (
        "traffic_frequency",
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
        plant_sampler: Callable[[np.random.Generator], Plant] | None = None,
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

        self.lane_change = choice(args, "lane_change", ("rule", "action", "off"))
        self.longitudinal = choice(args, "longitudinal", ("idm", "constant"))
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

        self._init_plant(args, plant_factory, plant_sampler)
        self._compiled = hasattr(self.plant, "kernel_params")
        self.camera = Camera(self.camera_params, self.dt, camera_x=self.vehicle.camera_x)
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
        self._sample_plant(seed)
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
        self._lc = NO_LANE_CHANGE  # lane-change path: offset [m], start s [m], length [m]
        self._corridor_origin = 0.0  # centre of the lane being left, in target-lane e1 [m]
        self._decided = False
        self._pending_lane_action = LANE_KEEP
        self.lane_changes = 0
        self.crashed = False
        self.departed = False
        self._switches: list[LaneSwitch] = []
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
        if self.lane_change == "action" and self._pending_lane_action != LANE_KEEP and not ended:
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
        e1 = self.plant.state[S_E1]
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
            if a.size != 1 or not np.isfinite(a[0]) or a[0] != int(a[0]) or not LANE_KEEP <= int(a[0]) <= LANE_ID_PLUS_1:
                raise ValueError(f"action must be 0 (keep), 1 (lane id - 1) or 2 (lane id + 1), got {action!r}")
            self._pending_lane_action = int(a[0])
            return 0.0, math.nan
        requested = self._check_steering_action(action)
        value = self._clip_steering(requested)
        return (value, math.nan) if self.action_mode == "offset" else (0.0, value)

    def _start_lane_change(self, index: tuple) -> None:
        """Switch the target lane now; the driver follows a reference from the old lane centre."""
        d_e1 = self._switch_target(tuple(index), SWITCH_LANE_CHANGE, self._row)
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
                # flat arguments, each group unpacked in place (advance_ticks, Notes: per-call cost)
                s, vx, delta, done, status = advance_ticks(
                    left, self.dt, tick0, self.plant.state, self.s, self.vx, self.ax,
                    *self.plant.kernel_params(),
                    CURVATURE_KNOTS, ks, kv, 0.0, kcum,
                    s_stop, self.curvature_preview,
                    *self.camera.kernel_args(),
                    *self.driver.kernel_args(),
                    float(offset), float(steering), self.last_delta,
                    float(lc_offset), float(lc_s0), float(lc_len),
                    chunk,
                )  # fmt: skip
            else:
                preview = self.curvature_preview
                s, vx, delta, done, status = advance_ticks_python(
                    left, self.dt, tick0, self.plant, self.s, self.vx, self.ax, lambda x: knot_lookup(x, ks, kv),
                    self.camera, self.driver, float(offset), float(steering), self.last_delta, chunk, s_stop=s_stop,
                    feedforward_curvature=lambda x, v: preview_curvature(x, preview * v, ks, kv, kcum),
                    lane_change=(lc_offset, lc_s0, lc_len),
                )  # fmt: skip
            self.s, self.vx, self.last_delta = float(s), float(vx), float(delta)
            done_total += done
            if done:
                self._last_tick = (float(delta), float(chunk[done - 1, LOG_AX]))
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
                self._switch_target(h.next_index, SWITCH_JOIN, row0 + done_total)

    def _pose(self) -> tuple[NDArray, float]:
        lane = self.network.get_lane(self.target_lane)
        x = self.plant.state
        return lane.position(self.s, float(x[S_E1])), float(lane.heading_at(self.s) + x[S_E2])

    def _switch_target(self, new_index: tuple, kind: int, row: int) -> float:
        """Re-express the physical state relative to lane ``new_index``; returns the ``e1`` jump [m].

        A lane change re-expresses the car's pose in the new lane. A hand-over to the next
        segment maps along the reference path (which already turned with the next lane's
        curvature over the second half of the ramp): ``s`` continues from the hand-over point
        and ``e1``, ``e2`` change by the join's lateral offset and heading mismatch only.
        """
        x = self.plant.state
        e1, e1d, e2, e2d = (float(x[i]) for i in (S_E1, S_E1_DOT, S_E2, S_E2_DOT))
        k_old = self.reference.kappa(self.target_lane, self.s)
        if kind == SWITCH_JOIN:
            h = self.reference.handover(self.target_lane)
            s_new = h.s_next + (self.s - h.s_switch)
            e1_new = h.lateral + e1 * math.cos(h.heading)
            e2_new = e2 - h.heading
        else:
            position, heading = self._pose()
            new_lane = self.network.get_lane(new_index)
            s_new, e1_new = new_lane.local_coordinates(position)
            e2_new = float(wrap_angle(heading - new_lane.heading_at(s_new)))
        k_new = self.reference.kappa(new_index, s_new)
        vy = e1d - self.vx * e2  # lateral velocity: the same in every lane frame
        r = e2d + self.vx * k_old  # yaw rate: idem
        x[S_E1] = e1_new
        x[S_E1_DOT] = vy + self.vx * e2_new
        x[S_E2] = e2_new
        x[S_E2_DOT] = r - self.vx * k_new
        d_e1, d_e2 = e1_new - e1, e2_new - e2
        self._shift_camera(d_e1, d_e2)
        if kind == SWITCH_JOIN:  # keep the lane-change path's progress across the hand-over
            offset, s0, length = self._lc
            self._lc = (offset, s0 + (float(s_new) - self.s), length)
        self.target_lane = tuple(new_index)
        self.s = float(s_new)
        if self.ego is not None:
            self.ego.target_lane_index = self.target_lane
        if kind == SWITCH_JOIN and self._corridor_origin != 0.0:
            self._corridor_origin += d_e1
        self._switches.append(LaneSwitch(row, kind, d_e1, d_e2, k_old, k_new))
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
            pending[slot, PEND_E1] += d_e1  # NaN (dropped frame) stays NaN
            pending[slot, PEND_E2] += d_e2

    def _check_departure(self) -> None:
        e1 = float(self.plant.state[S_E1])
        d = self.departure_threshold
        o = self._corridor_origin
        _, lc_s0, lc_len = self._lc
        if o != 0.0 and self.s >= lc_s0 + lc_len and abs(e1) < d:
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
        e1 = float(self.plant.state[S_E1])
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
                x[S_E1_DOT], x[S_E2], x[S_E2_DOT], x[S_LAG_F], x[S_LAG_R], delta, self.vx, ax, self.vx * kappa, 0.0, *self.plant.kernel_params()
            )
            slip, force = np.array([af, ar]), np.array([Fyf, Fyr])
        elif hasattr(self.plant, "output"):
            out = self.plant.output()
            slip, force = np.asarray(out.slip, dtype=float), np.asarray(out.force, dtype=float)
        else:
            return {}
        return {
            "true_state": x[[S_E1, S_E1_DOT, S_E2, S_E2_DOT]],
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
        return log_from_rows(out, self.vehicle)

    def _switch_info(self) -> dict[str, NDArray]:
        sw = self._switches
        return {
            "row": np.array([w.row for w in sw], dtype=np.int64),
            "lane_change": np.array([w.kind == SWITCH_LANE_CHANGE for w in sw], dtype=bool),
            "e1_jump": np.array([w.e1_jump for w in sw], dtype=float),
            "e2_jump": np.array([w.e2_jump for w in sw], dtype=float),
            "kappa_before": np.array([w.kappa_before for w in sw], dtype=float),
            "kappa_after": np.array([w.kappa_after for w in sw], dtype=float),
        }

    # -- rendering ---------------------------------------------------------------------
    def _make_viewer(self):
        return make_viewer(self, self.traffic_frequency, self._VIEWER)
