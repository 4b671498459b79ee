"""highway-env traffic scenes with the truth vehicle as the ego car (envs/highway*.py)."""

import importlib.util
import math
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from highway_env.road.lane import CircularLane, StraightLane
from highway_env.vehicle.behavior import IDMVehicle
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import tire_learning_env  # noqa: F401  (registers the ids)
from tire_learning_env.dynamics import error_state_derivative
from tire_learning_env.envs.highway import HighwayTrafficEnv, RacetrackTrafficEnv, lane_curvature
from tire_learning_env.envs.lane_keeping import OBSERVATION_NAMES
from tire_learning_env.params import CameraParams, ParameterError
from tire_learning_env.simulation import SENSOR_KEYS, TRUTH_KEYS

IDS = ["TireLearning-Highway-v0", "TireLearning-Racetrack-v0"]
ZERO = np.zeros(1, dtype=np.float32)


def run(env, seconds, action=ZERO):
    """Step ``env`` (unwrapped) for ``seconds``; return the concatenated logs and switch rows."""
    sensors, truth, switches, infos = [], [], [], []
    base = 0
    while env.t < seconds - 1e-9:
        _, _, term, trunc, info = env.step(action)
        sensors.append(info["sensor_log"])
        truth.append(info["truth_log"])
        sw = info["lane_switches"]
        switches += [(base + r, lc, j) for r, lc, j in zip(sw["row"], sw["lane_change"], sw["e1_jump"])]
        infos.append(info)
        base += len(info["sensor_log"]["t"])
        if term or trunc:
            break
    s = {k: np.concatenate([d[k] for d in sensors]) for k in sensors[0]}
    x = {k: np.concatenate([d[k] for d in truth]) for k in truth[0]}
    return s, x, switches, infos


# -- registration, checkers, spaces, config -------------------------------------------------


def test_discrete_lane_change_action_passes_both_checkers():
    env = gym.make("TireLearning-Highway-v0", config={"lane_change": "action", "vehicles_count": 5})
    assert env.action_space == gym.spaces.Discrete(3)
    check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(gym.make("TireLearning-Highway-v0", config={"lane_change": "action", "vehicles_count": 5}))


@pytest.mark.parametrize("env_id", IDS)
def test_observation_layout_and_info_keys_match_the_base_envs(env_id):
    env = gym.make(env_id)
    base = gym.make("TireLearning-LaneKeeping-v0")
    obs, info0 = env.reset(seed=0)
    base_obs, base_info0 = base.reset(seed=0)
    assert env.observation_space.shape == (len(OBSERVATION_NAMES),)
    np.testing.assert_array_equal(env.observation_space.low, base.observation_space.low)
    np.testing.assert_array_equal(env.observation_space.high, base.observation_space.high)
    assert set(base_info0) <= set(info0)
    _, _, _, _, info = env.step(ZERO)
    _, _, _, _, base_info = base.step(np.zeros(1, dtype=np.float32))
    assert set(base_info) <= set(info)
    assert tuple(info["sensor_log"]) == SENSOR_KEYS
    assert tuple(info["truth_log"]) == TRUTH_KEYS
    n = env.unwrapped.ticks_per_step
    assert all(v.shape == (n,) for v in info["sensor_log"].values())
    assert info["truth_log"]["true_state"].shape == (n, 4)
    for key in ("true_slip", "true_force", "true_force_nonlinear"):
        assert info["truth_log"][key].shape == (n, 2)
        assert info[key].shape == (2,)
    assert info["true_state"].shape == (4,)
    est = env.unwrapped.estimator_inputs
    assert set(est) == set(base.unwrapped.estimator_inputs)
    assert est["physics_dt"] == pytest.approx(1e-3)


def test_info_truth_at_step_end_matches_the_last_logged_tick():
    env = HighwayTrafficEnv(config={"vehicles_count": 0, "lane_change": "action"})
    env.reset(seed=0)
    for _ in range(5):
        env.step(2)  # a lane change: large steering, slip and force
    _, _, _, _, info = env.step(0)
    # the step-end truth is one tick after the last row: nearly equal, same sign
    np.testing.assert_allclose(info["true_slip"], info["truth_log"]["true_slip"][-1], atol=5e-4)
    np.testing.assert_allclose(info["true_force"], info["truth_log"]["true_force"][-1], atol=60.0)


