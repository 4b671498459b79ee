"""Speed of the excitation task: env steps/s against stable-baselines3 training steps/s, printed as JSON.

- ``env_steps_per_s``: ``TireLearning-Excitation-v0`` (1 kHz truth physics, 30 Hz camera,
  the observer's RLS update and the information reward, 20 Hz policy) stepped with
  random actions, one process, one core, safety filter on (the default); also the
  pieces (base env alone, base env + observer, the task without the safety filter) so
  the wrapper's and the filter's own costs are visible.
- ``ppo_train_steps_per_s`` / ``sac_train_steps_per_s``: ``model.learn`` throughput
  (env steps per wall second, data collection and gradient updates together) with the
  settings of ``agents/configs/ppo.json`` / ``sac.json`` (2 envs in one process, torch
  on one thread), on the same machine. SAC is measured after its warm-up
  (``learning_starts``), when it does one gradient step per env step.
- ``env_share_of_training``: the fraction of PPO/SAC training wall time spent stepping
  envs, ``train_steps_per_s / env_steps_per_s``: env steps are not the bottleneck when
  it is small.

Run: ``python benchmarks/bench_excitation.py`` (about 1-2 minutes).
"""

from __future__ import annotations

import importlib.util
import time
from pathlib import Path

from _bench_common import emit

import numpy as np  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def env_rate(make, seconds: float = 4.0) -> float:
    """Env steps per second with random actions (resets included)."""
    env = make()
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(50):  # warm-up (compilation, caches)
        env.step(rng.uniform(-1, 1, size=env.action_space.shape).astype(np.float32) * env.action_space.high)
    env.reset(seed=1)
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        a = rng.uniform(-1, 1, size=env.action_space.shape).astype(np.float32) * env.action_space.high
        _, _, term, trunc, _ = env.step(a)
        n += 1
        if term or trunc:
            env.reset()
    return n / (time.perf_counter() - t0)


def _agents_common():
    """``agents/_common.py``, loaded from its file (``agents/`` is not on ``sys.path`` here)."""
    spec = importlib.util.spec_from_file_location("agents_common", REPO / "agents" / "_common.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def train_rate(config: str, steps: int, warmup: int = 0) -> float:
    """``model.learn`` env steps per wall second with ``agents/configs/<config>``."""
    import torch
    from stable_baselines3.common.env_util import make_vec_env

    agents = _agents_common()
    algo_class, load_config, policy_kwargs_from_config = (
        agents.algo_class, agents.load_config, agents.policy_kwargs_from_config
    )
    cfg = load_config(REPO / "agents" / "configs" / config)
    torch.set_num_threads(int(cfg["torch_threads"]))
    env = make_vec_env(cfg["env_id"], n_envs=cfg["n_envs"], seed=0, env_kwargs=cfg["env_kwargs"])
    kwargs = dict(cfg["algo_kwargs"])
    if "learning_starts" in kwargs:
        kwargs["learning_starts"] = min(kwargs["learning_starts"], warmup)
    model = algo_class(cfg["algo"])(cfg["policy"], env, seed=0, device="cpu", verbose=0,
                                    policy_kwargs=policy_kwargs_from_config(cfg["policy_kwargs"]), **kwargs)  # fmt: skip
    if warmup:
        model.learn(total_timesteps=warmup)
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps, reset_num_timesteps=False)
    return steps / (time.perf_counter() - t0)


def main() -> None:
    import gymnasium as gym

    import tire_learning_env  # noqa: F401
    from tire_learning_env.wrappers import EstimatorWrapper
    from tire_learning_env.wrappers.excitation import EXCITATION_CAMERA

    base = env_rate(lambda: gym.make("TireLearning-LaneKeeping-v0", road="straight", camera=EXCITATION_CAMERA))
    with_observer = env_rate(
        lambda: EstimatorWrapper(gym.make("TireLearning-LaneKeeping-v0", road="straight", camera=EXCITATION_CAMERA),
                                 keep_history=False)  # fmt: skip
    )
    excitation = env_rate(lambda: gym.make("TireLearning-Excitation-v0", record=False))
    unfiltered = env_rate(
        lambda: gym.make("TireLearning-Excitation-v0", record=False, config={"safety_filter": False})
    )
    ppo = train_rate("ppo.json", steps=12_000)
    sac = train_rate("sac.json", steps=2_000, warmup=1_000)
    emit(
        {
            "benchmark": "excitation",
            "env_steps_per_s": round(excitation, 1),
            "env_pieces_steps_per_s": {"base_env": round(base, 1), "base_env_plus_observer": round(with_observer, 1),
                                       "excitation_without_safety_filter": round(unfiltered, 1)},
            "env_simulated_seconds_per_wall_second": round(excitation / 20.0, 1),
            "ppo_train_steps_per_s": round(ppo, 1),
            "sac_train_steps_per_s": round(sac, 1),
            "env_share_of_training": {"ppo": round(ppo / excitation, 3), "sac": round(sac / excitation, 3)},
            "notes": "one process; PPO/SAC with 2 envs in that process and torch on one thread (agents/configs)",
        }
    )


if __name__ == "__main__":
    main()
