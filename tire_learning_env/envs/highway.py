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


Modules: :mod:`.highway_lanes` (lane geometry, :class:`LaneReference`), :mod:`.highway_ego`
(the highway-env ego vehicle), :mod:`.highway_decisions` (lane-change rule, speed),
:mod:`.highway_rendering`, :mod:`.highway_traffic`
(the env core: physics chunking, target-lane switches, logs) and :mod:`.highway_scenes`
(the two scenes). This module re-exports their public names.
"""

from __future__ import annotations

from .highway_ego import TruthEgoVehicle
from .highway_lanes import LaneReference, lane_curvature
from .highway_scenes import HighwayTrafficEnv, RacetrackTrafficEnv
from .highway_traffic import LANE_ACTIONS, TRAFFIC_FEATURE_NAMES, TrafficEnv

__all__ = [
    "HighwayTrafficEnv",
    "RacetrackTrafficEnv",
    "TrafficEnv",
    "TruthEgoVehicle",
    "LaneReference",
    "lane_curvature",
    "TRAFFIC_FEATURE_NAMES",
    "LANE_ACTIONS",
]