def test_traffic_features_are_appended_only_when_configured():
    env = HighwayTrafficEnv(config={"traffic_features": 3, "vehicles_count": 10})
    obs, _ = env.reset(seed=3)
    assert obs.shape == (6 + 3 * 4,) and env.observation_space.contains(obs)
    feats = obs[6:].reshape(3, 4)
    assert feats[0, 0] == 1.0  # the nearest vehicle is present
    ego = env.ego
    dists = [np.hypot(*(v.position - ego.position)) for v in env.road.vehicles if v is not ego]
    assert np.hypot(feats[0, 1], feats[0, 2]) == pytest.approx(min(dists), abs=0.5)


def test_config_errors_name_the_problem():
    with pytest.raises(ParameterError, match="frobnicate"):
        gym.make("TireLearning-Highway-v0", config={"frobnicate": 1})
    with pytest.raises(ParameterError, match="lanes_count"):
        gym.make("TireLearning-Racetrack-v0", config={"lanes_count": 2})  # a highway key
    with pytest.raises(ParameterError, match="track"):
        gym.make("TireLearning-Racetrack-v0", config={"track": "monza"})
    with pytest.raises(ParameterError, match="traffic_frequency"):
        gym.make("TireLearning-Highway-v0", config={"traffic_frequency": 7.0})
    with pytest.raises(ParameterError, match="lane_change"):
        gym.make("TireLearning-Highway-v0", config={"lane_change": "sometimes"})


def test_nan_action_raises_and_out_of_range_is_clipped():
    env = gym.make("TireLearning-Racetrack-v0")
    env.reset(seed=0)
    for bad in (np.nan, np.inf):
        with pytest.raises(ValueError, match="NaN or infinite"):
            env.step(np.array([bad]))
    env_d = HighwayTrafficEnv(config={"lane_change": "action", "vehicles_count": 0})
    env_d.reset(seed=0)
    with pytest.raises(ValueError, match="keep"):
        env_d.step(3)
    # an offset of 10 rad is clipped to max_steering_offset: the two give the same step
    a, b = RacetrackTrafficEnv(), RacetrackTrafficEnv()
    a.reset(seed=1)
    b.reset(seed=1)
    _, _, _, _, ia = a.step(np.array([10.0]))
    _, _, _, _, ib = b.step(np.array([a.max_steering_offset], dtype=np.float32))
    np.testing.assert_array_equal(ia["sensor_log"]["delta"], ib["sensor_log"]["delta"])
    # below the simulator's own clamp (driver.max_steering): an unclipped offset would differ
    assert ia["sensor_log"]["delta"].max() < a.driver_params.max_steering - 1e-3


# -- determinism ------------------------------------------------------------------------------


def rollout(env_id, seed, steps=80, **kwargs):
    env = gym.make(env_id, **kwargs)
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for k in range(steps):
        obs, reward, term, trunc, info = env.step(np.array([0.01 * np.sin(0.3 * k)], dtype=np.float32))
        out += [obs, [reward], info["true_state"], info["sensor_log"]["e1"]]
        out += [np.concatenate([v.position, [v.heading, v.speed]]) for v in env.unwrapped.road.vehicles]
        if term or trunc:
            break
    return np.concatenate([np.ravel(o) for o in out])


@pytest.mark.parametrize("env_id", IDS)
def test_same_seed_same_rollout_traffic_included(env_id):
    camera = CameraParams.paper_noise(rate=20.0)
    a = rollout(env_id, 7, camera=camera, config={"vehicles_count": 8})
    b = rollout(env_id, 7, camera=camera, config={"vehicles_count": 8})
    c = rollout(env_id, 8, camera=camera, config={"vehicles_count": 8})
    np.testing.assert_array_equal(a, b)
    assert len(a) != len(c) or not np.allclose(a, c, equal_nan=True)


def test_policy_rate_does_not_change_the_physics():
    """The same 2 s at 10 Hz and at 20 Hz policy rate: identical per-tick logs."""
    logs = []
    for rate in (10.0, 20.0):
        env = RacetrackTrafficEnv(config={"policy_rate": rate, "vehicles_count": 3})
        env.reset(seed=4)
        s, x, _, _ = run(env, 2.0)
        logs.append((s, x))
    for key in SENSOR_KEYS:
        np.testing.assert_array_equal(logs[0][0][key], logs[1][0][key])
    np.testing.assert_array_equal(logs[0][1]["true_state"], logs[1][1]["true_state"])


