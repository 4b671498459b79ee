"""Excitation task (wrappers/excitation.py) and the agents/ scripts (scripted baselines: test_scripted.py)."""

import importlib.util
import json
import math
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import tire_learning_env
from tire_learning_env.observer import build_observer
from tire_learning_env.params import ParameterError
from tire_learning_env.scripted import run_policy
from tire_learning_env.simulation import SENSOR_KEYS
from tire_learning_env.wrappers.excitation import (
    EXCITATION_CAMERA,
    ExcitationConfig,
    ExcitationWrapper,
    TruthRandomization,
    make_excitation_env,
    target_slip_range,
    target_functionals,
)

REPO = Path(__file__).resolve().parents[1]
AGENTS = REPO / "agents"
ENV_ID = "TireLearning-Excitation-v0"


def _load_script(name):
    sys.path.insert(0, str(AGENTS))
    spec = importlib.util.spec_from_file_location(f"agents_{name}", AGENTS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _drive(env, offsets, seed=3):
    """Step ``env`` with normalised offsets; returns (total reward, summed info terms, last info)."""
    env.reset(seed=seed)
    total, terms, info = 0.0, {}, {}
    for u in offsets:
        _, r, term, trunc, info = env.step(np.array([u], dtype=np.float32))
        total += r
        for k, v in info["excitation"].items():
            if k.startswith(("penalty", "reward")):
                terms[k] = terms.get(k, 0.0) + v
        if term or trunc:
            break
    return total, terms, info


# -- registration (both env checkers: tests/test_registration.py) ---------------------------------
def test_registered_spec_recreates_the_same_env():
    env = gym.make(ENV_ID, config={"ay_limit": 6.0})
    again = gym.make(env.spec)
    assert again.get_wrapper_attr("config").ay_limit == 6.0
    a = env.reset(seed=4)[0]
    b = again.reset(seed=4)[0]
    np.testing.assert_array_equal(a, b)


def test_spaces_and_unknown_keys():
    env = gym.make(ENV_ID)
    assert env.action_space.shape == (1,) and env.action_space.low[0] == -1 and env.action_space.high[0] == 1
    n_target = len(env.get_wrapper_attr("target_names"))
    assert env.observation_space.shape == (16 + n_target,)
    with pytest.raises(ParameterError, match="frobnicate"):
        gym.make(ENV_ID, config={"frobnicate": 1})
    with pytest.raises(ParameterError, match="reward"):
        ExcitationConfig(reward="ground_truth")
    with pytest.raises(TypeError, match="EstimatorWrapper"):
        ExcitationWrapper(gym.make("TireLearning-LaneKeeping-v0"))
    with pytest.raises(ValueError, match="NaN or infinite"):
        env.reset(seed=0)
        env.step(np.array([np.nan], dtype=np.float32))


def test_target_range_is_the_nominal_slip_at_the_limit():
    veh = tire_learning_env.VehicleParams()
    af, ar = target_slip_range(veh, 4.0)
    assert math.degrees(af) == pytest.approx(1.009, abs=1e-3)
    assert math.degrees(ar) == pytest.approx(0.702, abs=1e-3)
    # steady state: the two axle forces m a lr / L and m a lf / L balance the yaw moment
    assert 2 * veh.Cf * af * veh.lf == pytest.approx(2 * veh.Cr * ar * veh.lr)
    assert target_slip_range(veh, 8.0)[0] == pytest.approx(2 * af)
    env = make_excitation_env()
    G, names = target_functionals(env.observer.basis, veh, (af, ar))
    # the 3 innermost information segments each side ([0, 0.005], [0.005, 0.01], [0.01, 0.02] rad)
    # and the zero-slip offset, per axle: the 30-entry observation the committed policy reads
    assert G.shape == (14, env.observer.n_weights) and len(names) == 14
    assert names[:7] == ("front slope [-0.02, -0.01]", "front slope [-0.01, -0.005]", "front slope [-0.005, -0]",
                         "front slope [0, 0.005]", "front slope [0.005, 0.01]", "front slope [0.01, 0.02]", "front offset")
    assert env.observation_space.shape == (30,)
    assert len(target_functionals(env.observer.basis, veh, target_slip_range(veh, 8.0))[1]) == 18  # +[0.02, 0.04]
    # each functional reads what it says off the learned curve, for any weights
    rng = np.random.default_rng(0)
    w = rng.uniform(env.observer.basis.weight_lower.ravel(), env.observer.basis.weight_upper.ravel())
    obs = env.observer
    for g, name in zip(G, names):
        axle = name.split()[0]
        c2 = 2.0 * (veh.Cf if axle == "front" else veh.Cr)
        nonlinear = lambda a: obs.axle_force(a, axle, weights=w) - c2 * a  # noqa: E731
        if name.endswith("offset"):
            expected = nonlinear(0.0) / (c2 * 0.01)
        else:
            lo, hi = (float(v) for v in name[name.index("[") + 1 : -1].split(","))
            expected = (nonlinear(hi) - nonlinear(lo)) / ((hi - lo) * c2)
        assert g @ w == pytest.approx(expected, rel=1e-9, abs=1e-12)
    assert np.linalg.matrix_rank(G) == 14


# -- reward ---------------------------------------------------------------------------------------
def test_reward_grows_when_the_same_drive_excites_a_wider_slip_range():
    """Same seed (truth, noise), same in-lane weave shape, two amplitudes within every limit."""
    k = np.arange(300)
    shape = np.sin(2 * np.pi * 0.4 * k / 20.0)
    env = make_excitation_env(randomization=True)
    small, small_terms, _ = _drive(env, 0.12 * shape)
    m_small = env.episode_metrics()
    large, large_terms, _ = _drive(env, 0.3 * shape)
    m_large = env.episode_metrics()
    for m in (m_small, m_large):  # no limit reached: the difference is information only
        assert m["max_abs_ay"] < 0.9 * env.config.ay_limit and m["max_abs_e1"] < 0.9 * env.config.lane_margin
    assert m_large["excited_slip_range_deg"]["front"][1] > 1.5 * m_small["excited_slip_range_deg"]["front"][1]
    assert large_terms["reward_information"] > small_terms["reward_information"] + 5.0
    assert large > small + 5.0


def test_lane_departure_and_ay_limit_are_penalised():
    env = make_excitation_env(config=ExcitationConfig(safety_filter=False))  # the filter would prevent both
    total, terms, info = _drive(env, np.ones(200))  # hard left until the car leaves the lane
    assert info["excitation"]["penalty_departure"] == env.config.departure_penalty
    assert terms["penalty_lane"] >= env.config.violation_penalty  # |e1_hat| beyond the margin before leaving
    assert terms["penalty_ay"] >= env.config.violation_penalty  # full offset exceeds 4 m/s^2
    assert total < -env.config.departure_penalty
    assert env.episode_metrics()["departed"]
    # the same episode start without the departure: no such penalties
    _, calm, info = _drive(env, np.zeros(40))
    assert calm["penalty_departure"] == 0 and calm["penalty_lane"] == 0


def test_information_reward_is_computable_from_the_sensor_log_alone():
    """Re-run a fresh observer on the logged sensors only: it reaches the same information."""
    env = make_excitation_env(info_logs=True)
    env.reset(seed=5)
    logs, info = [], None
    for k in range(120):
        _, _, _, _, info = env.step(np.array([0.4 * np.sin(0.25 * k)], dtype=np.float32))
        logs.append({key: info["sensor_log"][key] for key in SENSOR_KEYS})
    sensors = {key: np.concatenate([lg[key] for lg in logs]) for key in SENSOR_KEYS}
    obs = build_observer(env.vehicle, EXCITATION_CAMERA, env.estimator.config, 1e-3)
    obs.run(sensors)
    G = env.target_functionals
    j = -np.linalg.slogdet(G @ obs.pw @ G.T)[1]
    assert j == pytest.approx(info["excitation"]["information"], rel=1e-9)
    assert info["excitation"]["information"] > info["excitation"]["information_initial"] + 1.0


def test_truth_nrmse_reward_telescopes_to_the_error_decrease():
    cfg = ExcitationConfig(reward="truth_nrmse", ay_penalty=0, lane_penalty=0, violation_penalty=0, steering_rate_penalty=0)
    env = make_excitation_env(config=cfg)
    env.reset(seed=2)
    e0 = env.truth_error()
    total = sum(env.step(np.array([0.3 * np.sin(0.3 * k)], dtype=np.float32))[1] for k in range(100))
    assert total == pytest.approx(cfg.truth_scale * (e0 - env.truth_error()), rel=1e-9)


def test_min_eig_measure_and_test_track_setting():
    env = make_excitation_env(config=ExcitationConfig.test_track(information_measure="min_eig"))
    assert env.config.ay_limit == 8.0
    _, terms, info = _drive(env, 0.3 * np.sin(np.arange(100) * 0.12))
    assert info["excitation"]["information"] > info["excitation"]["information_initial"]


# -- truth randomisation and determinism ---------------------------------------------------------
def test_truth_randomisation_follows_the_seed():
    env = gym.make(ENV_ID)
    _, i1 = env.reset(seed=11)
    c1 = env.unwrapped.plant.true_axle_curve(0.02, "front")
    _, i2 = env.reset(seed=12)
    c2 = env.unwrapped.plant.true_axle_curve(0.02, "front")
    _, i3 = env.reset(seed=11)
    assert i1["truth_draw"] == i3["truth_draw"] != i2["truth_draw"]
    assert c1 != c2 and env.unwrapped.plant.true_axle_curve(0.02, "front") == c1
    lo, hi = TruthRandomization().stiffness_scale_low, TruthRandomization().stiffness_scale_high
    assert lo <= i1["truth_draw"]["scale_front"] <= hi


def test_same_seed_same_rollout():
    def roll(seed):
        env = gym.make(ENV_ID)
        obs, _ = env.reset(seed=seed)
        out = [obs]
        for k in range(40):
            obs, r, *_ = env.step(np.array([np.sin(0.3 * k)], dtype=np.float32))
            out += [obs, [r]]
        return np.concatenate([np.ravel(o) for o in out])

    np.testing.assert_array_equal(roll(7), roll(7))
    assert not np.allclose(roll(7), roll(8))


def test_highway_traffic_variant():
    """Same wrapper around the highway-env traffic scene (in-lane weaving among traffic)."""
    env = gym.make("TireLearning-HighwayExcitation-v0", config={"episode_time": 60.0})
    obs, info = env.reset(seed=3)
    assert obs.shape == env.observation_space.shape and "truth_draw" in info
    for k in range(80):  # 4 s: the observer's weights stay frozen for the first 3 s
        obs, r, term, trunc, info = env.step(np.array([0.4 * np.sin(0.2 * k)], dtype=np.float32))
        assert env.observation_space.contains(obs) and np.isfinite(r)
    assert info["excitation"]["information"] > info["excitation"]["information_initial"]
    assert env.get_wrapper_attr("episode_metrics")()["steps"] == 80


# -- agents/: training smoke runs, committed policy, evaluation ---------------------------------
@pytest.mark.parametrize("config", ["ppo.json", "sac.json"])
def test_smoke_training(tmp_path, config):
    train = _load_script("train")
    out = tmp_path / config.split(".")[0]
    overrides = ["--total-timesteps", "400", "--no-validation", "--no-progress"]
    # the committed config with a smoke-sized update: learning must actually happen within the 400 steps
    cfg = json.loads((AGENTS / "configs" / config).read_text())
    if config == "sac.json":  # learning must actually start within the smoke budget
        cfg["algo_kwargs"]["learning_starts"] = 100
    else:  # one PPO rollout of 200 steps per env (n_envs 2) is the 400 steps; the committed 1200 drove 2400
        assert cfg["n_envs"] == 2
        cfg["algo_kwargs"].update(n_steps=200, batch_size=100)
    (tmp_path / config).write_text(json.dumps(cfg))
    path = tmp_path / config
    assert train.main(["--config", str(path), "--seed", "1", "--out", str(out), *overrides]) == 0
    run = json.loads((out / "run.json").read_text())
    assert run["timesteps"] >= 400 and run["seed"] == 1
    assert (out / "final_model.zip").exists() and (out / "progress.csv").read_text().count("\n") >= 2
    common = _load_script("_common")
    model = common.load_model(out / "final_model.zip")
    env = gym.make(ENV_ID)
    obs, _ = env.reset(seed=0)
    action, _ = model.predict(obs, deterministic=True)
    assert env.action_space.contains(action)


def test_unknown_training_config_key_is_named(tmp_path):
    common = _load_script("_common")
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"algo": "PPO", "total_timesteps": 10, "learning_rat": 1}))
    with pytest.raises(common.ConfigError, match="learning_rat"):
        common.load_config(bad)


