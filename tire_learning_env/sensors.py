"""Lane-camera model: frame rate, latency, noise, bias and dropped frames.

A frame *shows* the true ``[e1, e2]`` at the physics tick on or after ``k / rate`` and is
*delivered* ``latency`` seconds later (on the first tick at or after that instant).
Noise is added per frame (uniform or Gaussian, see
:class:`~tire_learning_env.params.CameraParams`); a dropped frame is delivered as
``NaN`` (the log format's "no frame arrived").

The frame logic is the compiled :func:`~tire_learning_env._kernels.camera_tick`; this
class holds its state arrays and draws the noise, in blocks, from the generator given
to :meth:`Camera.reset` (the env's ``np_random``), so two envs seeded alike see
identical frames however their steps are chunked.
"""

from __future__ import annotations

import math

import numpy as np

from ._kernels import CAMC_NOISE, CAMS_LATEST_E1, CAMS_LATEST_E2, CAMS_LATEST_TIME, camera_tick
from .params import CameraParams, ParameterError

__all__ = ["Camera"]

_BLOCK = 4096


class Camera:
    """Stateful lane camera for a simulation stepped at ``physics_dt``.

    Parameters
    ----------
    params : CameraParams
        Rate, latency, noise, bias and dropout.
    physics_dt : float
        Simulation step [s]; frames and deliveries happen on these ticks.
    camera_x : float
        Where the camera measures ``e1``, ahead of the centre of gravity [m]
        (:attr:`~tire_learning_env.params.VehicleParams.camera_x`; the simulators pass the
        plant's). Default 0: the CG's ``e1``.
    """

    def __init__(self, params: CameraParams, physics_dt: float, camera_x: float = 0.0) -> None:
        self.params = params
        self.dt = float(physics_dt)
        self.camera_x = float(camera_x)
        if not math.isfinite(self.camera_x):
            raise ParameterError(f"camera_x must be finite [m], got {camera_x!r}")
        self.param_vec = np.array([params.rate, params.latency, params.e1_bias, params.e2_bias, self.camera_x])
        capacity = int(math.ceil(params.latency * params.rate)) + 4
        self.pending = np.zeros((capacity, 4))
        self.reset(np.random.default_rng(0))

    def reset(self, rng: np.random.Generator) -> None:
        """Clear pending frames and draw future noise from ``rng``."""
        self._rng = rng
        self.state = np.array([0.0, math.nan, math.nan, math.nan])  # next frame, latest e1, e2, time shown
        self.counters = np.zeros(3, dtype=np.int64)  # noise index, pending head, pending count
        self.noise = np.zeros((0, 2))
        self.drop = np.zeros(0, dtype=np.bool_)

    def ensure_noise(self, n_frames: int) -> None:
        """Make sure noise for at least ``n_frames`` more frames is drawn (whole blocks)."""
        used = int(self.counters[CAMC_NOISE])
        if len(self.noise) - used >= n_frames:
            return
        p = self.params
        blocks = max(1, int(math.ceil((n_frames - (len(self.noise) - used)) / _BLOCK)))
        size = blocks * _BLOCK
        if p.noise == "uniform":
            new = self._rng.uniform(-1.0, 1.0, size=(size, 2)) * (p.e1_noise, p.e2_noise)
        elif p.noise == "gaussian":
            new = self._rng.standard_normal(size=(size, 2)) * (p.e1_noise, p.e2_noise)
        else:
            new = np.zeros((size, 2))
        drop = self._rng.random(size) < p.dropout_probability if p.dropout_probability > 0 else np.zeros(size, bool)
        self.noise = np.ascontiguousarray(np.concatenate([self.noise[used:], new]))
        self.drop = np.ascontiguousarray(np.concatenate([self.drop[used:], drop]))
        self.counters[CAMC_NOISE] = 0

    def kernel_args(self) -> tuple:
        """``(cam, cstate, counters, pending, noise, drop)`` for the compiled loop (call after
        :meth:`ensure_noise`: it may replace the noise arrays)."""
        return self.param_vec, self.state, self.counters, self.pending, self.noise, self.drop

    def tick(self, t: float, e1: float, e2: float, kappa: float = 0.0) -> tuple[float, float] | None:
        """Advance to time ``t`` [s] where the CG's true errors are ``e1`` [m], ``e2`` [rad] on a path of
        curvature ``kappa`` [1/m] (it matters only for a camera ahead of the CG, ``camera_x``).

        Returns
        -------
        tuple of float or None
            The frame delivered at this tick (NaN values for a dropped frame), or ``None``.
        """
        self.ensure_noise(1)
        delivered, d1, d2 = camera_tick(t, e1, e2, kappa, *self.kernel_args())
        return (d1, d2) if delivered else None

    @property
    def latest(self) -> tuple[float, float]:
        """Last delivered valid frame ``(e1, e2)`` (NaN before the first)."""
        return float(self.state[CAMS_LATEST_E1]), float(self.state[CAMS_LATEST_E2])

    @property
    def latest_time(self) -> float:
        """Instant the last valid frame showed [s] (NaN before the first)."""
        return float(self.state[CAMS_LATEST_TIME])
