"""Helpers shared by the agent scripts (configuration files, loading policies).

Nothing in the package imports this directory; the scripts put it on ``sys.path``
themselves (``python agents/train.py`` does so automatically).
"""

from __future__ import annotations

import json
import platform
import sys
from pathlib import Path
from typing import Any, Callable

import numpy as np

AGENTS_DIR = Path(__file__).resolve().parent
REPO_DIR = AGENTS_DIR.parent

#: Keys of a training configuration file (agents/configs/*.json).
CONFIG_KEYS = {
    "algo": "PPO or SAC",
    "env_id": "registered env id (default TireLearning-Excitation-v0)",
    "env_kwargs": "keyword arguments of gym.make for the env (e.g. config, randomization, record)",
    "n_envs": "number of parallel envs",
    "vec_env": "'dummy' (same process) or 'subproc' (one process per env)",
    "total_timesteps": "env steps to train for",
    "policy": "SB3 policy name (MlpPolicy)",
    "policy_kwargs": "net_arch (list), activation_fn ('tanh' or 'relu'), log_std_init, ...",
    "algo_kwargs": "keyword arguments of the SB3 algorithm (learning_rate, n_steps, ...)",
    "checkpoint_every": "env steps between checkpoints (0: none)",
    "validate_every": "env steps between validations on validation_seeds (0: none)",
    "validation_seeds": "reset seeds of the validation episodes (never the evaluation seeds)",
    "torch_threads": "torch.set_num_threads",
    "description": "free text",
}
ALGOS = ("PPO", "SAC")

#: Seed ranges kept apart: training streams start at the training seed (0..99),
#: validation during training, baseline tuning, and the held-out evaluation seeds.
VALIDATION_SEEDS = tuple(range(500, 510))
TUNING_SEEDS = (10_000, 10_001, 10_002)
EVALUATION_SEEDS = tuple(range(1000, 1010))


class ConfigError(ValueError):
    """A training configuration file is invalid (the message names the key)."""


def load_config(path: str | Path, overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """Read a training configuration JSON; unknown keys raise :class:`ConfigError` naming them."""
    path = Path(path)
    try:
        cfg = json.loads(path.read_text())
    except OSError as exc:
        raise ConfigError(f"cannot read config {path}: {exc}") from exc
    except json.JSONDecodeError as exc:
        raise ConfigError(f"{path} is not valid JSON: {exc}") from exc
    if not isinstance(cfg, dict):
        raise ConfigError(f"{path}: expected a JSON object")
    cfg.update(overrides or {})
    unknown = sorted(set(cfg) - set(CONFIG_KEYS))
    if unknown:
        raise ConfigError(f"{path}: unknown key(s) {unknown}; allowed keys are {sorted(CONFIG_KEYS)}")
    if cfg.get("algo") not in ALGOS:
        raise ConfigError(f"{path}: 'algo' must be one of {ALGOS}, got {cfg.get('algo')!r}")
    if cfg.get("vec_env", "dummy") not in ("dummy", "subproc"):
        raise ConfigError(f"{path}: 'vec_env' must be 'dummy' or 'subproc', got {cfg.get('vec_env')!r}")
    for key in ("n_envs", "total_timesteps"):
        if key in cfg and not (isinstance(cfg[key], int) and cfg[key] > 0):
            raise ConfigError(f"{path}: {key!r} must be a positive integer, got {cfg[key]!r}")
    defaults = {
        "env_id": "TireLearning-Excitation-v0",
        "env_kwargs": {},
        "n_envs": 2,
        "vec_env": "dummy",
        "policy": "MlpPolicy",
        "policy_kwargs": {},
        "algo_kwargs": {},
        "checkpoint_every": 0,
        "validate_every": 0,
        "validation_seeds": list(VALIDATION_SEEDS),
        "torch_threads": 1,
        "description": "",
    }
    out = {**defaults, **cfg}
    if "total_timesteps" not in out:
        raise ConfigError(f"{path}: 'total_timesteps' is required")
    return out


def policy_kwargs_from_config(kwargs: dict[str, Any]) -> dict[str, Any]:
    """JSON policy kwargs -> SB3 policy kwargs (activation names to torch classes)."""
    import torch

    out = dict(kwargs)
    act = out.get("activation_fn")
    if isinstance(act, str):
        table = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU, "elu": torch.nn.ELU}
        if act not in table:
            raise ConfigError(f"activation_fn must be one of {sorted(table)}, got {act!r}")
        out["activation_fn"] = table[act]
    return out


def algo_class(name: str):
    from stable_baselines3 import PPO, SAC

    return {"PPO": PPO, "SAC": SAC}[name]


def load_model(path: str | Path):
    """Load a saved SB3 model, whichever of PPO/SAC it is (read from its ``.json`` sidecar or tried in turn)."""
    path = Path(path)
    meta = path.with_suffix(".json")
    if meta.exists():
        algo = json.loads(meta.read_text()).get("algo")
        if algo in ALGOS:
            return algo_class(algo).load(str(path), device="cpu")
    last: Exception | None = None
    for name in ALGOS:
        try:
            return algo_class(name).load(str(path), device="cpu")
        except Exception as exc:  # noqa: BLE001 - try the next algorithm
            last = exc
    raise ValueError(f"{path} is neither a PPO nor a SAC model: {last}")


def model_policy(model) -> Callable[[np.ndarray, int], np.ndarray]:
    """``(obs, k) -> action`` of a trained model (deterministic)."""

    def act(obs: np.ndarray, k: int) -> np.ndarray:
        action, _ = model.predict(obs, deterministic=True)
        return action

    return act


def versions() -> dict[str, str]:
    import gymnasium
    import stable_baselines3
    import torch

    import tire_learning_env

    return {
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "torch": torch.__version__,
        "stable_baselines3": stable_baselines3.__version__,
        "gymnasium": gymnasium.__version__,
        "tire_learning_env": tire_learning_env.__version__,
    }
