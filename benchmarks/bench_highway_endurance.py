"""Endurance run: the default driver in dense highway traffic for 5 minutes, over many seeds.

Counts collisions and lane departures of ``TireLearning-Highway-v0`` driven by its
built-in lane-keeping driver (zero steering offset) with rule-based (MOBIL) lane changes
and IDM speed, in dense traffic (:data:`DENSE_TRAFFIC`), and prints JSON.

Command line (about 5 to 10 minutes on 2 cores)::

    python benchmarks/bench_highway_endurance.py --seeds 20 --minutes 5 --workers 2
"""

from __future__ import annotations

import argparse
import json
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

__all__ = ["DENSE_TRAFFIC", "run_seed", "endurance"]

#: Dense traffic: 30 IDM vehicles at twice highway-env's default density on 3 lanes
#: (recycled around the ego car, so the density holds for the whole run).
DENSE_TRAFFIC: dict[str, Any] = {"vehicles_count": 30, "vehicles_density": 2.0, "lanes_count": 3}


def run_seed(seed: int, seconds: float = 300.0, config: dict | None = None, env_id: str = "TireLearning-Highway-v0") -> dict:
    """Drive one seed for ``seconds`` of simulated time; returns what happened."""
    import gymnasium as gym

    import tire_learning_env  # noqa: F401

    cfg = dict(DENSE_TRAFFIC if config is None else config)
    env = gym.make(env_id, config=cfg, max_episode_steps=None).unwrapped
    env.reset(seed=seed)
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    t0 = time.perf_counter()
    steps = 0
    max_dev = 0.0
    min_gap = np.inf
    speeds = []
    terminated = truncated = False
    info: dict = {}
    while env.t < seconds - 1e-9:
        _, _, terminated, truncated, info = env.step(action)
        steps += 1
        speeds.append(env.vx)
        ego = env.ego
        for v in env.road.vehicles:
            if v is not ego:
                min_gap = min(min_gap, float(np.hypot(*(v.position - ego.position))))
        if terminated or truncated:
            break
        max_dev = max(max_dev, abs(float(info["true_state"][0])) if env._corridor_origin == 0.0 else 0.0)
    return {
        "seed": seed,
        "simulated_s": round(env.t, 3),
        "collision": bool(info.get("crashed", False)),
        "lane_departure": bool(info.get("lane_departure", False)),
        "end_of_road": bool(truncated),
        "lane_changes": int(info.get("lane_changes", 0)),
        "mean_speed": round(float(np.mean(speeds)), 2),
        "min_speed": round(float(np.min(speeds)), 2),
        "max_abs_e1_in_lane": round(max_dev, 4),
        "min_centre_distance_to_traffic": round(min_gap, 2),
        "wall_s": round(time.perf_counter() - t0, 1),
        "policy_steps": steps,
    }


def endurance(
    seeds: int = 20,
    seconds: float = 300.0,
    workers: int = 2,
    config: dict | None = None,
    env_id: str = "TireLearning-Highway-v0",
) -> dict:
    """Run :func:`run_seed` for seeds ``0 .. seeds-1`` and sum up collisions and departures."""
    with ProcessPoolExecutor(max_workers=workers) as pool:
        runs = list(pool.map(run_seed, range(seeds), [seconds] * seeds, [config] * seeds, [env_id] * seeds))
    return {
        "env_id": env_id,
        "config": dict(DENSE_TRAFFIC if config is None else config),
        "seconds_per_seed": seconds,
        "seeds": seeds,
        "collisions": sum(r["collision"] for r in runs),
        "lane_departures": sum(r["lane_departure"] for r in runs),
        "completed": sum(r["simulated_s"] >= seconds - 1e-6 for r in runs),
        "total_lane_changes": sum(r["lane_changes"] for r in runs),
        "runs": runs,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--minutes", type=float, default=5.0)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--config", default=None, help="JSON dict of env config keys (default: DENSE_TRAFFIC)")
    parser.add_argument("--env", default="TireLearning-Highway-v0", help="registered id")
    args = parser.parse_args(argv)
    config = json.loads(args.config) if args.config else None
    print(json.dumps(endurance(args.seeds, 60.0 * args.minutes, args.workers, config, args.env), indent=2))


if __name__ == "__main__":
    main()
