"""Predictive lateral-acceleration safety filter (wrappers/safety.py) and its use in the excitation env."""

import math

import numpy as np
import pytest

from tire_learning_env.envs.lane_keeping import LaneKeepingEnv
from tire_learning_env.params import CameraParams, DriverParams, ParameterError, VehicleParams
from tire_learning_env.scripted import make_manoeuvre, run_manoeuvre
from tire_learning_env.wrappers.excitation import EXCITATION_CAMERA, ExcitationConfig, make_excitation_env
from tire_learning_env.wrappers.safety import LateralAccelerationFilter, camera_noise_std

VX = VehicleParams().vx


def _filter(**kw):
    args = dict(vehicle=VehicleParams(), driver=DriverParams(), ay_limit=4.0, dt_step=0.05, camera=EXCITATION_CAMERA)
    args.update(kw)
    return LateralAccelerationFilter(**args)


def test_prediction_matches_the_simulated_closed_loop():
    """Linear-tire truth, noise-free 1 kHz camera: the filter's model is the plant closed with the driver."""
    env = LaneKeepingEnv(road="straight", tire_model="linear")
    env.reset(seed=0)
    ay = []
    for k in range(40):  # one 50 ms step of 0.02 rad, then the driver alone (the "release" backup)
        _, _, _, _, info = env.step(np.array([0.02 if k == 0 else 0.0], dtype=np.float32))
        ay.append(info["sensor_log"]["ay"])
    simulated = np.concatenate(ay)[::5]  # the 5 ms prediction grid
    filt = _filter(camera=CameraParams(), stiffness_uncertainty=0.0)
    predicted = filt.predict(0.02, np.zeros(4), 0.0, VX, 0.0)[0, 0]
    assert np.max(np.abs(simulated[: len(predicted)] - predicted)) < 1e-3 * np.max(np.abs(predicted))
    # the direct feed-through of the offset: 2 Cf u / m
    assert predicted[0] == pytest.approx(2 * VehicleParams().Cf * 0.02 / VehicleParams().m, rel=1e-9)


def test_prediction_from_a_moving_state_on_a_curve():
    """Start state, driver integral and road curvature enter the prediction as in the simulation:
    mid-episode on a constant-radius arc (linear tires, noise-free 1 kHz camera), one held offset,
    then the driver alone."""
    from tire_learning_env.roads import PiecewiseCurvatureRoad

    kappa = 1.0 / 400.0
    env = LaneKeepingEnv(road=PiecewiseCurvatureRoad((0.0, 1.0), (kappa, kappa)), tire_model="linear")
    env.reset(seed=0)
    for k in range(30):  # a disturbed start: 1.5 s of weaving offsets
        env.step(np.array([0.01 * np.sin(k / 3.0)], dtype=np.float32))
    sim = env.sim
    state, integral = sim.plant.state[:4].copy(), float(sim.driver.integral)
    assert np.max(np.abs(state[[1, 3]])) > 1e-3 and abs(integral) > 1e-6  # really moving
    ay = []
    for k in range(40):
        _, _, _, _, info = env.step(np.array([-0.01 if k == 0 else 0.0], dtype=np.float32))
        ay.append(info["sensor_log"]["ay"])
    simulated = np.concatenate(ay)[::5]
    filt = _filter(camera=CameraParams(), stiffness_uncertainty=0.0)
    predicted = filt.predict(-0.01, state, integral, VX, kappa)[0, 0]
    assert np.max(np.abs(simulated[: len(predicted)] - predicted)) < 2e-3 * np.max(np.abs(predicted))
    assert predicted[-1] == pytest.approx(VX**2 * kappa, rel=0.01)  # settles on the arc's v^2 kappa


def test_small_offsets_pass_and_large_ones_are_cut_symmetrically():
    filt = _filter()
    assert filt.filter(0.001, np.zeros(4), 0.0, VX, 0.0, max_offset=0.05) == 0.001
    up = filt.decide(0.05, np.zeros(4), 0.0, VX, 0.0, max_offset=0.05)
    down = filt.decide(-0.05, np.zeros(4), 0.0, VX, 0.0, max_offset=0.05)
    assert up.active and not up.driver_beyond_limit and 0.0 < up.applied < 0.05
    assert down.applied == pytest.approx(-up.applied)
    # at the cut, the worst vertex reaches exactly the limit minus the margin
    assert up.predicted_peak == pytest.approx(4.0 - filt.margin(VX), rel=1e-6)
    # and the worst vertex is the stiffer front axle: +20 % feed-through
    assert up.applied == pytest.approx((4.0 - filt.margin(VX)) * VehicleParams().m / (2 * 1.2 * VehicleParams().Cf), rel=1e-6)


def test_margin_follows_the_camera_noise():
    assert _filter(camera=CameraParams()).margin(VX) == 0.0
    s1, s2 = camera_noise_std(EXCITATION_CAMERA)
    d, v = DriverParams(), VehicleParams()
    expected = 2.0 * 1.2 * 2 * v.Cf / v.m * d.gain * math.hypot(s1, VX * d.lookahead_time * s2)
    assert _filter().margin(VX) == pytest.approx(expected)
    uniform = CameraParams(noise="uniform", e1_noise=0.01, e2_noise=math.radians(1.0))
    assert camera_noise_std(uniform) == pytest.approx((0.01 / math.sqrt(3), math.radians(1.0) / math.sqrt(3)))


