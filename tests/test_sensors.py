"""The lane camera (sensors.py): frame rate, latency, dropped frames and noise, seen in simulated logs."""

import numpy as np
import pytest

from tire_learning_env.dynamics import StateIndex
from tire_learning_env.params import CameraParams
from tire_learning_env.simulation import simulate


def test_camera_rate_latency_and_dropouts():
    camera = CameraParams(rate=20.0, latency=0.1, dropout_probability=0.3)
    log = simulate("study1", 10.0, camera=camera, seed=1)
    t, e1 = log.sensors["t"], log.sensors["e1"]
    arrived = ~np.isnan(e1)
    # 20 Hz frames, each delivered 0.1 s after it showed
    frame_times = np.round(np.arange(0.0, 10.0 - 0.1 - 1e-9, 0.05) + 0.1, 6)
    delivered = np.round(t[arrived], 6)
    assert set(delivered) <= set(frame_times)
    lost = 1 - len(delivered) / len(frame_times)
    assert 0.2 < lost < 0.4
    # a delivered frame equals the truth 0.1 s earlier (no noise configured)
    idx = np.flatnonzero(arrived)
    np.testing.assert_allclose(e1[idx], log.truth["true_state"][idx - 100, StateIndex.E1], atol=1e-12)


def test_uniform_noise_has_the_configured_width():
    log = simulate("straight", 20.0, camera=CameraParams.paper_noise(rate=100.0), seed=2)
    err = log.sensors["e1"] - log.truth["true_state"][:, StateIndex.E1]
    err = err[~np.isnan(err)]
    assert np.abs(err).max() <= 0.01
    assert np.std(err) == pytest.approx(0.01 / np.sqrt(3), rel=0.1)


@pytest.mark.parametrize("speed_profile", [None, lambda t: (25.0 + 0.1 * t, 0.1)], ids=["compiled loop", "python loop"])
def test_a_camera_ahead_of_the_cg_shows_the_offset_of_its_own_point(speed_profile):
    """``VehicleParams.camera_x``: the simulator's camera measures ``e1 + x sin(e2) - kappa x^2 / 2`` of the state
    it shows (the point x ahead, minus the path's own bend over x); ``e2`` is the car's. The driver steers on it."""
    from tire_learning_env.params import VehicleParams

    camera = CameraParams(rate=20.0, latency=0.1)
    x = 1.5
    log = simulate("sine", 10.0, vehicle=VehicleParams(camera_x=x), camera=camera, seed=1, speed_profile=speed_profile)
    e1, e2 = log.sensors["e1"], log.sensors["e2"]
    idx = np.flatnonzero(np.isfinite(e1))
    shown = idx - 100  # 0.1 s earlier at 1 kHz
    state = log.truth["true_state"][shown]
    kappa = log.sensors["kappa"][shown]
    expected = state[:, StateIndex.E1] + x * np.sin(state[:, StateIndex.E2]) - 0.5 * kappa * x * x
    np.testing.assert_allclose(e1[idx], expected, atol=1e-12)
    np.testing.assert_allclose(e2[idx], state[:, StateIndex.E2], atol=1e-12)
    assert np.max(np.abs(e1[idx] - state[:, StateIndex.E1])) > 1e-3  # not the CG's offset
    assert np.max(np.abs(kappa)) > 0 and np.max(np.abs(state[:, StateIndex.E2])) > 1e-4  # both terms exercised
    at_cg = simulate("sine", 10.0, camera=camera, seed=1, speed_profile=speed_profile)
    assert not np.allclose(at_cg.sensors["delta"], log.sensors["delta"])  # the driver saw the camera's e1
