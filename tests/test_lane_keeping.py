"""LaneKeepingEnv (envs/lane_keeping.py): determinism, action checks, config, info, rendering, vector envs
(both env checkers on every registered id: tests/test_registration.py)."""

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.env_util import make_vec_env

import tire_learning_env
from tire_learning_env.params import ParameterError


def rollout(env, seed, steps=60):
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for k in range(steps):
        obs, reward, term, trunc, info = env.step(np.array([0.01 * np.sin(0.3 * k)], dtype=np.float32))
        out.append(obs)
        out.append(info["true_state"])
    return np.concatenate([np.ravel(o) for o in out])


def test_same_seed_same_rollout_different_seed_differs_with_noise():
    camera = tire_learning_env.CameraParams.paper_noise(rate=20.0)
    a = rollout(gym.make("TireLearning-LaneChange-v0", camera=camera), seed=7)
    b = rollout(gym.make("TireLearning-LaneChange-v0", camera=camera), seed=7)
    c = rollout(gym.make("TireLearning-LaneChange-v0", camera=camera), seed=8)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)


def test_nan_action_raises_and_out_of_range_is_clipped():
    env = gym.make("TireLearning-Cornering-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="NaN or infinite"):
        env.step(np.array([np.nan]))
    with pytest.raises(ValueError, match="NaN or infinite"):
        env.step(np.array([np.inf]))
    # an offset of 10 rad is clipped to max_steering_offset by the env: the same step as the bound itself
    a, b = gym.make("TireLearning-Cornering-v0"), gym.make("TireLearning-Cornering-v0")
    a.reset(seed=0)
    b.reset(seed=0)
    _, _, _, _, ia = a.step(np.array([10.0]))
    _, _, _, _, ib = b.step(np.array([a.unwrapped.max_steering_offset], dtype=np.float32))
    np.testing.assert_array_equal(ia["sensor_log"]["delta"], ib["sensor_log"]["delta"])
    # the clipped steering stays below the simulator's own clamp (driver.max_steering), so an
    # unclipped offset would give a different log: the comparison above can fail
    assert ia["sensor_log"]["delta"].max() < a.unwrapped.driver_params.max_steering - 1e-3


def test_unknown_config_key_is_named():
    with pytest.raises(ParameterError, match="frobnicate"):
        gym.make("TireLearning-LaneKeeping-v0", config={"frobnicate": 1})
    with pytest.raises(ParameterError, match="VehicleParams"):
        gym.make("TireLearning-LaneKeeping-v0", config={"vehicle": {"mass": 3}})


def test_config_chooses_the_road_and_rates():
    env = gym.make("TireLearning-LaneKeeping-v0", config={"road": "sine", "policy_rate": 10.0, "camera": {"rate": 20.0}})
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(1))
    log = info["sensor_log"]
    assert len(log["t"]) == 100
    assert np.isfinite(log["e1"]).sum() == 2  # 20 Hz frames over 0.1 s


def test_info_carries_ground_truth():
    env = gym.make("TireLearning-Cornering-v0")
    env.reset(seed=0)
    for _ in range(300):
        _, _, _, _, info = env.step(np.zeros(1))
    assert info["true_state"].shape == (4,)
    for key in ("true_slip", "true_force", "true_force_nonlinear"):
        assert info[key].shape == (2,)
    # on the 300 m arc the Pacejka truth force is below the linear one: nonlinear part negative
    assert np.all(info["true_force_nonlinear"] < 0)
    assert info["truth_log"]["true_state"].shape == (50, 4)


def test_observation_entries_are_what_their_names_say():
    """The base observation is listed positionally (per step); each OBSERVATION_NAMES entry holds its value."""
    from tire_learning_env.envs._base import NO_FRAME_AGE, OBSERVATION_NAMES

    env = gym.make("TireLearning-Cornering-v0")
    obs, _ = env.reset(seed=0)
    at = {name: float(obs[i]) for i, name in enumerate(OBSERVATION_NAMES)}
    assert (at["e1"], at["e2"], at["frame_age"]) == (0.0, 0.0, NO_FRAME_AGE)  # no frame yet
    for _ in range(200):
        obs, _, _, _, info = env.step(np.array([0.01], dtype=np.float32))
    at = {name: float(obs[i]) for i, name in enumerate(OBSERVATION_NAMES)}
    sim, log = env.unwrapped.sim, info["sensor_log"]
    framed = np.flatnonzero(np.isfinite(log["e1"]))[-1]
    f32 = lambda x: float(np.float32(x))  # noqa: E731
    assert at["e1"] == f32(log["e1"][framed]) and at["e2"] == f32(log["e2"][framed])
    assert at["frame_age"] == f32(sim.t - sim.camera.latest_time) and 0.0 <= at["frame_age"] < 0.1
    assert at["vx"] == f32(env.unwrapped.vehicle.vx)
    assert at["kappa"] == f32(sim.table.lookup(sim.s)[0]) and at["kappa"] != 0.0  # on the arc
    assert at["last_delta"] == f32(log["delta"][-1])


