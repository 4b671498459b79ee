"""Headless pictures: a top-down view of road, lane and car as an RGB array (numpy only), and
an env episode saved as an animated GIF (:func:`record_episode`, frames from ``env.render()``;
command line: ``examples/record_episode.py``). For MP4 use ``gymnasium.wrappers.RecordVideo``
(it needs ``moviepy``, not a dependency of this package)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Callable

import numpy as np
from gymnasium.spaces import Discrete
from numpy.typing import NDArray

from .roads import Road

__all__ = ["TopDownRenderer", "record_episode", "save_gif"]

_GRASS = np.array([96, 150, 72], dtype=np.uint8)
_ASPHALT = np.array([90, 90, 96], dtype=np.uint8)
_MARKING = np.array([240, 240, 240], dtype=np.uint8)
_PATH = np.array([250, 200, 60], dtype=np.uint8)
_CAR = np.array([40, 110, 230], dtype=np.uint8)
_TRACE = np.array([230, 60, 60], dtype=np.uint8)


class TopDownRenderer:
    """Draws a window that follows the car: three lanes around the reference path.

    Parameters
    ----------
    road : Road
        Reference path (its lane width sets the marking spacing).
    width, height : int
        Image size [px].
    metres_per_pixel : float
        Scale.
    """

    def __init__(self, road: Road, width: int = 480, height: int = 320, metres_per_pixel: float = 0.15) -> None:
        self.road = road
        self.width, self.height, self.mpp = width, height, metres_per_pixel
        self._geom_len = 0.0
        self._geom: dict[str, NDArray] | None = None

    def _geometry(self, s_max: float) -> dict[str, NDArray]:
        if self._geom is None or s_max > self._geom_len:
            self._geom_len = max(2.0 * s_max, 500.0)
            self._geom = self.road.geometry(self._geom_len, ds=0.5)
        return self._geom

    def render(self, s: float, e1: float, e2: float, vehicle_length: float, vehicle_width: float) -> NDArray[np.uint8]:
        """Picture with the car at path distance ``s`` [m], offset ``e1`` [m], heading error ``e2`` [rad]."""
        g = self._geometry(s + self.width * self.mpp)
        i = min(int(round(s / 0.5)), len(g["s"]) - 1)
        cx, cy, ch = g["x"][i], g["y"][i], g["heading"][i]
        nx, ny = -math.sin(ch), math.cos(ch)
        car_x, car_y, car_h = cx + e1 * nx, cy + e1 * ny, ch + e2
        # pixel grid in the world, window aligned with the path heading, car at 1/3 from the left
        u = (np.arange(self.width) - self.width / 3.0) * self.mpp
        v = (self.height / 2.0 - np.arange(self.height)) * self.mpp
        uu, vv = np.meshgrid(u, v)
        wx = car_x + uu * math.cos(ch) - vv * math.sin(ch)
        wy = car_y + uu * math.sin(ch) + vv * math.cos(ch)
        # lateral distance of every pixel to the path: for gently curved paths the nearest
        # path point of a pixel column lies ``u`` metres further along the path
        k = np.clip(i + np.round(uu / 0.5).astype(int), 0, len(g["s"]) - 1)
        px, py, ph = g["x"][k], g["y"][k], g["heading"][k]
        lateral = -(wx - px) * np.sin(ph) + (wy - py) * np.cos(ph)
        # lanes are fixed to the road: the path of a lane change moves across them
        lane_lateral = lateral + self.road.lateral_target(g["s"][k])
        w = self.road.lane_width
        img = np.empty((self.height, self.width, 3), dtype=np.uint8)
        img[:] = _GRASS
        img[np.abs(lane_lateral) < 1.5 * w] = _ASPHALT
        dashes = (np.floor(g["s"][k] / 6.0) % 2) == 0
        for edge in (-1.5 * w, -0.5 * w, 0.5 * w, 1.5 * w):
            line = np.abs(lane_lateral - edge) < 0.12
            img[line & (dashes | (abs(edge) > w))] = _MARKING
        img[np.abs(lateral) < 0.05] = _PATH
        # the car: rectangle in its own frame
        dx, dy = wx - car_x, wy - car_y
        along = dx * math.cos(car_h) + dy * math.sin(car_h)
        across = -dx * math.sin(car_h) + dy * math.cos(car_h)
        img[(np.abs(along) < vehicle_length / 2) & (np.abs(across) < vehicle_width / 2)] = _CAR
        return img


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
        import gymnasium as gym

        env = gym.make(env, render_mode="rgb_array", **make_kwargs)
    if env.render_mode != "rgb_array":
        raise ValueError("record_episode needs an env created with render_mode='rgb_array'")
    if policy is None:
        space = env.action_space
        zero = 0 if isinstance(space, Discrete) else np.zeros(space.shape, dtype=space.dtype)
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