# -- geometry: e1 against highway-env's lanes, curvature, consistency with SPEC §1 ------------


@pytest.mark.parametrize("cls", [HighwayTrafficEnv, RacetrackTrafficEnv])
def test_e1_is_the_lateral_distance_to_the_target_lane_centre(cls):
    if cls is HighwayTrafficEnv:  # a slow car ahead: the driver changes lanes (world heading turns)
        env = cls(config={"vehicles_count": 0})
        env.reset(seed=2)
        lane = env.target_lane_object
        env.road.vehicles.append(IDMVehicle(env.road, lane.position(env.s + 50.0, 0.0), 0.0, 12.0))
    else:
        env = cls(config={"vehicles_count": 4})
        env.reset(seed=2)
    headings, n_curved = [], 0
    while env.t < 40.0:
        heading_before = env.ego.heading
        _, _, term, _, info = env.step(ZERO)
        assert not term, info
        # independent: highway-env's own lane object and the ego's world position
        lane = env.network.get_lane(info["target_lane_index"])
        s_lane, lateral = lane.local_coordinates(env.ego.position)
        assert info["true_state"][0] == pytest.approx(lateral, abs=1e-9)
        assert env.s == pytest.approx(s_lane, abs=1e-6)
        n_curved += isinstance(lane, CircularLane)
        # the camera frame (1 kHz, no noise) is the truth one tick earlier
        obs_e1 = env._observation()[0]
        assert obs_e1 == pytest.approx(lateral, abs=5e-3)
        # the world heading turns by the integral of the truth yaw rate (a hand-over between
        # road segments may add ~1e-3 rad: the curvature ramp of the join vs. the lane arcs)
        turned = math.remainder(env.ego.heading - heading_before, 2 * math.pi)
        integral = float(np.sum(info["sensor_log"]["yaw_rate"]) * env.dt)
        joins = np.sum(~info["lane_switches"]["lane_change"])
        assert turned == pytest.approx(integral, abs=3e-3 if joins else 5e-4)
        headings.append(turned)
    assert np.abs(np.cumsum(headings)).max() > 0.03  # the car did turn
    if cls is RacetrackTrafficEnv:
        assert n_curved > 100  # really on arcs


def test_lane_curvature_from_highway_env_geometry():
    straight = StraightLane([0, 0], [100, 0])
    arc = CircularLane([0, 0], 20.0, 0.0, np.pi / 2, clockwise=True)
    arc_cw = CircularLane([0, 0], 25.0, np.pi, 0.0, clockwise=False)
    s = np.linspace(1.0, 20.0, 5)
    assert np.all(lane_curvature(straight, s) == 0.0)
    for lane in (arc, arc_cw):
        h = 1e-3
        finite_diff = [(lane.heading_at(x + h) - lane.heading_at(x - h)) / (2 * h) for x in s]
        np.testing.assert_allclose(lane_curvature(lane, s), finite_diff, rtol=1e-6)
    assert lane_curvature(arc, s)[0] == pytest.approx(1 / 20.0)
    assert lane_curvature(arc_cw, s)[0] == pytest.approx(-1 / 25.0)


def test_racetrack_handovers_keep_heading_and_ramp_integrates_to_the_curvature_step():
    env = RacetrackTrafficEnv()
    ref = env.reference
    for index in env.network.lanes_dict():
        h = ref.handover(index)
        assert h is not None  # a closed track
        assert abs(h.heading) < 1e-3  # switched where the headings agree
        assert abs(h.lateral) < 0.25  # highway-env's join offsets (documented)
        ks, kv, cum = ref.profile(index, h.s_switch - 3.0, h.s_switch + 3.0)
        k_before = lane_curvature(env.network.get_lane(index), np.array([h.s_switch]))[0]
        k_after = lane_curvature(env.network.get_lane(h.next_index), np.array([h.s_next]))[0]
        # heading change of the profile across the ramp = that of the curvature step
        integral = np.interp(h.s_switch + 1.0, ks, cum) - np.interp(h.s_switch - 1.0, ks, cum)
        assert integral == pytest.approx(k_before * 1.0 + k_after * 1.0, abs=1e-9), index
        # the next lane's profile has the same ramp around its entry: continuous curvature
        for ds in (-0.03, 0.0, 0.02, 0.04):
            assert ref.kappa(index, h.s_switch + ds) == pytest.approx(ref.kappa(h.next_index, h.s_next + ds), abs=1e-9)


