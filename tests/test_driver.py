"""The built-in lane-keeping driver (driver.py) keeps its lane on every road."""

import numpy as np
import pytest

from tire_learning_env.params import CameraParams
from tire_learning_env.roads import BUILTIN_ROADS
from tire_learning_env.simulation import simulate


@pytest.mark.parametrize("road", sorted(BUILTIN_ROADS))
def test_driver_keeps_lane_on_every_builtin_road(road):
    log = simulate(road, 60.0, camera=CameraParams(rate=1000.0))
    assert np.abs(log.truth["true_state"][:, 0]).max() < 0.5


@pytest.mark.parametrize("road", ["study1", "lane_changes", "chirp"])
def test_driver_keeps_lane_with_a_noisy_20hz_camera(road):
    log = simulate(road, 60.0, camera=CameraParams.paper_noise(rate=20.0, latency=0.05), seed=3)
    assert np.abs(log.truth["true_state"][:, 0]).max() < 0.5