def test_momentum_is_anticipated():
    """A state already turning hard leaves less room than rest for the same offset direction."""
    filt = _filter()
    turning = np.array([0.0, 0.0, 0.0, 0.08])  # heading error rate building up
    at_rest = filt.decide(0.05, np.zeros(4), 0.0, VX, 0.0, max_offset=0.05).applied
    other = filt.decide(0.05, turning, 0.0, VX, 0.0, max_offset=0.05).applied
    assert other < at_rest


def test_beyond_the_limit_the_offset_may_only_help():
    """The driver alone is predicted beyond the limit: an offset that adds is cut to zero, one that
    relieves passes (the filter never overrides the driver's own steering)."""
    filt = _filter()
    state = np.array([0.0, 0.0, 0.05, 0.0])  # 0.05 rad heading error at 30 m/s: far beyond 4 m/s^2
    adding = filt.decide(0.05, state, 0.0, VX, 0.0, max_offset=0.05)
    assert adding.driver_beyond_limit and adding.applied == pytest.approx(0.0, abs=1e-12)
    relieving = filt.decide(-0.002, state, 0.0, VX, 0.0, max_offset=0.05)
    assert relieving.applied == -0.002
    # a full counter-steer would overshoot to the other side later: cut to what stays inside there
    strong = filt.decide(-0.05, state, 0.0, VX, 0.0, max_offset=0.05)
    assert -0.05 < strong.applied < -0.002
    worst = lambda u: np.max(np.abs(filt.predict(u, state, 0.0, VX, 0.0)))  # noqa: E731
    assert worst(strong.applied) < worst(relieving.applied) < worst(0.0) < worst(0.05)


def test_safety_layers_keep_the_tuned_roads_in_lane():
    """Scripted roads whose curves need up to 3.9 m/s^2, no offset: the per-tick guard (which clamps
    the total steering) does not push the car out of its lane."""
    for name, params in (("cornering", {"amplitude": 0.00335}), ("sine_road", {"wavelength": 150.0, "amplitude": 0.00336})):
        m = make_manoeuvre(name, **params)
        for seed in (1000, 1001):
            r = run_manoeuvre(m, seed=seed, duration=30.0, config=ExcitationConfig())
            assert not r["departed"] and r["lane_violation_steps"] == 0, (name, seed)


def test_on_a_curve_the_room_left_by_the_curve_is_what_the_offset_gets():
    """A curve that alone needs 2.5 m/s^2: a relieving offset passes, an adding one is cut to the bound,
    and the cut is smaller than on the straight (the curve uses part of the room)."""
    filt = _filter()
    kappa = 2.5 / VX**2
    relieving = filt.decide(-0.005, np.zeros(4), 0.0, VX, kappa, max_offset=0.05)
    adding = filt.decide(0.05, np.zeros(4), 0.0, VX, kappa, max_offset=0.05)
    straight = filt.decide(0.05, np.zeros(4), 0.0, VX, 0.0, max_offset=0.05)
    assert not adding.driver_beyond_limit
    assert relieving.applied == -0.005
    assert 0.0 < adding.applied < straight.applied
    assert adding.predicted_peak == pytest.approx(4.0 - filt.margin(VX), rel=1e-6)


def test_bad_settings_are_named():
    with pytest.raises(ParameterError, match="stiffness_uncertainty"):
        _filter(stiffness_uncertainty=1.0)
    with pytest.raises(ParameterError, match="dt_predict"):
        _filter(dt_predict=0.003)
    with pytest.raises(ParameterError, match="safety_stiffness_uncertainty"):
        ExcitationConfig(safety_stiffness_uncertainty=1.5)
    with pytest.raises(ParameterError, match="safety_noise_sigmas"):
        ExcitationConfig(safety_noise_sigmas=-1.0)
    with pytest.raises(ParameterError, match="margin"):
        _filter(noise_sigmas=20.0)
    with pytest.raises(ValueError, match="finite"):
        _filter().decide(math.nan, np.zeros(4), 0.0, VX, 0.0)


def _bang_bang(env, seed, steps=300):
    env.reset(seed=seed)
    for k in range(steps):
        u = 1.0 if (k // 20) % 2 == 0 else -1.0  # full offset, switched every second
        _, _, terminated, truncated, info = env.step(np.array([u], dtype=np.float32))
        if terminated or truncated:
            break
    return env.episode_metrics()


@pytest.mark.parametrize("seed", [7, 8, 9])
def test_filter_keeps_a_bang_bang_policy_within_the_limit(seed):
    """Randomised truth tires (+/-20 % stiffness): full-offset bang-bang exceeds 4 m/s^2 without the
    filter and stays within it with the filter (the env's default)."""
    raw = _bang_bang(make_excitation_env(config=ExcitationConfig(safety_filter=False)), seed)
    filtered = _bang_bang(make_excitation_env(), seed)
    assert raw["max_abs_ay"] > 4.5 and raw["ay_violation_steps"] > 0
    assert filtered["max_abs_ay"] <= 4.0 and filtered["ay_violation_steps"] == 0
    assert filtered["filter_active_steps"] > 0
    assert raw["departed"]
    # a_y alone does not keep the car in its lane; with the lane constraint it stays in
    guarded = _bang_bang(make_excitation_env(config=ExcitationConfig(safety_lane=True)), seed)
    assert not guarded["departed"] and guarded["lane_violation_steps"] == 0
    assert guarded["max_abs_ay"] <= 4.0
