"""The certified gains and their certificates: :class:`ObserverGains` (gains per speed cell, the
``lmi`` summary) and :class:`GroupCertificate` (one channel group); made by
:func:`.gains.synthesize_gains`, re-exported by :mod:`.gains`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .model import MeasurementModel

__all__ = ["GroupCertificate", "ObserverGains"]


@dataclass
class GroupCertificate:
    """The certificate of one channel group's gains."""

    group: str
    period: float
    P: NDArray
    decay_rate: float
    vertex_decay_rate: float
    cost: float
    max_vertex_eig: float
    dense_points: int
    dense_contraction: float
    certified: bool
    n_vertices: int
    solve_s: float

    def to_dict(self) -> dict:
        return {
            "group": self.group,
            "period_s": self.period,
            "certified": bool(self.certified),
            "decay_rate_certified": float(self.decay_rate),
            "decay_rate_at_vertices": float(self.vertex_decay_rate),
            "h2_cost": float(self.cost),
            "max_vertex_eig": float(self.max_vertex_eig),
            "n_vertices": int(self.n_vertices),
            "dense_check_points": int(self.dense_points),
            "dense_check_worst_contraction": float(self.dense_contraction),
            "solve_s": round(self.solve_s, 4),
        }


@dataclass
class ObserverGains:
    """Certified gains per speed cell for the channel groups of a measurement model.

    Attributes
    ----------
    edges : ndarray (n_cells + 1,)
        Speed cell edges [m/s].
    L_cam, L_imu : ndarray (n_cells, nx, 2)
        Correction gains of the camera / IMU channels (zeros for a group not used), SI:
        ``x += L [z - h(x)]``.
    slope_box : ndarray (2, 2)
        Certified total axle slopes ``[[k_f_lo, k_f_hi], [k_r_lo, k_r_hi]]`` [N/rad].
    certificates : list of GroupCertificate
    """

    model: MeasurementModel
    edges: NDArray
    L_cam: NDArray
    L_imu: NDArray
    slope_box: NDArray
    certificates: list
    cache_hit: bool = False
    settings: dict = field(default_factory=dict)

    @property
    def certified(self) -> bool:
        return all(c.certified for c in self.certificates)

    @property
    def decay_rate(self) -> float:
        """Slowest certified decay rate over the groups [1/s]."""
        return min(c.decay_rate for c in self.certificates)

    @property
    def frame_period(self) -> float:
        return self.certificates[-1].period

    @property
    def solve_s(self) -> float:
        return sum(c.solve_s for c in self.certificates)

    @property
    def n_cells(self) -> int:
        return len(self.edges) - 1

    @property
    def speed_range(self) -> tuple[float, float]:
        return float(self.edges[0]), float(self.edges[-1])

    def cell_index(self, vx) -> NDArray:
        """Cell of each speed (speeds outside the range use the nearest cell)."""
        idx = np.searchsorted(self.edges, np.asarray(vx, dtype=float), side="right") - 1
        return np.clip(idx, 0, self.n_cells - 1)

    def summary(self) -> dict:
        """The ``lmi`` block of ``metrics.json``."""
        return {
            "what": "robust-H2 vertex LMIs with a common Lyapunov matrix per channel group, speed-scheduled "
            "gains, numpy re-check at the vertices and on a dense grid of slopes and speeds",
            "sensors": self.model.name,
            "certified": bool(self.certified),
            "decay_rate": float(self.decay_rate),
            "speed_range_mps": list(self.speed_range),
            "n_cells": self.n_cells,
            "slope_box_N_per_rad": {"front": self.slope_box[0].tolist(), "rear": self.slope_box[1].tolist()},
            "groups": [c.to_dict() for c in self.certificates],
            "noise_std_designed": self.settings.get("noise_std"),
            "force_error_N": self.settings.get("force_error_N"),
            "cache_hit": self.cache_hit,
            "solve_s": round(self.solve_s, 4),
            "max_vertex_eig": max(c.max_vertex_eig for c in self.certificates),
            "frame_period_s": self.frame_period,
        }
