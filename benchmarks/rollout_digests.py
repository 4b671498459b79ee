"""Digests of rollouts of every registered env id and of ``simulate()`` paths, to check a change is bit-identical.

Not a timing. Each array a rollout returns (observation, reward, flags, every info entry including
``sensor_log`` and ``truth_log``) is hashed (sha256 of dtype, shape and bytes) under a name; two
code trees are compared by their digests::

    PYTHONPATH=/path/to/old python benchmarks/rollout_digests.py --out old.json
    PYTHONPATH=/path/to/new python benchmarks/rollout_digests.py --out new.json
    python benchmarks/rollout_digests.py --compare old.json new.json

Rollouts: every id of :data:`tire_learning_env.registration.ENV_IDS`, seeds 0 and 3, ``--steps``
steps of uniform random actions from a seeded generator (discrete spaces: ``action_space.sample()``
seeded), resets on episode end included; the Cornering id with a noisy 30 Hz camera and full
steering, the LaneChange id with tire relaxation, the Highway id with the noisy camera. ``simulate()``:
study1, lane_changes and sine (compiled loop), a speed profile (Python loop), a noisy camera.
Prints a JSON summary (array count, or the names that differ).
"""

from __future__ import annotations

import argparse
import hashlib
import json

import numpy as np


def _digest(value) -> str:
    a = np.asarray(value)
    h = hashlib.sha256(f"{a.dtype}{a.shape}".encode())
    h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def _put(digests: dict, name: str, value) -> None:
    """Add ``value``'s digest under ``name`` (dicts and sequences of arrays by entry)."""
    if isinstance(value, dict):
        for key in sorted(value):
            _put(digests, f"{name}.{key}", value[key])
    elif isinstance(value, (list, tuple)) and value and not np.isscalar(value[0]):
        for i, v in enumerate(value):
            _put(digests, f"{name}[{i}]", v)
    else:
        try:
            a = np.asarray(value)
        except Exception:  # noqa: BLE001 - an entry numpy cannot take: compared by repr
            a = None
        digests[name] = repr(value) if a is None or a.dtype == object else _digest(a)


def _rollout(digests: dict, env_id: str, seed: int, steps: int, **kwargs) -> None:
    import gymnasium as gym

    env = gym.make(env_id, **kwargs)
    obs, info = env.reset(seed=seed)
    env.action_space.seed(seed)
    rng = np.random.default_rng(seed)
    tag = f"{env_id}/{seed}/{sorted(kwargs)}"
    _put(digests, f"{tag}/reset", {"obs": obs, "info": info})
    for k in range(steps):
        space = env.action_space
        if isinstance(space, gym.spaces.Box):
            action = rng.uniform(space.low, space.high).astype(space.dtype)
        else:
            action = space.sample()
        obs, reward, term, trunc, info = env.step(action)
        _put(digests, f"{tag}/{k}", {"obs": obs, "reward": reward, "term": term, "trunc": trunc, "info": info})
        if term or trunc:
            obs, _ = env.reset()
            _put(digests, f"{tag}/{k}/reset", obs)
    env.close()


def digests(steps: int) -> dict[str, str]:
    """Name -> digest of every array of the rollouts listed in the module docstring."""
    import tire_learning_env
    from tire_learning_env.dynamics import PlantEffects
    from tire_learning_env.registration import ENV_IDS
    from tire_learning_env.simulation import simulate

    out: dict[str, str] = {}
    for env_id in ENV_IDS:
        for seed in (0, 3):
            _rollout(out, env_id, seed, steps)
    cam = tire_learning_env.CameraParams.paper_noise(rate=30.0)
    _rollout(out, "TireLearning-Cornering-v0", 5, steps, camera=cam, action_mode="full")
    _rollout(out, "TireLearning-LaneChange-v0", 6, steps, camera=cam, effects=PlantEffects(relaxation_length=0.5))
    _rollout(out, "TireLearning-Highway-v0", 2, steps, camera=cam)
    for road in ("study1", "lane_changes", "sine"):
        log = simulate(road, 20.0)
        _put(out, f"simulate/{road}", {"sensors": log.sensors, "truth": log.truth})
    _put(out, "simulate/profile", simulate("study1", 10.0, speed_profile=lambda t: (20.0 + 0.5 * t, 0.5)).sensors)
    _put(out, "simulate/noisy", simulate("study1", 20.0, camera=cam, seed=4).sensors)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=120, help="env steps per rollout")
    parser.add_argument("--out", help="write the digests here (JSON)")
    parser.add_argument("--compare", nargs=2, metavar=("A", "B"), help="compare two digest files instead")
    args = parser.parse_args()
    if args.compare:
        a, b = (json.load(open(path))["digests"] for path in args.compare)
        differ = sorted(k for k in a.keys() | b.keys() if a.get(k) != b.get(k))
        print(json.dumps({"entries": [len(a), len(b)], "identical": not differ, "differ": differ[:50]}, indent=2))
        return
    result = {"steps": args.steps, "digests": digests(args.steps)}
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=0, sort_keys=True)
    print(json.dumps({"entries": len(result["digests"]), "out": args.out}, indent=2))


if __name__ == "__main__":
    main()
