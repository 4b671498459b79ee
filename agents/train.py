#!/usr/bin/env python
"""Train an excitation policy with stable-baselines3 (PPO or SAC) on ``TireLearning-Excitation-v0``.

Examples
--------
    python agents/train.py --config agents/configs/ppo.json --seed 0 --out runs/ppo_seed0
    python agents/train.py --config agents/configs/sac.json --seed 0 --out runs/sac_seed0
    python agents/train.py --config agents/configs/ppo.json --total-timesteps 512 --out /tmp/smoke

Writes to ``--out``: ``progress.csv`` and TensorBoard events (``tensorboard --logdir
runs/``), ``checkpoints/<algo>_<steps>_steps.zip``, ``final_model.zip``,
``best_model.zip`` (lowest validation tire-curve error without a limit violation, when
validation is on) and ``run.json`` (configuration, seed, command, wall time, steps/s,
package versions). The printed last line is ``run.json``'s path.

Seeds: ``--seed S`` seeds torch/numpy (SB3 ``seed=S``) and the envs (env ``i`` is reset
first with seed ``S + i``; later resets continue its random streams). Validation uses
the seeds of the config (default 500-502), evaluation 1000-1009: neither is a training
reset seed.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shlex
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

from _common import (  # noqa: E402
    algo_class,
    load_config,
    model_policy,
    policy_kwargs_from_config,
    versions,
)


def _callbacks(cfg: dict[str, Any], out: Path, n_envs: int, progress: bool, total: int):
    from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback

    class ProgressBar(BaseCallback):
        """tqdm progress bar over env steps (SB3's own needs ``rich``)."""

        def _on_training_start(self) -> None:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=total, unit="step", dynamic_ncols=True, desc=cfg["algo"])

        def _on_step(self) -> bool:
            self.bar.update(self.training_env.num_envs)
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    class EpisodeStats(BaseCallback):
        """Per-episode sums of the reward terms, max |a_y| and information gain -> logger ``excitation/*``."""

        KEYS = ("reward_information", "penalty_ay", "penalty_lane", "penalty_steering_rate", "penalty_departure")

        def _on_training_start(self) -> None:
            self.acc = [dict.fromkeys(self.KEYS + ("max_abs_ay", "steps"), 0.0) for _ in range(self.training_env.num_envs)]

        def _on_step(self) -> bool:
            for i, (info, done) in enumerate(zip(self.locals["infos"], self.locals["dones"])):
                ex = info.get("excitation")
                if ex is None:
                    continue
                acc = self.acc[i]
                for k in self.KEYS:
                    acc[k] += ex.get(k, 0.0)
                acc["max_abs_ay"] = max(acc["max_abs_ay"], ex.get("max_abs_ay", 0.0))
                acc["steps"] += 1
                if done:
                    for k, v in acc.items():
                        self.logger.record_mean(f"excitation/{k}", v)
                    self.acc[i] = dict.fromkeys(acc, 0.0)
            return True

    class Validation(BaseCallback):
        """Every ``validate_every`` steps: deterministic episodes on the validation seeds, scored against the truth."""

        def __init__(self, every: int, seeds: list[int], env_kwargs: dict[str, Any]) -> None:
            super().__init__()
            self.every, self.seeds, self.env_kwargs = every, seeds, env_kwargs
            self.next_at = every
            self.best = math.inf
            self.history: list[dict[str, Any]] = []

        def _on_step(self) -> bool:
            if self.num_timesteps < self.next_at:
                return True
            self.next_at += self.every
            from tire_learning_env.scripted import run_policy

            kwargs = {k: v for k, v in self.env_kwargs.items() if k not in ("record", "keep_history")}
            act = model_policy(self.model)
            results = [run_policy(act, seed=s, **kwargs) for s in self.seeds]
            nrmse = float(np.mean([r["tire_curve_nrmse_max"] for r in results]))
            violations = int(sum(r["lane_violation_steps"] + r["ay_violation_steps"] + r["departed"] for r in results))
            max_ay = float(max(r["max_abs_ay"] for r in results))
            self.logger.record("validation/tire_curve_nrmse_max", nrmse)
            self.logger.record("validation/violation_steps", violations)
            self.logger.record("validation/max_abs_ay", max_ay)
            entry = {"timesteps": self.num_timesteps, "nrmse_max": nrmse, "violation_steps": violations, "max_abs_ay": max_ay}
            if violations == 0 and nrmse < self.best:
                self.best = nrmse
                self.model.save(str(out / "best_model.zip"))
                entry["saved_best"] = True
            self.history.append(entry)
            return True

    callbacks: list[BaseCallback] = [EpisodeStats()]
    if progress:
        callbacks.append(ProgressBar())
    if cfg["checkpoint_every"]:
        callbacks.append(
            CheckpointCallback(max(cfg["checkpoint_every"] // n_envs, 1), str(out / "checkpoints"), name_prefix=cfg["algo"].lower())
        )
    validation = None
    if cfg["validate_every"]:
        validation = Validation(int(cfg["validate_every"]), list(cfg["validation_seeds"]), dict(cfg["env_kwargs"]))
        callbacks.append(validation)
    return callbacks, validation


def train(cfg: dict[str, Any], seed: int, out: Path, progress: bool = True, command: str = "") -> dict[str, Any]:
    """Train with ``cfg`` (see ``_common.CONFIG_KEYS``); returns the ``run.json`` content."""
    import torch
    from stable_baselines3.common import logger as sb3_logger
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    import tire_learning_env  # noqa: F401  (registers the ids)

    torch.set_num_threads(int(cfg["torch_threads"]))
    out.mkdir(parents=True, exist_ok=True)
    vec_cls = SubprocVecEnv if cfg["vec_env"] == "subproc" else DummyVecEnv
    env = make_vec_env(cfg["env_id"], n_envs=cfg["n_envs"], seed=seed, vec_env_cls=vec_cls, env_kwargs=cfg["env_kwargs"])
    formats = ["csv"]
    try:
        import tensorboard  # noqa: F401

        formats.append("tensorboard")
    except ImportError:
        print("tensorboard is not installed: writing CSV logs only", file=sys.stderr)
    if not progress:
        formats.append("stdout")
    algo = algo_class(cfg["algo"])
    model = algo(
        cfg["policy"],
        env,
        seed=seed,
        device="cpu",
        verbose=0,
        policy_kwargs=policy_kwargs_from_config(cfg["policy_kwargs"]),
        **cfg["algo_kwargs"],
    )
    model.set_logger(sb3_logger.configure(str(out), formats))
    callbacks, validation = _callbacks(cfg, out, cfg["n_envs"], progress, cfg["total_timesteps"])
    t0, c0 = time.perf_counter(), time.process_time()
    model.learn(total_timesteps=cfg["total_timesteps"], callback=callbacks)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    model.logger.dump(model.num_timesteps)  # the last values (SAC dumps only every few episodes)
    model.save(str(out / "final_model.zip"))
    env.close()
    run = {
        "algo": cfg["algo"],
        "seed": seed,
        "command": command,
        "config": cfg,
        "timesteps": int(model.num_timesteps),
        "wall_time_s": wall,
        "cpu_time_s": cpu,
        "train_steps_per_s": model.num_timesteps / wall,
        "load_average_at_end": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
        "validation": None if validation is None else {"best_nrmse_max": validation.best, "history": validation.history},
        "versions": versions(),
        "final_model": str(out / "final_model.zip"),
        "best_model": str(out / "best_model.zip") if (out / "best_model.zip").exists() else None,
    }
    (out / "run.json").write_text(json.dumps(run, indent=2, default=str))
    return run


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", type=Path, required=True, help="training configuration JSON (agents/configs/)")
    parser.add_argument("--seed", type=int, default=0, help="training seed (torch, numpy, env resets)")
    parser.add_argument("--out", type=Path, required=True, help="output directory")
    parser.add_argument("--total-timesteps", type=int, default=None, help="override the config's total_timesteps")
    parser.add_argument("--no-validation", action="store_true", help="skip the periodic validation episodes")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar (log to stdout instead)")
    args = parser.parse_args(argv)
    overrides: dict[str, Any] = {}
    if args.total_timesteps is not None:
        overrides["total_timesteps"] = args.total_timesteps
    if args.no_validation:
        overrides["validate_every"] = 0
    cfg = load_config(args.config, overrides)
    command = " ".join(shlex.quote(a) for a in ["python", "agents/train.py", *(argv if argv is not None else sys.argv[1:])])
    run = train(cfg, args.seed, args.out, progress=not args.no_progress, command=command)
    print(
        f"{run['algo']}: {run['timesteps']} steps in {run['wall_time_s']:.1f} s "
        f"({run['train_steps_per_s']:.0f} steps/s, CPU {run['cpu_time_s']:.1f} s); final model {run['final_model']}"
    )
    print(args.out / "run.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