def test_lane_departure_terminates():
    env = gym.make("TireLearning-LaneKeeping-v0", road="straight", action_mode="full")
    env.reset(seed=0)
    for _ in range(200):
        _, _, terminated, truncated, info = env.step(np.array([0.05]))
        if terminated:
            break
    assert terminated
    assert abs(info["true_state"][0]) > env.unwrapped.departure_threshold


def test_render_rgb_array():
    env = gym.make("TireLearning-LaneChange-v0", render_mode="rgb_array")
    env.reset(seed=0)
    env.step(np.zeros(1))
    img = env.render()
    assert img.dtype == np.uint8 and img.shape[2] == 3
    assert len(np.unique(img.reshape(-1, 3), axis=0)) >= 4  # grass, asphalt, marking, car


def test_gymnasium_vector_env():
    envs = gym.make_vec("TireLearning-LaneChange-v0", num_envs=3, vectorization_mode="sync")
    obs, _ = envs.reset(seed=[1, 2, 3])
    assert obs.shape == (3, 6)
    obs, rew, term, trunc, info = envs.step(np.zeros((3, 1), dtype=np.float32))
    assert rew.shape == (3,)
    assert info["true_state"].shape == (3, 4)


def test_sb3_vec_env():
    vec = make_vec_env("TireLearning-Cornering-v0", n_envs=2, seed=0)
    obs = vec.reset()
    assert obs.shape == (2, 6)
    obs, rew, done, infos = vec.step(np.zeros((2, 1), dtype=np.float32))
    assert len(infos) == 2 and "true_slip" in infos[0]


def test_end_of_step_truth_matches_the_last_logged_tick():
    env = gym.make("TireLearning-Cornering-v0")
    env.reset(seed=0)
    for _ in range(300):
        _, _, _, _, info = env.step(np.zeros(1, dtype=np.float32))
    # one tick after the last logged row, with the same held steering: nearly equal
    np.testing.assert_allclose(info["true_slip"], info["truth_log"]["true_slip"][-1], rtol=1e-3, atol=1e-6)
    np.testing.assert_allclose(info["true_force"], info["truth_log"]["true_force"][-1], rtol=1e-3, atol=1e-3)


@pytest.mark.parametrize("env_id", ["TireLearning-Cornering-v0", "TireLearning-Highway-v0"])
def test_set_plant_swaps_the_truth_vehicle_for_the_next_episode(env_id):
    """``set_plant`` changes the truth between episodes: the env and its simulator step the new
    plant, and its ground truth reaches ``info``."""
    from tire_learning_env.dynamics import BicyclePlant
    from tire_learning_env.tires import axle_tires

    env = gym.make(env_id, config={"vehicles_count": 0} if "Highway" in env_id else None).unwrapped
    soft = env.vehicle.replace(Cf=0.5 * env.vehicle.Cf, Cr=0.5 * env.vehicle.Cr)
    plant = BicyclePlant(env.vehicle, *axle_tires(soft, "linear"))
    env.set_plant(plant)
    assert env.plant is plant and getattr(getattr(env, "sim", env), "plant", plant) is plant
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([0.02], dtype=np.float32))
    np.testing.assert_array_equal(info["true_state"], np.asarray(plant.state[:4]))
    # the linear half-stiffness truth: force = 2 (C/2) alpha on the front axle
    assert info["true_force"][0] == pytest.approx(soft.Cf * 2 * info["true_slip"][0], rel=1e-9)


@pytest.mark.parametrize("env_id", ["TireLearning-Cornering-v0", "TireLearning-Highway-v0"])
def test_plant_sampler_draws_the_truth_from_the_reset_seed(env_id):
    """A ``plant_sampler`` (rng -> plant) is called at every reset with the env's truth generator:
    seeded by the reset's seed (the same truth for the same seed, whatever ran before), continued
    by a reset without one; the env steps the plant it returned."""
    from tire_learning_env.dynamics import BicyclePlant
    from tire_learning_env.tires import axle_tires

    drawn = []

    def sampler(rng):
        scale = float(rng.uniform(0.5, 1.5))
        v = env.vehicle
        plant = BicyclePlant(v, *axle_tires(v.replace(Cf=scale * v.Cf, Cr=scale * v.Cr), "linear"))
        drawn.append((scale, plant))
        return plant

    kwargs = {"config": {"vehicles_count": 0}} if "Highway" in env_id else {}
    env = gym.make(env_id, plant_sampler=sampler, **kwargs).unwrapped
    env.reset(seed=3)
    env.reset()  # continues the seed-3 stream
    env.reset(seed=4)
    env.reset(seed=3)
    scales = [s for s, _ in drawn]
    assert scales[0] == scales[3] and len(set(scales[:3])) == 3
    assert env.plant is drawn[-1][1]
    _, _, _, _, info = env.step(np.array([0.02], dtype=np.float32))
    np.testing.assert_array_equal(info["true_state"], np.asarray(drawn[-1][1].state[:4]))
    assert info["true_force"][0] == pytest.approx(scales[-1] * env.vehicle.Cf * 2 * info["true_slip"][0], rel=1e-9)
    with pytest.raises(ParameterError, match="plant_sampler"):
        env.set_plant_sampler("not callable")