@pytest.mark.parametrize("cls", [HighwayTrafficEnv, RacetrackTrafficEnv])
def test_logs_follow_the_error_state_model_of_spec_1(cls):
    """Row to row, the truth obeys SPEC §1 with the logged inputs (psi_dot_des = vx kappa)."""
    env = cls(config={"lane_change": "action", "vehicles_count": 0})
    env.reset(seed=1)
    sensors, truth = [], []
    base, switch_rows = 0, []
    change = 2 if env.target_lane[2] == 0 else 1
    for k in range(300):
        _, _, term, _, info = env.step(change if k == 20 else 0)  # one lane change
        sensors.append(info["sensor_log"])
        truth.append(info["truth_log"])
        switch_rows += list(base + info["lane_switches"]["row"])
        base += env.ticks_per_step
        assert not term
    s = {k: np.concatenate([d[k] for d in sensors]) for k in sensors[0]}
    x = np.concatenate([d["true_state"] for d in truth])
    f = np.concatenate([d["true_force"] for d in truth])
    np.testing.assert_allclose(s["psi_dot_des"], s["vx"] * s["kappa"], rtol=0, atol=1e-12)
    p, q, vx, ax = s["psi_dot_des"], s["psi_ddot_des"], s["vx"], s["ax"]
    veh = env.vehicle
    d0 = error_state_derivative(x[:-1], p[:-1], q[:-1], f[:-1, 0], f[:-1, 1], veh, vx=vx[:-1], ax=ax[:-1])
    d1 = error_state_derivative(x[1:], p[1:], q[:-1], f[1:, 0], f[1:, 1], veh, vx=vx[1:], ax=ax[:-1])
    residual = np.diff(x, axis=0) / env.dt - 0.5 * (d0 + d1)
    ok = np.diff(q) == 0  # rows where psi_ddot_des is not switching within the tick
    for r in switch_rows:
        ok[max(r - 1, 0) : r + 1] = False
    assert ok.mean() > 0.95 and len(switch_rows) >= 1
    assert np.abs(residual[ok][:, [0, 2]]).max() < 5e-4  # trapezoid rule error, O(dt^2)
    assert np.abs(residual[ok][:, [1, 3]]).max() < 0.1  # [m/s^2], [rad/s^2] against peaks of several


# -- lane changes --------------------------------------------------------------------------


def test_lane_change_moves_the_target_lane_and_e1_jumps_one_lane_width_then_converges():
    env = HighwayTrafficEnv(config={"lane_change": "action", "vehicles_count": 0, "initial_lane_id": 1})
    env.reset(seed=0)
    for _ in range(10):
        env.step(0)
    lane_before = env.target_lane
    _, _, _, _, info = env.step(2)  # to lane id + 1 (+lateral)
    assert env.target_lane == (lane_before[0], lane_before[1], lane_before[2] + 1)
    sw = info["lane_switches"]
    assert list(sw["lane_change"]) == [True] and sw["row"][0] == 0
    width = env.lane_width
    assert sw["e1_jump"][0] == pytest.approx(-width)
    e1_cam = info["sensor_log"]["e1"]
    x = info["truth_log"]["true_state"]
    assert e1_cam[0] == pytest.approx(-width, abs=1e-3)  # the frame of the switch tick: new lane
    assert x[0, 0] == pytest.approx(-width, abs=1e-3)
    s, xt, _, infos = run(env, env.t + 12.0, action=0)
    assert not any(i["lane_departure"] or i["crashed"] for i in infos)
    e1 = np.concatenate([[e1_cam[-1]], s["e1"]])
    assert np.all(np.diff(e1[:2000]) >= -1e-6)  # moves monotonically toward the new centre at first
    assert abs(s["e1"][-1]) < 0.05 and abs(xt["true_state"][-1, 2]) < 0.01
    # the manoeuvre stays a comfortable one at 25 m/s
    assert np.abs(s["ay"]).max() < 4.0


