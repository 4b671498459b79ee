"""The outcome of the discrepancy workflow: :class:`DiscrepancyResult` and its ``report.json`` document."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from numpy.typing import NDArray

from ..params import VehicleParams
from ._model import CHANNELS
from .config import DiscrepancyConfig
from .data import ModelData
from .diagnostics import GapSummary, WhitenessTest
from .effects import IMU_CONFOUNDED, library_for
from .residuals import Evaluation, ResidualModel
from .selection import SelectionResult

__all__ = ["VERDICT_RULES", "DiscrepancyResult", "imu_steering"]

#: the verdict rules in plain words (also written to report.json)
VERDICT_RULES = (
    "found: at least one candidate effect passed the selection criterion and the residual of the model with the "
    "accepted effects is white (camera portmanteau test, p >= whiteness_alpha). ambiguous: as found, but another "
    "candidate that also passed the criterion fits the log about equally well (BIC within ambiguity_bic of the "
    "accepted one): the candidates are listed with their parameters and evidence, none is named, and the manoeuvre "
    "that would separate them is proposed (and checked by simulating it). none: no candidate passed and the "
    "nominal residual is white: the nominal model explains the data within the noise. unexplained: a structured "
    "residual remains that the accepted effects, if any, do not remove; effects accepted on the way are then listed "
    "as partial_effects, never as the answer."
)


@dataclass
class DiscrepancyResult:
    """Everything the workflow found (see :meth:`to_json` for the ``report.json`` layout)."""

    verdict: str
    effects: list[dict]
    partial_effects: list[dict]
    gap_before: GapSummary
    gap_after: GapSummary
    gap_after_partial: GapSummary | None
    whiteness_before: WhitenessTest
    whiteness_after: WhitenessTest
    selection: SelectionResult
    data: ModelData
    model: ResidualModel
    nominal: Evaluation
    final: Evaluation
    trajectories_before: NDArray
    trajectories_after: NDArray
    windows_before: list[dict]
    windows_after: list[dict]
    regimes_before: dict
    regimes_after: dict
    cross_correlation_before: dict
    cross_correlation_after: dict
    tire: dict
    vehicle: VehicleParams
    config: DiscrepancyConfig
    source: str
    runtime_s: float
    notes: list[str] = field(default_factory=list)
    turn_braking_before: dict | None = None
    turn_braking_after: dict | None = None
    steering_mode: str = "curvature"
    input_noise: Any = None
    candidates: list[dict] = field(default_factory=list)
    separating_manoeuvre: dict | None = None

    @property
    def gap_ratio(self) -> float:
        """Noise-normalised band RMS over all channels, before / after."""
        return _ratio(self.gap_before.normalised_band_rms["all"], self.gap_after.normalised_band_rms["all"])

    def gap_ratios(self) -> dict:
        """Ratios per channel: band RMS, raw RMS, and the normalised camera (or IMU) / all figures."""
        b, a = self.gap_before, self.gap_after
        out = {
            "band": {k: _ratio(b.band_rms[k], a.band_rms[k]) for k in b.band_rms},
            "raw": {k: _ratio(b.rms[k], a.rms[k]) for k in b.rms},
            "normalised_band": {
                k: _ratio(b.normalised_band_rms[k], a.normalised_band_rms[k])
                for k in ("camera", "imu", "all")
                if k in b.normalised_band_rms
            },
        }
        return out

    def _method_text(self) -> str:
        cfg = self.config
        if self.data.kind == "imu":
            return (
                "IMU-only log: the body-frame bicycle model (states vy, r; inputs the logged delta, the time-varying "
                f"vx and a smoothed ax) is compared with the measured yaw rate and lateral acceleration. The log is cut "
                f"into windows of about {cfg.window:g} s; in each the model runs open loop from an initial state "
                "[vy, r] at the window's first row, fitted to that window's own measurements (descent Gauss-Newton, "
                "kept physical); the residual is measurement minus simulation, weighted by each channel's noise "
                "level. No state estimate of any observer is used as a measurement. The gap is the residual's RMS, "
                "raw and in the vehicle-dynamics band (0.5 s centred moving average within each window)."
            )
        return (
            f"The log is cut into windows of about {cfg.window:g} s; in each the model runs open loop on the "
            f"logged delta, vx and kappa from an initial state fitted to that window's own measurements "
            f"(simulation starts {cfg.preroll:g} s before the window's first measurement); the residual is "
            "measurement minus simulation, weighted by each channel's noise level. The gap is its RMS, raw "
            "and in the vehicle-dynamics band (0.5 s centred moving average within each window)."
        )

    def to_json(self) -> dict[str, Any]:
        """The ``report.json`` document."""
        cfg = self.config
        d = self.data
        sel = self.selection
        rounds = []
        for st in sel.steps:
            rounds.append(
                {
                    "round": st.round,
                    "chi2_before": st.chi2_before,
                    "accepted": st.accepted,
                    "dropped": st.dropped,
                    "candidates": st.tried,
                }
            )
        return {
            "verdict": self.verdict,
            "effects": self.effects,
            **({"candidates": self.candidates, "separating_manoeuvre": self.separating_manoeuvre}
               if self.verdict == "ambiguous" else {}),
            "gap_before": self.gap_before.to_dict(),
            "gap_after": self.gap_after.to_dict(),
            "gap_ratio": self.gap_ratio,
            "gap_ratios": self.gap_ratios(),
            "partial_effects": self.partial_effects,
            "gap_after_partial": None if self.gap_after_partial is None else self.gap_after_partial.to_dict(),
            "comparison": {
                "method": "multiple-shooting output error",
                "description": self._method_text(),
                "window_s": cfg.window,
                "preroll_s": cfg.preroll,
                "windows": d.n_windows,
                "measurements": d.n_measurements,
                "channels": list(d.channels),
                "noise_sigma": {c: float(d.sigma[i]) for i, c in enumerate(CHANNELS) if c in d.channels},
                "noise_sigma_estimated": {
                    c: float(d.sigma_estimated[i]) for i, c in enumerate(CHANNELS) if c in d.channels
                },
                "steering_between_rows": self.steering_mode if d.kind == "camera" else imu_steering(cfg),
                **({"input_noise": self.input_noise.to_dict()} if self.input_noise is not None else {}),
                **({"model": "body-frame bicycle model (states vy, r)", "primary_channels": ["yaw_rate", "ay"],
                    "preroll_s": 0.0,
                    "ax_input": "slope of vx (0.1 s centred moving average) + slow part (1 s) of logged ax - slope"}
                   if d.kind == "imu" else {}),
            },
            "nominal_model": {"vehicle": self.vehicle.to_dict(), "vehicle_source": _vehicle_source(),
                              "tire": self.tire},
            "log": {
                **({"kind": "imu"} if d.kind == "imu" else {}),
                "source": self.source,
                "rows": int(len(d.t)),
                "duration_s": float(d.t[-1] - d.t[0]),
                "speed_variation": d.speed_variation,
                "notes": d.notes,
            },
            "selection": {
                "criterion": (
                    "chi2 = sum(((y - y_model)/sigma)^2) with the noise levels fixed; accept the best candidate of a "
                    f"round if its likelihood-ratio p-value < {cfg.alpha:g} / (candidates in the round) and it lowers "
                    "BIC = chi2 + k ln(n); refit all accepted effects jointly; drop any that is no longer significant; "
                    f"stop when none passes or {cfg.max_effects} are in. Candidates whose score (predicted chi2 "
                    "reduction) is below a quarter of the acceptance threshold are reported but not fitted."
                ),
                "n_measurements": d.n_measurements,
                "rounds": rounds,
                "evaluations": sel.n_evaluations,
            },
            "whiteness": {"before": self.whiteness_before.to_dict(), "after": self.whiteness_after.to_dict(),
                          "alpha": cfg.whiteness_alpha},  # fmt: skip
            "locate": {
                "windows_before": self.windows_before,
                "windows_after": self.windows_after,
                "regimes_before": self.regimes_before,
                "regimes_after": self.regimes_after,
                "cross_correlation_before": self.cross_correlation_before,
                "cross_correlation_after": self.cross_correlation_after,
                **({"turn_and_braking_before": self.turn_braking_before,
                    "turn_and_braking_with_accepted_effects": self.turn_braking_after}
                   if self.turn_braking_before is not None else {}),
            },
            "library": [
                {"name": e.name, "parameters": e.units_dict(), "description": e.description}
                for e in library_for(d.kind)
            ],
            **({"identifiability": _identifiability_doc()} if d.kind == "imu" else {}),
            "verdict_rules": VERDICT_RULES if d.kind == "camera" else VERDICT_RULES.replace(
                "camera portmanteau test", "portmanteau test of the yaw_rate and ay residuals"
            ),
            "config": cfg.to_dict(),
            "runtime_s": self.runtime_s,
            "notes": self.notes,
        }


def imu_steering(cfg: DiscrepancyConfig) -> str:
    return "linear" if cfg.steering in ("curvature", "auto") else cfg.steering


def _identifiability_doc() -> list[dict]:
    return [{"effects": sorted(pair), "why": why} for pair, why in IMU_CONFOUNDED.items()] + [
        {
            "effects": ["lateral_load_transfer", "nominal tire curve"],
            "why": "the load-transfer loss is a function of a_y, which rises with slip: a tire curve learned from the "
            "same log as a function of slip (--tire learned) already contains most of it",
        },
        {
            "effects": ["crosswind"],
            "why": "not in the IMU library: on a closed track the car's heading turns through any wind every lap, so a "
            "constant body-frame side force is not a wind; a constant one would equal road_bank + ay_bias",
        },
    ]


def _ratio(before: float, after: float) -> float:
    if after <= 0:
        return math.inf if before > 0 else 1.0
    return float(before / after)


def _vehicle_source() -> str:
    """Where the nominal vehicle came from: the CLI's ``--vehicle`` path or its built-in default
    (recorded by ``vehicle_from_args``), else a caller of the library."""
    from ..io import current_run_context

    info = current_run_context().info.get("vehicle")
    return str(info["source"]) if isinstance(info, dict) and "source" in info else "given by the caller (VehicleParams)"
