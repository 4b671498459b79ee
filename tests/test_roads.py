"""Road geometry (roads.py): curvature, its rate, lane changes, user-defined roads."""

import numpy as np
import pytest

from tire_learning_env.roads import BUILTIN_ROADS, LaneChangeRoad, PiecewiseCurvatureRoad, study1_road
from tire_learning_env.simulation import simulate


def test_study1_road_geometry():
    road = study1_road()
    assert road.curvature(100.0) == 0.0
    assert road.curvature(600.0) == pytest.approx(1 / 300)
    assert road.curvature(1500.0) == pytest.approx(1 / 250)


@pytest.mark.parametrize("road", [study1_road(), LaneChangeRoad.repeated(), BUILTIN_ROADS["chirp"](__import__("tire_learning_env").RoadParams())])
def test_curvature_rate_is_the_derivative_of_curvature(road):
    s = np.linspace(1.0, 1800.0, 7001)
    s = s[np.abs(s[:, None] - np.asarray(getattr(road, "s_knots", [-1e9]))[None, :]).min(1) > 0.1]
    h = 1e-3
    numeric = (road.curvature(s + h) - road.curvature(s - h)) / (2 * h)
    np.testing.assert_allclose(road.curvature_rate(s), numeric, atol=1e-8)


def test_desired_yaw_is_consistent():
    road = LaneChangeRoad.repeated()
    s = np.linspace(0, 1800, 1000)
    pdd, pddd = road.desired_yaw(s, 30.0)
    np.testing.assert_allclose(pdd, 30.0 * road.curvature(s))
    np.testing.assert_allclose(pddd, 900.0 * road.curvature_rate(s))


def test_lane_change_moves_one_lane_width_and_returns_heading():
    road = LaneChangeRoad(starts=(100.0,), directions=(1,), change_length=90.0)
    geo = road.geometry(400.0, ds=0.05)
    assert geo["y"][-1] == pytest.approx(road.lane_width, rel=2e-3)
    assert abs(geo["heading"][-1]) < 1e-9
    assert road.lateral_target(1000.0) == pytest.approx(road.lane_width)


def test_user_defined_piecewise_road():
    road = PiecewiseCurvatureRoad.from_segments([(100.0, float("inf")), (200.0, -150.0)], transition_length=20.0)
    assert road.curvature(250.0) == pytest.approx(-1 / 150)
    log = simulate(road, 15.0)
    assert np.abs(log.truth["true_state"][:, 0]).max() < 0.5
