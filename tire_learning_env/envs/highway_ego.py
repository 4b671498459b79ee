"""highway-env's view of the truth ego car (a vehicle whose pose the environment sets)."""

from __future__ import annotations

from typing import Any

from numpy.typing import NDArray

from highway_env.road.road import Road as HighwayRoad
from highway_env.vehicle.behavior import IDMVehicle

__all__ = ["TruthEgoVehicle"]


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
