"""The ego car's decisions in the traffic scenes: lane changes (MOBIL rule or action) and speed (IDM).

:class:`EgoDecisions` is a mixin of the traffic env (:mod:`.highway_traffic`): it reads the
env's ego state (``s``, ``vx``, ``target_lane``, camera, highway-env ``road`` and ``ego``) and
starts a lane change through the env's ``_start_lane_change``.
"""

from __future__ import annotations

import math

import numpy as np

from highway_env.vehicle.kinematics import Vehicle as HighwayVehicle

__all__ = ["EgoDecisions", "LANE_KEEP", "LANE_ID_MINUS_1", "LANE_ID_PLUS_1"]

#: The discrete actions of ``lane_change="action"``: keep the lane, change to highway-env's lane
#: id - 1 (its ``LANE_LEFT`` on screen), change to lane id + 1 (``LANE_RIGHT``).
LANE_KEEP, LANE_ID_MINUS_1, LANE_ID_PLUS_1 = range(3)


class EgoDecisions:
    """Lane-change rule and longitudinal decision of the ego car (mixin of the traffic env)."""

    #: Time after a lane change ends before the next may start [s] (stops MOBIL ping-pong).
    LANE_CHANGE_COOLDOWN = 3.0
    #: Slowest speed at which the rule-based driver starts a lane change [m/s].
    LANE_CHANGE_MIN_SPEED = 5.0
    #: Strongest braking the ego's IDM may command [m/s^2] (highway-env's IDM clips at 6).
    EGO_MAX_BRAKING = 8.0

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
        self._pending_lane_action = LANE_KEEP
        if self._lane_change_busy():
            return
        index = self._side_lane(-1 if action == LANE_ID_MINUS_1 else 1)
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
