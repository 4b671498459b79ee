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

Several seeds or configurations as Ray tasks (the ``fleet`` extra; docs/fleet.md)::

    python agents/train.py --config agents/configs/ppo.json agents/configs/sac.json \
        --seeds 0 1 2 --workers 2 --out runs/sweep

trains every (config, seed) pair as one task of :func:`tire_learning_env.fleet.run_items`
into ``--out/<config stem>_seed<S>/`` (the single-run files above) and records each
finished run in ``--out/runs.jsonl``; ``--out/runs.csv`` lists them. Re-running the same
command skips the runs already finished with an unchanged configuration, so a sweep
killed half-way resumes where it stopped. ``--address`` joins a Ray cluster (every node
needs this checkout at the same path); ``--serial`` runs the sweep without Ray.
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
    from tire_learning_env.io import atomic_write_text

    atomic_write_text(out / "run.json", json.dumps(run, indent=2, default=str))  # whole or absent after a kill
    return run


def _train_task(spec: dict[str, Any]) -> dict[str, Any]:
    """One run of a sweep (a Ray task): train and return the headline of its ``run.json``."""
    run = train(spec["cfg"], spec["seed"], Path(spec["out"]), progress=False, command=spec["command"])
    val = run.get("validation") or {}
    return {
        "run": spec["name"], "config": spec["config"], "algo": run["algo"], "seed": run["seed"],
        "timesteps": run["timesteps"], "wall_time_s": run["wall_time_s"], "train_steps_per_s": run["train_steps_per_s"],
        "best_nrmse_max": val.get("best_nrmse_max"), "final_model": run["final_model"], "best_model": run["best_model"],
        "out": spec["out"],
    }  # fmt: skip


def sweep(configs: list[Path], seeds: list[int], out: Path, overrides: dict[str, Any], command: str,
          workers: int | None = None, address: str | None = None, serial: bool = False, progress: bool = True,
          cpus_per_run: float = 1.0) -> list:  # fmt: skip
    """Train every (config, seed) pair as a task of :func:`tire_learning_env.fleet.run_items`, resumably.

    Returns the runner's :class:`~tire_learning_env.fleet.ItemResult` list (one per run) and
    writes ``out/runs.jsonl`` (the resume state) and ``out/runs.csv``.
    """
    import csv
    import hashlib
    import io

    from tire_learning_env.fleet import run_items
    from tire_learning_env.io import atomic_write_text

    specs, keys, prints = [], [], []
    stems = [c.stem for c in configs]
    for path in configs:
        cfg = load_config(path, overrides)
        stem = path.stem if stems.count(path.stem) == 1 else f"{path.parent.name}_{path.stem}"
        for seed in seeds:
            name = f"{stem}_seed{seed}"
            specs.append({"cfg": cfg, "seed": seed, "out": str((out / name).resolve()), "name": name,
                          "config": str(path), "command": command})  # fmt: skip
            keys.append(name)
            prints.append(hashlib.sha256(json.dumps([cfg, seed], sort_keys=True, default=str).encode()).hexdigest()[:16])
    agents_dir = str(Path(__file__).resolve().parent)
    pythonpath = os.pathsep.join(p for p in (agents_dir, os.environ.get("PYTHONPATH", "")) if p)
    results = run_items(_train_task, specs, keys=keys, fingerprints=prints, store=out / "runs.jsonl", workers=workers,
                        address=address, engine="serial" if serial else "ray", progress=progress, desc="runs",
                        num_cpus_per_item=cpus_per_run,
                        ray_init_kwargs={"runtime_env": {"env_vars": {"PYTHONPATH": pythonpath}}})  # fmt: skip
    cols = ["run", "status", "error", "config", "algo", "seed", "timesteps", "wall_time_s", "train_steps_per_s",
            "best_nrmse_max", "final_model", "best_model"]  # fmt: skip
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in results:
        row = {"run": r.key, "status": r.status, "error": r.error, **(r.result or {})}
        w.writerow(["" if row.get(c) is None else row.get(c, "") for c in cols])
    atomic_write_text(out / "runs.csv", buf.getvalue())
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", type=Path, nargs="+", required=True,
                        help="training configuration JSON (agents/configs/); several = a sweep on Ray")
    parser.add_argument("--seed", type=int, default=0, help="training seed (torch, numpy, env resets)")
    parser.add_argument("--seeds", type=int, nargs="+", default=None,
                        help="several training seeds: a sweep of every (config, seed) as Ray tasks, resumable")
    parser.add_argument("--workers", type=int, default=None, help="sweep: runs at once on local Ray (default: all cores)")
    parser.add_argument("--address", default=None, help="sweep: join this Ray cluster (auto, HOST:PORT)")
    parser.add_argument("--serial", action="store_true", help="sweep: run in this process, without Ray")
    parser.add_argument("--cpus-per-run", type=float, default=1.0, help="sweep: CPUs Ray reserves per run")
    parser.add_argument("--out", type=Path, required=True,
                        help="output directory (a sweep: one sub-folder per run, runs.jsonl, runs.csv)")
    parser.add_argument("--total-timesteps", type=int, default=None, help="override the config's total_timesteps")
    parser.add_argument("--no-validation", action="store_true", help="skip the periodic validation episodes")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar (log to stdout instead)")
    args = parser.parse_args(argv)
    overrides: dict[str, Any] = {}
    if args.total_timesteps is not None:
        overrides["total_timesteps"] = args.total_timesteps
    if args.no_validation:
        overrides["validate_every"] = 0
    command = " ".join(shlex.quote(a) for a in ["python", "agents/train.py", *(argv if argv is not None else sys.argv[1:])])
    if len(args.config) > 1 or args.seeds is not None:
        results = sweep(args.config, args.seeds if args.seeds is not None else [args.seed], args.out, overrides, command,
                        workers=args.workers, address=args.address, serial=args.serial, progress=not args.no_progress,
                        cpus_per_run=args.cpus_per_run)  # fmt: skip
        counts = {s: sum(r.status == s for r in results) for s in ("ok", "failed", "skipped")}
        for r in results:
            if r.status == "failed":
                print(f"train: run {r.key} failed: {r.error}", file=sys.stderr)
        print(f"{len(results)} runs: {counts['ok']} ok, {counts['failed']} failed, {counts['skipped']} skipped (done before)")
        print(args.out / "runs.csv")
        return 0 if not counts["failed"] else 1
    cfg = load_config(args.config[0], overrides)
    run = train(cfg, args.seed, args.out, progress=not args.no_progress, command=command)
    print(
        f"{run['algo']}: {run['timesteps']} steps in {run['wall_time_s']:.1f} s "
        f"({run['train_steps_per_s']:.0f} steps/s, CPU {run['cpu_time_s']:.1f} s); final model {run['final_model']}"
    )
    print(args.out / "run.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