def test_rule_based_driver_overtakes_a_slow_car():
    env = HighwayTrafficEnv(config={"vehicles_count": 0, "initial_lane_id": 1})
    env.reset(seed=0)
    lane = env.target_lane_object
    slow = IDMVehicle(env.road, lane.position(env.s + 60.0, 0.0), lane.heading_at(env.s + 60.0), 15.0)
    slow.enable_lane_change = False
    env.road.vehicles.append(slow)
    _, _, _, infos = run(env, 25.0)
    assert infos[-1]["lane_changes"] >= 1
    assert not any(i["crashed"] or i["lane_departure"] for i in infos)
    assert env.ego.position[0] > slow.position[0] + 20.0  # passed it
    assert env.vx > 20.0


def test_lane_change_on_the_racetrack_shifts_frames_still_in_the_camera_queue():
    """With a 20 Hz camera and 60 ms latency, every delivered frame refers to the target lane."""
    cam = CameraParams(rate=20.0, latency=0.06)
    env = RacetrackTrafficEnv(camera=cam, config={"lane_change": "action", "vehicles_count": 0})
    env.reset(seed=3)
    change = 2 if env.target_lane[2] == 0 else 1
    sensors, truth, switches = [], [], []
    for k in range(200):  # 10 s, the lane change after 1 s
        _, _, _, _, info = env.step(change if k == 20 else 0)
        sw = info["lane_switches"]
        switches += [(env.ticks_per_step * k + r, lc, j) for r, lc, j in zip(sw["row"], sw["lane_change"], sw["e1_jump"])]
        sensors.append(info["sensor_log"])
        truth.append(info["truth_log"])
    s = {k: np.concatenate([d[k] for d in sensors]) for k in sensors[0]}
    x = {k: np.concatenate([d[k] for d in truth]) for k in truth[0]}
    assert any(lc for _, lc, _ in switches)
    frames = np.flatnonzero(np.isfinite(s["e1"]))
    shown = frames - 60  # a frame delivered at row j showed the truth at row j - 60
    keep = shown >= 0
    # compare where no target switch happened between showing and delivery
    sw_rows = np.array([r for r, _, _ in switches])
    crossed = 0
    for j, i in zip(frames[keep], shown[keep]):
        if np.any((sw_rows > i) & (sw_rows <= j)):
            jump = sum(jp for r, _, jp in switches if i < r <= j)
            assert s["e1"][j] == pytest.approx(x["true_state"][i, 0] + jump, abs=1e-9)
            crossed += abs(jump) > 1.0
        else:
            assert s["e1"][j] == pytest.approx(x["true_state"][i, 0], abs=1e-9)
    assert crossed >= 1  # a frame was in the queue when the lane changed


# -- traffic, termination ------------------------------------------------------------------


def test_collision_terminates_with_the_crash_flag():
    env = HighwayTrafficEnv(config={"vehicles_count": 0, "lane_change": "off", "longitudinal": "constant", "initial_lane_id": 0})
    env.reset(seed=0)
    lane = env.target_lane_object
    wall = IDMVehicle(env.road, lane.position(env.s + 40.0, 0.0), lane.heading_at(env.s), 0.0)
    wall.enable_lane_change = False
    env.road.vehicles.append(wall)
    for _ in range(100):
        _, reward, term, _, info = env.step(ZERO)
        if term:
            break
    assert term and info["crashed"] and not info["lane_departure"] and reward == -1.0


def test_lane_departure_terminates():
    env = gym.make("TireLearning-Racetrack-v0", action_mode="full", config={"vehicles_count": 0})
    env.reset(seed=0)
    for _ in range(200):
        _, _, term, _, info = env.step(np.array([0.05], dtype=np.float32))
        if term:
            break
    assert term and info["lane_departure"]
    assert abs(info["true_state"][0]) > env.unwrapped.departure_threshold


def test_traffic_is_recycled_around_the_ego_on_long_runs():
    env = HighwayTrafficEnv(config={"vehicles_count": 10})
    env.reset(seed=5)
    _, _, _, infos = run(env, 60.0)
    assert not infos[-1]["crashed"]
    x_ego = env.ego.position[0]
    dx = np.array([v.position[0] - x_ego for v in env.road.vehicles if v is not env.ego])
    assert len(dx) == 10
    assert np.all(dx > -HighwayTrafficEnv._RECYCLE_BEHIND - 40.0) and np.all(dx < HighwayTrafficEnv._RECYCLE_AHEAD + 40.0)


