"""Settings of the neuro-adaptive observer: :class:`AdaptationParams` (the weight prior and the
learning law) and :class:`HealthParams` (the health flag); re-exported by :mod:`.neuro_adaptive`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from ..params import ParameterError, _Params

__all__ = ["AdaptationParams", "HealthParams"]


@dataclass(frozen=True)
class AdaptationParams(_Params):
    """Weight-adaptation settings (weight standard deviations in units of the basis weight range).

    Parameters
    ----------
    initial_std : float
        Prior std of every tire weight, ``P_w(0) = (initial_std r)^2 corr`` with ``r`` the
        basis' :attr:`~.basis.SoftClipBasis.weight_range` and ``corr`` its smooth-curve prior.
    random_walk : float
        Weight random walk [1/sqrt(s)] in the same unit (0: a stationary tire).
    max_std : float
        Cap of each weight's std (``P_w`` stays bounded without excitation).
    settle_time_constants : float
        Weights are frozen after a reset until the initial state error has decayed by
        ``exp(-settle_time_constants)`` at the certified rate (not learned as a tire force).
    prior_length : float
        Length scale [deg of slip] of the smooth slope prior
        (:meth:`~.basis.SoftClipBasis.slope_prior`).
    prior_symmetry : float
        Weight of its left/right mirror term, in [0, 1).
    online_prior_length : float, optional
        Length scale [deg] of the prior the *causal* pass starts from (``None``: ``prior_length``).
        The offline fit always uses ``prior_length``. With a lane camera the causal pass is
        better off without the smooth prior: its correlations spread the noisy early updates
        over the whole curve (measured on 60 s of lane changes with the paper's noise: rear
        stiffness +34 % at ``prior_length`` 1 deg, +11 % at 0; with a nominal 12 % off,
        +17.5 % against -1.4 %), while the offline fit, which sees all data at once, gains
        from it (-0.30/-0.03 % against +0.41/+1.02 %).
    causal_update : {"block", "rls"}
        How the causal pass learns. ``"block"`` (default): the weights are held for
        ``block_s`` seconds while the Kalman predictor of the model accumulates the
        prediction-error normal equations of the block; at the block's end one Gauss-Newton
        step of the fit over *all the data so far* (every block's quadratic model, around
        the weights it was run with, plus the prior) gives the new weights and their
        covariance: the offline fit, made recursive. ``"rls"``: per-measurement recursive
        least squares with the certified gain (the paper's update law). Measured with
        ``benchmarks/bench_causal_drift.py``: the per-measurement law drifts on a straight
        road driven in closed loop (rear stiffness +92 % at 60 s: the driver's steering
        answers the camera noise, and the certified gain's innovations are not white, so the
        regressor correlates with them); the block law does not. The block law corrects the
        state with the Kalman gain of its predictor (a Riccati recursion), not the LMI-certified
        gain: with the certified gain in its place the same benchmark read +39 / +89 % (straight)
        and +3.4 / +37 % (lane changes) at 60 s, and the e1 error doubled (7.9 against 4.4 mm),
        because the certified gain's innovations are not white.
    block_s : float
        Block length of the ``"block"`` law [s].
    sensor_offsets : bool
        Learn constant offsets of the IMU's ``a_y`` and yaw rate (when the IMU is read).
    ay_offset_std, yaw_rate_offset_std : float
        Their prior std [m/s^2], [rad/s] (a 1 deg mounting tilt is 0.17 m/s^2; a MEMS gyro
        offset a few mrad/s).
    """

    initial_std: float = 0.5
    random_walk: float = 0.0
    max_std: float = 1.0
    settle_time_constants: float = 3.0
    prior_length: float = 1.0
    prior_symmetry: float = 0.8
    online_prior_length: float | None = None
    causal_update: str = "block"
    block_s: float = 2.0
    sensor_offsets: bool = True
    ay_offset_std: float = 0.2
    yaw_rate_offset_std: float = 0.005

    _positive: ClassVar[tuple[str, ...]] = ("initial_std", "max_std", "ay_offset_std", "yaw_rate_offset_std", "block_s")
    _non_negative: ClassVar[tuple[str, ...]] = ("random_walk", "settle_time_constants", "prior_length", "prior_symmetry")

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.causal_update not in ("block", "rls"):
            raise ParameterError(f"AdaptationParams.causal_update must be 'block' or 'rls', got {self.causal_update!r}")


@dataclass(frozen=True)
class HealthParams(_Params):
    """Health-flag settings.

    Parameters
    ----------
    window_s : float
        NIS window length [s] (at least ``min_updates`` updates).
    min_updates : int
        Smallest window [updates].
    nis_factor : float
        The window's NIS sum may exceed the chi-square bound (probability 1e-4 under a
        consistent model) by this factor before the flag trips: the model of the noise is
        estimated, not known, so a consistent estimator must not trip on small errors in it.
    gap_frames : float
        The flag trips when no measurement arrived for this many sample periods ...
    min_gap_s : float
        ... and at least this long [s].
    rollback_s : float
        On a trip the weights return to a checkpoint at least this old [s].
    """

    window_s: float = 2.0
    min_updates: int = 10
    nis_factor: float = 3.0
    gap_frames: float = 10.0
    min_gap_s: float = 0.5
    rollback_s: float = 2.0

    _positive: ClassVar[tuple[str, ...]] = ("window_s", "min_updates", "nis_factor", "gap_frames", "min_gap_s", "rollback_s")
