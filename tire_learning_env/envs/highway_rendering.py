"""Rendering of the traffic scenes through highway-env's viewer."""

from __future__ import annotations

import os

__all__ = ["make_viewer"]


class _ViewerScene:
    """The few attributes highway-env's ``EnvViewer`` reads from an env."""

    observation_type = None
    action_type = None

    def __init__(self, env, config: dict) -> None:
        self._env = env
        self.config = config

    @property
    def road(self):
        return self._env.road

    @property
    def vehicle(self):
        return self._env.ego

    def close(self) -> None:
        pass


def make_viewer(env, traffic_frequency: float, overrides: dict):
    """highway-env's ``EnvViewer`` drawing ``env.road`` around ``env.ego`` off-screen (headless without a display).

    Parameters
    ----------
    env
        A traffic env (``road`` and ``ego`` attributes).
    traffic_frequency : float
        highway-env's simulation frequency [Hz] (its viewer draws at that rate).
    overrides : dict
        Viewer settings of the scene (screen size, centring, scaling).
    """
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # headless
    from highway_env.envs.common.graphics import EnvViewer

    config = {
        "screen_width": 600,
        "screen_height": 150,
        "scaling": 5.5,
        "centering_position": [0.3, 0.5],
        "offscreen_rendering": True,
        "render_agent": True,
        "real_time_rendering": False,
        "simulation_frequency": traffic_frequency,
    }
    config.update(overrides)
    viewer = EnvViewer(_ViewerScene(env, config), config=config)
    viewer.enabled = True  # highway-env disables drawing under SDL's dummy driver; offscreen needs no display
    return viewer