def test_committed_policy_loads_and_runs():
    policies = sorted((AGENTS / "policies").glob("*.zip"))
    assert policies, "no committed policy under agents/policies/"
    common = _load_script("_common")
    for path in policies:
        meta = json.loads(path.with_suffix(".json").read_text())
        assert {"algo", "command", "seed", "wall_time_s"} <= set(meta)
        model = common.load_model(path)
        result = run_policy(common.model_policy(model), seed=1000, duration=5.0)
        assert result["steps"] == 100


def test_evaluation_script_writes_the_table(tmp_path):
    evaluate = _load_script("evaluate")
    assert evaluate.main(["--seeds", "1000", "1001", "--duration", "4", "--out", str(tmp_path)]) == 0
    data = json.loads((tmp_path / "excitation_table.json").read_text())
    names = [r["name"] for r in data["summary"]]
    assert {"none", "cornering", "lane_changes", "sine_road", "chirp_road", "sine_weave", "chirp_weave"} <= set(names)
    assert any(r["kind"] == "learned" for r in data["summary"])
    for r in data["results"]:
        assert [e["seed"] for e in r["episodes"]] == [1000, 1001]
    table = (tmp_path / "excitation_table.md").read_text()
    assert table.count("\n| ") >= len(names) + 1 and "Best scripted baseline" in table
    assert (tmp_path / "figures" / "excitation_curves.png").stat().st_size > 10_000
    # scripted manoeuvres are driven with and without the safety filter by default
    kinds = {(r["name"], r["safety_filter"]) for r in data["summary"] if r["kind"] == "scripted"}
    assert ("lane_changes", True) in kinds and ("lane_changes", False) in kinds


def test_evaluation_on_the_highway_variant_with_and_without_the_filter(tmp_path):
    evaluate = _load_script("evaluate")
    policy = str(AGENTS / "policies" / "ppo_excitation.zip")
    args = ["--env", "highway", "--policies", policy, "--policy-filter", "both", "--seeds", "4000", "--duration", "3",
            "--no-figures", "--out", str(tmp_path)]  # fmt: skip
    assert evaluate.main(args) == 0
    data = json.loads((tmp_path / "excitation_table.json").read_text())
    assert data["meta"]["env_id"] == "TireLearning-HighwayExcitation-v0"
    rows = {(r["name"], r["kind"], r["safety_filter"]) for r in data["summary"]}
    assert rows == {("ppo", "learned", True), ("ppo", "learned", False)}  # no scripted rows: they need their roads
    assert "TireLearning-HighwayExcitation-v0" in (tmp_path / "excitation_table.md").read_text()
