"""Save an episode of a highway-env scene as an animated GIF (headless).

Frames come from the environment's ``render()`` (highway-env's renderer, drawn offscreen:
no display needed) and are written with Pillow, one frame per policy step, played at the
policy rate. For MP4 use ``gymnasium.wrappers.RecordVideo`` instead (it needs
``moviepy``, which is not a dependency of this package).

Command line::

    python -m tire_learning_env.envs.highway_record --env TireLearning-Highway-v0 \\
        --seconds 20 --seed 0 --out highway.gif --config '{"vehicles_count": 30}'
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Callable

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

__all__ = ["record_episode", "save_gif"]


def save_gif(frames: list[NDArray], path: str | Path, fps: float) -> Path:
    """Write RGB frames (H, W, 3) uint8 to an animated GIF played at ``fps`` [1/s]."""
    from PIL import Image

    if not frames:
        raise ValueError("no frames to save")
    path = Path(path)
    images = [Image.fromarray(np.asarray(f, dtype=np.uint8)) for f in frames]
    duration = max(int(round(1000.0 / fps)), 20)  # [ms]; GIF viewers clamp below 20 ms
    images[0].save(path, save_all=True, append_images=images[1:], duration=duration, loop=0, optimize=False)
    return path


def record_episode(
    env: gym.Env | str,
    path: str | Path,
    seconds: float = 20.0,
    seed: int | None = 0,
    policy: Callable[[NDArray], object] | None = None,
    every: int = 1,
    **make_kwargs,
) -> dict:
    """Run an episode, render every ``every``-th policy step and save it as a GIF.

    Parameters
    ----------
    env : gymnasium.Env or str
        An env created with ``render_mode="rgb_array"``, or a registered id (then created
        with ``make_kwargs``).
    path : str or Path
        Output ``.gif`` file.
    seconds : float
        Simulated time to record [s] (stops earlier if the episode ends).
    seed : int, optional
        Reset seed.
    policy : callable, optional
        ``obs -> action``; default: the zero steering offset (the built-in driver alone),
        or "keep lane" for a discrete action space.
    every : int
        Keep one frame every ``every`` policy steps (the GIF plays in real time).

    Returns
    -------
    dict
        ``path``, ``frames``, ``simulated_s``, ``terminated``, ``truncated``.
    """
    if isinstance(env, str):
        env = gym.make(env, render_mode="rgb_array", **make_kwargs)
    if env.render_mode != "rgb_array":
        raise ValueError("record_episode needs an env created with render_mode='rgb_array'")
    if policy is None:
        space = env.action_space
        zero = 0 if isinstance(space, gym.spaces.Discrete) else np.zeros(space.shape, dtype=space.dtype)
        policy = lambda obs: zero  # noqa: E731
    rate = float(env.unwrapped.policy_rate)
    obs, _ = env.reset(seed=seed)
    frames = [env.render()]
    terminated = truncated = False
    n_steps = int(round(seconds * rate))
    for k in range(n_steps):
        obs, _, terminated, truncated, _ = env.step(policy(obs))
        if (k + 1) % every == 0 or terminated or truncated:
            frames.append(env.render())
        if terminated or truncated:
            break
    save_gif(frames, path, fps=rate / every)
    return {
        "path": str(path),
        "frames": len(frames),
        "simulated_s": float(env.unwrapped.t),
        "terminated": bool(terminated),
        "truncated": bool(truncated),
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="TireLearning-Highway-v0", help="registered id")
    parser.add_argument("--out", default="episode.gif", help="output GIF")
    parser.add_argument("--seconds", type=float, default=20.0, help="simulated time [s]")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--every", type=int, default=1, help="keep one frame every N policy steps")
    parser.add_argument("--config", default=None, help="JSON dict of env config keys")
    args = parser.parse_args(argv)
    import tire_learning_env  # noqa: F401  (registers the ids)

    config = json.loads(args.config) if args.config else None
    result = record_episode(args.env, args.out, args.seconds, args.seed, every=args.every, config=config)
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