# -- plants, rendering, wrappers ---------------------------------------------------------------


@pytest.mark.parametrize("guard", [False, True])
def test_compiled_and_python_loops_give_the_same_log_through_handovers_and_lane_changes(guard, python_only_plant):
    from tire_learning_env.dynamics import BicyclePlant
    from tire_learning_env.tires import axle_tires

    cam = CameraParams(rate=30.0, latency=0.05, noise="gaussian", e1_noise=0.01, e2_noise=0.005, dropout_probability=0.1)
    logs = []
    for python in (False, True):

        def factory(v, python=python):
            plant = BicyclePlant(v, *axle_tires(v))
            return python_only_plant(plant) if python else plant

        env = RacetrackTrafficEnv(camera=cam, plant_factory=factory, config={"lane_change": "action", "vehicles_count": 0})
        if guard:  # the lane change's a_y is clamped: the guard runs in both loops alike
            env.driver.set_ay_guard(1.0, 100.0, 160.0)
        env.reset(seed=2)
        out = []
        for k in range(160):  # 8 s: joins and a lane change
            _, _, _, _, info = env.step(2 if k == 40 else 0)
            out.append(info)
        logs.append(out)
    assert sum(len(i["lane_switches"]["row"]) for i in logs[0]) >= 3
    for a, b in zip(*logs):
        for key in SENSOR_KEYS:
            np.testing.assert_allclose(a["sensor_log"][key], b["sensor_log"][key], rtol=1e-12, atol=1e-12, equal_nan=True)
        np.testing.assert_allclose(a["truth_log"]["true_state"], b["truth_log"]["true_state"], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("env_id", IDS)
def test_render_rgb_array_headless(env_id):
    env = gym.make(env_id, render_mode="rgb_array")
    env.reset(seed=0)
    env.step(ZERO)
    img = env.render()
    h, w = (150, 600) if "Highway" in env_id else (600, 600)
    assert img.shape == (h, w, 3) and img.dtype == np.uint8
    colours = {tuple(c) for c in np.unique(img.reshape(-1, 3), axis=0)}
    assert (50, 200, 0) in colours  # the ego car, in highway-env's ego green
    assert len(colours) >= 4  # road, markings, cars
    env.close()


def test_vector_env():
    envs = gym.make_vec("TireLearning-Racetrack-v0", num_envs=2, vectorization_mode="sync")
    obs, _ = envs.reset(seed=[1, 2])
    assert obs.shape == (2, 6)
    obs, rew, term, trunc, info = envs.step(np.zeros((2, 1), dtype=np.float32))
    assert rew.shape == (2,) and info["true_state"].shape == (2, 4)


@pytest.mark.parametrize("env_id", IDS)
def test_estimator_wrapper_runs_unchanged(env_id):
    wrappers = pytest.importorskip("tire_learning_env.wrappers", reason="the estimator wrapper is not written yet")
    EstimatorWrapper = getattr(wrappers, "EstimatorWrapper", None)
    if EstimatorWrapper is None:
        pytest.skip("tire_learning_env.wrappers has no EstimatorWrapper yet")
    env = EstimatorWrapper(gym.make(env_id, config={"vehicles_count": 4}))
    obs, info = env.reset(seed=0)
    assert "estimate" in info
    for _ in range(40):
        obs, reward, term, trunc, info = env.step(ZERO)
        assert np.all(np.isfinite(info["estimate"]["state"]))
        if term or trunc:
            break
    assert env.observation_space.contains(obs)


# -- long runs (slow) ------------------------------------------------------------------------


@pytest.mark.slow
def test_dense_traffic_five_minutes_twenty_seeds_without_collision_or_departure():
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_highway_endurance.py"
    spec = importlib.util.spec_from_file_location("bench_highway_endurance", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # the worker processes unpickle run_seed by module name
    spec.loader.exec_module(module)
    endurance = module.endurance

    result = endurance(seeds=20, seconds=300.0, workers=2)
    assert result["completed"] == 20, result
    assert result["collisions"] == 0 and result["lane_departures"] == 0, result
