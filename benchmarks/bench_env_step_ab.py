"""A/B of two code trees: CPU time per Cornering env step, Study 1 ``simulate()`` and highway step, as JSON.

Each sample is one subprocess running this script with ``--child`` and ``PYTHONPATH`` set to one
tree (the package is imported from it; the measuring code is this file for both), pinned to one
core (:func:`_bench_common.pin_to_one_core`, or ``--cpu``). The trees alternate (old, new, old,
new, ...; the order flips every round) so that load from other users of the machine falls on both;
the summary takes medians over the processes. Every sample carries the 1-minute load average read
before and after it.

Measured with ``time.process_time`` (CPU time of the process, so time the process waits for the
core is not counted; cache and frequency effects of other load still are):

- ``env_step_cpu_us``: ``TireLearning-Cornering-v0`` made by ``gym.make`` (its wrappers included,
  as ``bench_simulator.py`` steps it), zero action; ``--blocks`` blocks of ``--steps`` steps, each
  block after a ``reset(seed=0)`` (not timed), so every block runs the same ticks; the process's
  figure is the median block, in us per step (50 physics ticks per step).
- ``highway_step_cpu_ms``: ``TireLearning-Highway-v0`` with 20 traffic vehicles at a 10 Hz policy
  (``bench_highway.py``'s first configuration), zero action; ``--highway-blocks`` blocks of
  :data:`HIGHWAY_STEPS` steps after a ``reset(seed=0)``, median block in ms per step.
- ``study1_cpu_s``: ``simulate("study1", 60.0)`` (60 000 ticks), median of ``--repeats`` calls,
  measured first in the fresh process (as ``bench_simulator.py`` measures it);
  ``study1_after_env_cpu_s``: the same after the env blocks, in the same process. The two differ
  by a few per cent from process to process, and not the same way for both trees: the heap
  the env steps leave behind moves where the 9.6 MB log and the loop's small arrays land (and how
  many pages the process faults in; a ``simulate()`` faults in ~600-800 pages, ``process_time``
  counts that kernel time too).

Run (from ``benchmarks/``): ``python bench_env_step_ab.py --old /tmp/wt_before`` (``--old``: a git
worktree of the old commit; ``--new`` defaults to this checkout); ``--out FILE`` also writes the JSON.
Issue 20's figures: ``results/env_step_ab_issue20.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from _bench_common import emit, pin_to_one_core

HERE = Path(__file__).resolve().parent
#: Policy steps of ``TireLearning-Highway-v0`` per timed block (10 Hz policy: 4 s simulated).
HIGHWAY_STEPS = 40


def _loadavg() -> float:
    """The 1-minute load average."""
    return round(os.getloadavg()[0], 2)


def child(blocks: int, steps: int, repeats: int, cpu: int | None, highway_blocks: int) -> dict:
    """One sample: the medians of this process (run with ``PYTHONPATH`` set to a tree)."""
    if cpu is None:
        pin_to_one_core()
    else:
        os.sched_setaffinity(0, {cpu})
    load_before = _loadavg()
    import gymnasium as gym
    import numpy as np

    import tire_learning_env
    from tire_learning_env.simulation import simulate

    def study1_cpu_s() -> list[float]:
        """CPU time [s] of each of ``repeats`` Study 1 runs after one warm-up run."""
        simulate("study1", 60.0)  # warm-up (numba cache load)
        times = []
        for _ in range(repeats):
            t0 = time.process_time()
            simulate("study1", 60.0)
            times.append(time.process_time() - t0)
        return times

    study1 = study1_cpu_s()  # first, in the fresh process (as bench_simulator.py measures it)
    env = gym.make("TireLearning-Cornering-v0")
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    env.reset(seed=0)
    for _ in range(50):  # warm-up: first-call paths
        env.step(action)
    per_step = []
    for _ in range(blocks):
        env.reset(seed=0)
        t0 = time.process_time()
        for _ in range(steps):
            env.step(action)
        per_step.append((time.process_time() - t0) / steps * 1e6)
    study1_after = study1_cpu_s()
    highway = []
    if highway_blocks:
        import highway_env  # noqa: F401  (registers highway-env's scenes)

        env = gym.make("TireLearning-Highway-v0", config={"vehicles_count": 20, "policy_rate": 10.0})
        env.reset(seed=0)
        for _ in range(10):  # warm-up
            env.step(action)
        for _ in range(highway_blocks):
            env.reset(seed=0)
            t0 = time.process_time()
            n = 0
            for _ in range(HIGHWAY_STEPS):
                _, _, term, trunc, _ = env.step(action)
                n += 1
                if term or trunc:
                    break
            highway.append((time.process_time() - t0) / n * 1e3)
    return {
        "package": str(Path(tire_learning_env.__file__).resolve().parent),
        "cpu": sorted(os.sched_getaffinity(0)),
        "env_step_cpu_us": round(statistics.median(per_step), 3),
        "env_step_cpu_us_min": round(min(per_step), 3),
        "study1_cpu_s": round(statistics.median(study1), 5),
        "study1_cpu_s_min": round(min(study1), 5),
        "study1_after_env_cpu_s": round(statistics.median(study1_after), 5),
        "highway_step_cpu_ms": round(statistics.median(highway), 4) if highway else None,
        "loadavg_before": load_before,
        "loadavg_after": _loadavg(),
    }


def run_tree(tree: str, args: argparse.Namespace) -> dict:
    """One ``--child`` subprocess with ``PYTHONPATH=tree``; its JSON."""
    env = dict(os.environ, PYTHONPATH=str(Path(tree).resolve()))
    cmd = [sys.executable, str(HERE / "bench_env_step_ab.py"), "--child", "--blocks", str(args.blocks)]
    cmd += ["--steps", str(args.steps), "--repeats", str(args.repeats), "--highway-blocks", str(args.highway_blocks)]
    if args.cpu is not None:
        cmd += ["--cpu", str(args.cpu)]
    out = subprocess.run(cmd, env=env, cwd=HERE, capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


def _summary(samples: list[dict], key: str) -> dict:
    """Median, min, max and the per-process values of ``key`` over ``samples``."""
    values = [s[key] for s in samples]
    return {
        "median": statistics.median(values),
        "min": min(values),
        "max": max(values),
        "samples": values,
    }


def main() -> None:
    """Parse the arguments; run the alternating samples (or, with ``--child``, one sample)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", help="old code tree (a worktree)")
    parser.add_argument("--new", help="new code tree (default: this checkout)", default=str(HERE.parent))
    parser.add_argument("--rounds", type=int, default=6, help="processes per tree (alternating)")
    parser.add_argument("--blocks", type=int, default=15, help="timed blocks of env steps per process")
    parser.add_argument("--steps", type=int, default=200, help="env steps per block")
    parser.add_argument("--repeats", type=int, default=7, help="timed simulate() calls per process")
    parser.add_argument("--highway-blocks", type=int, default=7, help="timed blocks of highway steps (0: none)")
    parser.add_argument("--cpu", type=int, default=None, help="core to pin to (default: the first allowed)")
    parser.add_argument("--out", help="also write the JSON here")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.blocks, args.steps, args.repeats, args.cpu, args.highway_blocks)))
        return
    if not args.old:
        parser.error("--old is required")
    trees = {"old": args.old, "new": args.new}
    # warm the numba caches of both trees (compiles on a fresh tree), not counted
    for tree in trees.values():
        subprocess.run(
            [sys.executable, "-c", "import tire_learning_env.simulation as s; s.simulate('study1', 1.0)"],
            env=dict(os.environ, PYTHONPATH=str(Path(tree).resolve())), check=True, capture_output=True,
        )  # fmt: skip
    samples: dict[str, list[dict]] = {"old": [], "new": []}
    order = []
    for r in range(args.rounds):
        sides = ("old", "new") if r % 2 == 0 else ("new", "old")
        for side in sides:
            sample = run_tree(trees[side], args)
            sample["round"] = r
            samples[side].append(sample)
            order.append(side)
            print(f"{side} {sample}", file=sys.stderr, flush=True)
    result = {
        "benchmark": "env_step_ab",
        "trees": {k: str(Path(v).resolve()) for k, v in trees.items()},
        "command": " ".join([Path(sys.executable).name, *sys.argv]),
        "order": order,
        "settings": {
            "blocks": args.blocks,
            "steps_per_block": args.steps,
            "study1_repeats": args.repeats,
            "highway_blocks": args.highway_blocks,
            "highway_steps_per_block": HIGHWAY_STEPS,
        },
    }
    keys = ["env_step_cpu_us", "study1_cpu_s", "study1_after_env_cpu_s"] + ["highway_step_cpu_ms"] * (args.highway_blocks > 0)
    for key in keys:
        old, new = _summary(samples["old"], key), _summary(samples["new"], key)
        result[key] = {
            "old": old,
            "new": new,
            "new_over_old_median": round(new["median"] / old["median"], 4),
        }
    result["samples"] = samples
    emit(result)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=2)
            f.write("\n")


if __name__ == "__main__":
    main()
