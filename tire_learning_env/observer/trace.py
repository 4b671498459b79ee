"""The per-row output every estimator returns (the neuro-adaptive observer in all its modes, the
joint UKF and the linear Kalman filter): :class:`EstimateTrace`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .model import StateIndex, to_error_state

__all__ = ["EstimateTrace", "HEALTH_NAMES"]

HEALTH_NAMES = ("ok", "settling", "no_data", "inconsistent", "diverged", "recovering")


@dataclass
class EstimateTrace:
    """Per-row estimates (row ``j`` = posterior at ``t_j``).

    Attributes
    ----------
    t : (n,) time [s]
    state : (n, nx) estimated state, components named by ``state_names``
        (``vy`` [m/s], ``yaw_rate`` [rad/s], and with a camera ``e1`` [m], ``e2`` [rad])
    slip : (n, 2) front and rear slip angles [rad]
    force : (n, 2) total axle lateral forces [N]
    force_nonlinear : (n, 2) the part beyond the nominal ``2 C alpha`` [N]
    weights : (n, nw) learned parameters (empty when not recorded)
    std : (n, nx) standard deviation of each state estimate (empty when not computed)
    health : (n,) int8 health code (:data:`HEALTH_NAMES`; 0 = ok)
    innovation : (n, 4) innovations of ``e1, e2, a_y, yaw_rate`` before the correction (NaN: no sample)
    nis : (n,) normalised innovation squared of the row's corrections (NaN: none)
    vx, kappa : (n,) speed [m/s] and path curvature [1/m] of the rows (for coordinate changes)
    state_names : tuple of str
    meta : dict
    """

    t: NDArray
    state: NDArray
    slip: NDArray
    force: NDArray
    force_nonlinear: NDArray
    weights: NDArray
    std: NDArray
    health: NDArray
    innovation: NDArray
    nis: NDArray
    vx: NDArray
    kappa: NDArray
    state_names: tuple = ("vy", "yaw_rate", "e1", "e2")
    meta: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.t)

    @property
    def vy(self) -> NDArray:
        return self.state[:, StateIndex.VY]

    @property
    def yaw_rate(self) -> NDArray:
        return self.state[:, StateIndex.R]

    @property
    def beta(self) -> NDArray:
        """Sideslip at the centre of gravity ``atan(vy / vx)`` [rad]."""
        return np.arctan2(self.vy, np.maximum(self.vx, 1e-3))

    @property
    def has_pose(self) -> bool:
        return self.state.shape[1] == 4

    @property
    def xi(self) -> NDArray:
        """The SPEC §1 error state ``[e1, e1_dot, e2, e2_dot]`` (needs the camera states)."""
        if not self.has_pose:
            raise AttributeError("this estimate has no path states (IMU-only): no error state xi")
        return to_error_state(self.state, self.vx, self.kappa)

    @property
    def healthy(self) -> NDArray:
        """``health == ok`` per row."""
        return self.health == 0

    @property
    def health_fraction(self) -> dict:
        """Fraction of rows in each health state."""
        n = max(len(self.health), 1)
        return {name: float(np.sum(self.health == i)) / n for i, name in enumerate(HEALTH_NAMES)}

    @property
    def final_health(self) -> str:
        return HEALTH_NAMES[int(self.health[-1])] if len(self.health) else "ok"

    @staticmethod
    def concatenate(traces: list["EstimateTrace"]) -> "EstimateTrace":
        """Join consecutive traces (e.g. the steps of an episode)."""
        keys = ("t", "state", "slip", "force", "force_nonlinear", "weights", "std", "health", "innovation", "nis", "vx", "kappa")
        out = {k: np.concatenate([getattr(tr, k) for tr in traces]) for k in keys}
        return EstimateTrace(**out, state_names=traces[0].state_names, meta=dict(traces[0].meta))
