"""Settings of the discrepancy workflow (one frozen, validated dataclass)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from ..params import ParameterError, _Params

__all__ = ["DiscrepancyConfig"]


@dataclass(frozen=True)
class DiscrepancyConfig(_Params):
    """Everything that defines a discrepancy analysis. Unknown keys raise :class:`ParameterError`.

    Parameters
    ----------
    window : float
        Length of a multiple-shooting window [s]: the model runs open loop for at most this
        long (plus ``preroll``) from an initial state fitted to the window's data.
    preroll : float
        Simulated time before each window's first measurement [s]; bounds the camera
        latency that can be represented (the latency candidate's upper bound).
    step : float
        Largest RK4 sub-step [s].
    gn_iterations : int
        Gauss-Newton steps of each window's initial state per evaluation inside a fit
        (comparisons between models always use converged states).
    alpha : float
        Family-wise significance level of one selection round (Bonferroni over the
        candidates): a candidate is accepted only if its likelihood-ratio p-value is below
        ``alpha / n_candidates`` *and* it lowers the BIC.
    max_effects : int
        At most this many effects are accepted (greedy forward selection).
    whiteness_alpha : float
        Level of the residual whiteness and excess-energy tests (Monte Carlo null).
    whiteness_lags : float
        Autocorrelation lags of the portmanteau statistic, as a time span [s].
    mc_draws : int
        Monte Carlo draws of the null distributions.
    min_speed : float
        Windows with a speed below this are skipped (the model is singular at rest) [m/s].
    speed_variation : float
        Speed-dependent candidates are tried only if ``(vx_p95 - vx_p5) / median(vx)``
        reaches this [-].
    e1_floor, e2_floor, yaw_rate_floor, ay_floor : float
        Smallest noise standard deviation assumed per channel [m], [rad], [rad/s],
        [m/s^2] (a noise-free channel is weighted as if it had this noise).
    use_imu : bool
        Use ``yaw_rate`` / ``ay`` when the log has them.
    steering : {"auto", "curvature", "linear", "hold"}
        How the steering evolves between logged rows (:func:`.data.steering_slope`);
        ``auto`` (default) takes whichever of ``curvature`` and ``linear`` leaves the smaller
        nominal residual (a sampled controller logged at its own rate, or a continuous
        steering / a log sparser than the controller). IMU-only logs have no curvature and
        use ``linear`` instead of ``curvature`` / ``auto``.
    input_noise : bool
        Estimate the steering error between logged rows from the log and account for it
        (:mod:`.noise`, errors-in-variables); off: the residual is assumed to be measurement
        noise only.
    ambiguity_bic : float
        Two candidates whose BIC differ by less than this (both passing the acceptance test)
        explain the log about equally well: the verdict is ``ambiguous`` (Kass and Raftery:
        a BIC difference above 10 is "very strong" evidence).
    verify_separation : bool
        With an ``ambiguous`` verdict, simulate the proposed separating manoeuvre with each
        candidate as the truth and check that it separates them (:mod:`.separation`).
    seed : int
        Seed of the Monte Carlo null distributions.
    correlation_correction : {"auto", "on", "off"}
        Divide every likelihood-ratio statistic by the residual's variance inflation from
        its correlation in time (:func:`.criteria.long_run_variance`). ``auto``: on for
        IMU-only logs (a real car's residual is never white at 100 Hz), off for camera logs.
    """

    window: float = 3.0  # [s]
    preroll: float = 0.3  # [s]
    step: float = 0.01  # [s]
    gn_iterations: int = 2
    alpha: float = 0.01
    max_effects: int = 3
    whiteness_alpha: float = 0.01
    whiteness_lags: float = 0.5  # [s]
    mc_draws: int = 100
    min_speed: float = 3.0  # [m/s]
    speed_variation: float = 0.15
    e1_floor: float = 1e-4  # [m]
    e2_floor: float = 1e-5  # [rad]
    yaw_rate_floor: float = 1e-3  # [rad/s]
    ay_floor: float = 0.02  # [m/s^2]
    use_imu: bool = True
    steering: str = "auto"
    input_noise: bool = True
    ambiguity_bic: float = 10.0
    verify_separation: bool = True
    seed: int = 0
    correlation_correction: str = "auto"

    _positive: ClassVar[tuple[str, ...]] = (
        "window", "step", "alpha", "whiteness_alpha", "whiteness_lags", "mc_draws", "min_speed",
        "e1_floor", "e2_floor", "yaw_rate_floor", "ay_floor", "ambiguity_bic",
    )  # fmt: skip
    _non_negative: ClassVar[tuple[str, ...]] = ("preroll", "gn_iterations", "max_effects", "speed_variation")

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("alpha", "whiteness_alpha"):
            if not 0.0 < getattr(self, name) < 1.0:
                raise ParameterError(f"DiscrepancyConfig.{name} must be in (0, 1), got {getattr(self, name)!r}")
        for name in ("gn_iterations", "max_effects", "mc_draws", "seed"):
            if not isinstance(getattr(self, name), int) or isinstance(getattr(self, name), bool):
                raise ParameterError(f"DiscrepancyConfig.{name} must be an integer, got {getattr(self, name)!r}")
        if self.steering not in ("auto", "curvature", "linear", "hold"):
            raise ParameterError(
                f"DiscrepancyConfig.steering must be 'auto', 'curvature', 'linear' or 'hold', got {self.steering!r}"
            )
        if self.correlation_correction not in ("auto", "on", "off"):
            raise ParameterError(
                "DiscrepancyConfig.correlation_correction must be 'auto', 'on' or 'off', "
                f"got {self.correlation_correction!r}"
            )
        if self.window < 4 * self.step or not math.isfinite(self.window):
            raise ParameterError(f"DiscrepancyConfig.window must be at least 4 steps, got {self.window!r}")

    @property
    def floors(self) -> tuple[float, float, float, float]:
        """Noise floors of the channels ``e1, e2, yaw_rate, ay``."""
        return self.e1_floor, self.e2_floor, self.yaw_rate_floor, self.ay_floor
