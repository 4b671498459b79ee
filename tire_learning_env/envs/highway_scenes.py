"""The two registered traffic scenes: highway-env's straight highway and its racetracks."""

from __future__ import annotations

import numpy as np

from highway_env.road.road import RoadNetwork
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.kinematics import Vehicle as HighwayVehicle

from ..params import ParameterError
from .highway_traffic import TrafficEnv

__all__ = ["HighwayTrafficEnv", "RacetrackTrafficEnv"]


class HighwayTrafficEnv(TrafficEnv):
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
    error state; plants without compiled parameters run in the Python twin of the loop) and
    ``plant_sampler`` (``np.random.Generator -> Plant``: a truth vehicle drawn at every reset,
    :meth:`~tire_learning_env.envs._base.TireLearningEnv.set_plant_sampler`).
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


class RacetrackTrafficEnv(TrafficEnv):
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
