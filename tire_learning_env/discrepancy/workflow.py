"""The discrepancy workflow: compare, locate, name, add and show.

:func:`analyze` takes a driving log (:class:`~tire_learning_env.io.DrivingLog`, only its
``sensors`` are read), a nominal vehicle and a tire choice, and returns a
:class:`DiscrepancyResult` whose :meth:`~DiscrepancyResult.to_json` is ``report.json``.

Verdict rules (``config`` = :class:`.config.DiscrepancyConfig`):

- ``found``: at least one candidate effect passed the selection criterion
  (:mod:`.selection`) *and* the residual of the model with the accepted effects is white
  (camera portmanteau test, p >= ``whiteness_alpha``);
- ``ambiguous``: as ``found``, but another candidate that also passed fits about equally
  well (BIC within ``ambiguity_bic``): the candidates are listed with their evidence, none is
  named, and the separating manoeuvre is proposed and checked by simulation
  (:mod:`.separation`);
- ``none``: no candidate passed and the nominal residual is white: the nominal model
  explains the data within the noise;
- ``unexplained``: a structured residual remains (not white) that the accepted effects,
  if any, do not remove. Effects accepted on the way are then listed as
  ``partial_effects``, never as the answer.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
from numpy.typing import NDArray

from ..io import DrivingLog
from ..params import CameraParams, ParameterError, TireParams, VehicleParams
from ..tires import CallableTire, LinearTire, TireModel, axle_tires
from ._model import CHANNELS
from .config import DiscrepancyConfig
from .data import ModelData, noise_std, prepare
from .diagnostics import (
    GapSummary,
    WhitenessTest,
    cross_correlation,
    gap,
    locate_windows,
    regimes,
    turn_and_braking,
    whiteness,
)
from .effects import IMU_CONFOUNDED, CandidateEffect, library_for
from .residuals import Evaluation, ResidualModel
from .selection import SelectionResult, acceptance_threshold, forward_selection
from .separation import propose, verify_separation

__all__ = ["TIRE_CHOICES", "VERDICT_RULES", "DiscrepancyResult", "analyze", "nominal_tires"]

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

TIRE_CHOICES = ("pacejka", "linear", "learned")

#: rows at most this far apart [s] (40 Hz and more) resolve the road-wheel angle of a car (the steering system's
#: bandwidth is a few Hz): ``steering="auto"`` uses ``curvature`` (a sampled controller logged at its rate) and no
#: steering error between rows is estimated. Sparser rows take the better of ``curvature`` and ``linear`` on the
#: nominal residual, and the steering error between rows is estimated from the log when the residual is
#: structured (:mod:`.noise`)
SPARSE_ROWS_DT = 0.025

#: effect pairs that e1/e2 alone cannot tell apart (the IMU can)
_EQUIVALENT_WITHOUT_IMU = {frozenset({"road_bank", "crosswind"})}


def nominal_tires(
    log: DrivingLog, vehicle: VehicleParams, tire: str, tire_params: TireParams | None = None
) -> tuple[TireModel, TireModel, dict]:
    """Front/rear axle tires of the nominal model and a description.

    ``learned`` runs the neuro-adaptive observer on the log (:func:`~tire_learning_env.observer.estimate`;
    for an IMU-only log with ``sensors="imu"`` and the IMU noise measured by
    :func:`~tire_learning_env.imu.imu_noise_std`) and uses the learned axle curves (refined
    pass). Only the curves are used: the observer's state estimates (e.g. its causal
    sideslip) never enter the comparison.
    """
    if tire == "learned" and log.kind == "imu":
        from ..imu import imu_noise_std
        from ..observer import ObserverConfig, estimate

        s = log.sensors
        rows = {k: np.asarray(s[k], dtype=float) for k in ("t", "delta", "vx", "ay", "yaw_rate")}
        noise, _ = imu_noise_std(rows["t"], rows["ay"], rows["yaw_rate"])
        result = estimate(rows, vehicle, config=ObserverConfig(sensors="imu", imu_noise=noise))
        cf, cr = result.cornering_stiffness()
        front = CallableTire(lambda a: result.axle_force(a, "front"), "learned front (IMU observer)")
        rear = CallableTire(lambda a: result.axle_force(a, "rear"), "learned rear (IMU observer)")
        h = math.radians(1.0)
        secant = {a: float((result.axle_force(h, a) - result.axle_force(-h, a)) / (2 * h)) for a in ("front", "rear")}
        return front, rear, {
            "kind": "learned",
            "learner": "neuro-adaptive observer on the IMU (tire_learning_env.observer.estimate, sensors='imu'), "
            "refined curves; only its axle curves are used, never its state estimates",
            "cornering_stiffness_per_tire": {"front": cf, "rear": cr},
            "secant_pm1deg_per_axle_N_per_rad": secant,
        }
    if tire == "linear":
        return LinearTire(2.0 * vehicle.Cf), LinearTire(2.0 * vehicle.Cr), {"kind": "linear"}
    if tire == "pacejka":
        tp = tire_params or TireParams()
        f, r = axle_tires(vehicle, "pacejka", tp)
        return f, r, {"kind": "pacejka", "mu": tp.mu, "shape": tp.shape, "curvature": tp.curvature}
    if tire == "learned":
        from ..observer import ObserverConfig, estimate

        s = log.sensors
        t = s["t"]
        kappa = np.nan_to_num(s["kappa"])
        pdd = s["vx"] * kappa
        rows = {
            "t": t, "delta": s["delta"], "vx": s["vx"], "psi_dot_des": pdd,
            "psi_ddot_des": np.gradient(pdd, t), "e1": s["e1"], "e2": s["e2"],
        }  # fmt: skip
        frames = np.flatnonzero(np.isfinite(s["e1"]) & np.isfinite(s["e2"]))
        rate = 1.0 / float(np.median(np.diff(t[frames])))
        # gains designed for the camera noise estimated from the log itself
        n1, n2 = noise_std(s["e1"][frames]), noise_std(s["e2"][frames])
        camera = CameraParams(rate=rate)
        if n1 > 0 and n2 > 0:
            camera = CameraParams(rate=rate, noise="gaussian", e1_noise=n1, e2_noise=n2)
        result = estimate(rows, vehicle, camera, ObserverConfig(), physics_dt=float(np.median(np.diff(t))))
        cf, cr = result.cornering_stiffness()
        front = CallableTire(lambda a: result.axle_force(a, "front"), "learned front")
        rear = CallableTire(lambda a: result.axle_force(a, "rear"), "learned rear")
        return front, rear, {"kind": "learned", "cornering_stiffness_per_tire": {"front": cf, "rear": cr}}
    raise ParameterError(f"tire must be one of {TIRE_CHOICES}, got {tire!r}")


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
                "steering_between_rows": self.steering_mode if d.kind == "camera" else _imu_steering(cfg),
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


def _imu_steering(cfg: DiscrepancyConfig) -> str:
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


def _effect_entry(
    effect: CandidateEffect, values: NDArray, stderr: NDArray, evidence: dict, channels: tuple[str, ...],
    kind: str = "camera",
) -> dict:  # fmt: skip
    entry = {
        "name": effect.name,
        "parameters": effect.as_dict(values),
        "units": effect.units_dict(),
        "standard_errors": effect.as_dict(stderr),
        "description": effect.description,
        "evidence": evidence,
    }
    if kind == "imu":
        theory = {next(iter(pair - {effect.name})): why for pair, why in IMU_CONFOUNDED.items() if effect.name in pair}
        corr = evidence.get("signature_correlation", {})
        lr = float(evidence.get("likelihood_ratio", 0.0))
        limit = float(evidence.get("acceptance_threshold", 0.0))
        # the part of the effect's likelihood ratio that another candidate cannot reproduce, to first
        # order: LR (1 - rho^2); below the acceptance threshold the log cannot tell the two apart
        separation = {n: lr * (1.0 - c * c) for n, c in corr.items()}
        close = sorted((n for n in corr if separation[n] < limit), key=lambda n: -corr[n])
        if theory:
            entry["evidence"]["confounded_in_theory_with"] = theory
        if corr:
            entry["evidence"]["separation_from"] = {
                n: separation[n] for n in sorted(corr, key=lambda n: separation[n])[:5]
            }
        if close:
            entry["evidence"]["indistinguishable_from"] = close[0] if len(close) == 1 else close
            entry["evidence"]["note"] = (
                f"on this log the signature of {effect.name} correlates at "
                + ", ".join(f"{corr[n]:.3f} with {n}" for n in close)
                + f": the part of its likelihood ratio the other cannot reproduce, LR (1 - rho^2), is below the "
                f"acceptance threshold {limit:.3g}; the data cannot tell them apart, the name is the better fit, "
                "not a proof"
            )
    if "yaw_rate" not in channels and "ay" not in channels:
        for pair in _EQUIVALENT_WITHOUT_IMU:
            if effect.name in pair:
                other = next(iter(pair - {effect.name}))
                entry["evidence"]["indistinguishable_from"] = other
                entry["evidence"]["note"] = (
                    f"without IMU channels {effect.name} and {other} act identically on e1/e2 (a constant lateral "
                    "force); the accelerometer would tell them apart"
                )
    return entry


def analyze(
    log: DrivingLog,
    vehicle: VehicleParams | None = None,
    tire: str = "pacejka",
    config: DiscrepancyConfig | None = None,
    progress: bool | None = None,
    tire_params: TireParams | None = None,
    candidates: Sequence[str] | None = None,
) -> DiscrepancyResult:
    """Run the whole workflow on a camera log.

    Parameters
    ----------
    log : DrivingLog
        Driving log (only ``log.sensors`` is read).
    vehicle : VehicleParams, optional
        Nominal vehicle (default: the paper's sedan).
    tire : {"pacejka", "linear", "learned"}
        Nominal tire model.
    config : DiscrepancyConfig, optional
    progress : bool, optional
        Show a tqdm progress bar (default: when attached to a terminal).
    tire_params : TireParams, optional
        Magic Formula shape of the nominal Pacejka tire.
    candidates : sequence of str, optional
        Names of the library effects to try (default: the whole library of the log's kind).

    Returns
    -------
    DiscrepancyResult
    """
    from tqdm import tqdm

    t_start = time.perf_counter()
    config = config or DiscrepancyConfig()
    vehicle = vehicle or VehicleParams()
    if tire not in TIRE_CHOICES:
        raise ParameterError(f"tire must be one of {TIRE_CHOICES}, got {tire!r}")
    notes: list[str] = []
    if log.kind == "imu":
        from ..imu import clean_imu_log

        # checks (units, signs, uniform sampling) and causal cleaning of steering / yaw-rate spikes, reported
        log, cleaning = clean_imu_log(log, vehicle)
        notes += [f"IMU log cleaning: {n}" for n in cleaning.notes()]
    data = prepare(log, config)
    library = library_for(data.kind)
    if candidates is not None:
        unknown = sorted(set(candidates) - {c.name for c in library})
        if unknown:
            raise ParameterError(f"unknown candidate effect(s) {unknown}; the library has {[c.name for c in library]}")
        library = tuple(c for c in library if c.name in set(candidates))
    candidates = [c for c in library if not c.needs_speed_variation or data.speed_variation >= config.speed_variation]
    skipped = [c.name for c in library if c not in candidates]
    if skipped:
        notes.append(
            f"{skipped} not tried: the speed varies by only {100 * data.speed_variation:.1f} % "
            f"(needs {100 * config.speed_variation:.0f} %)"
        )
    disable = None if progress is None else not progress  # None: only on a terminal
    bar = tqdm(total=len(candidates) + 4, desc="discrepancy", unit="step", disable=disable)
    try:
        bar.set_postfix_str("nominal tire")
        front, rear, tire_info = nominal_tires(log, vehicle, tire, tire_params)
        model = ResidualModel(data, vehicle, front, rear, config)
        steering_mode, input_noise = _prepare_model(model, config, notes)
        bar.update(1)

        def tick(name: str) -> None:
            # the number of rounds is not known in advance: grow the total as they come
            if bar.n >= bar.total - 2:
                bar.total += len(candidates)
            bar.set_postfix_str(name)
            bar.update(1)

        bar.set_postfix_str("selection")
        imu = data.kind == "imu"
        correct = config.correlation_correction == "on" or (config.correlation_correction == "auto" and imu)
        sel = forward_selection(
            model, candidates, config.alpha, config.max_effects, progress=tick, correct_correlation=correct,
            signatures=imu, robust_states=imu,
        )  # fmt: skip
        if correct:
            notes.append(
                "likelihood-ratio statistics are divided by the residual's variance inflation from its correlation "
                "in time (Bartlett long-run variance over 1 s, floored at 1; lr_raw and inflation in each candidate)"
            )
        bar.set_postfix_str("whiteness")
        rng = np.random.default_rng(config.seed)
        lag_span = config.whiteness_lags
        w_before = whiteness(data, sel.nominal, lag_span, config.mc_draws, rng)
        w_final = whiteness(data, sel.final, lag_span, config.mc_draws, rng) if sel.accepted else w_before
        sparse = float(np.median(np.diff(data.t))) > SPARSE_ROWS_DT
        if config.input_noise and sparse and data.kind == "camera" and w_final.p_value < config.whiteness_alpha:
            # a structured residual: is it the steering the rows do not resolve? lambda from the nominal residual
            # (conservative: with an effect present it takes part of the effect for input noise, which costs
            # power, whereas lambda from a model with falsely accepted effects would be too small; see .noise)
            from .noise import estimate_input_noise

            input_noise = estimate_input_noise(model, sel.nominal)
            if input_noise.active:
                model.input_noise = input_noise
                notes.append(
                    f"the rows do not resolve the steering: a steering error between rows of lambda = "
                    f"{input_noise.scale:.3g} times the logged steering's roughness ({input_noise.sigma_u:.3g} rad) "
                    "is part of the noise (restricted likelihood on the nominal residual; the residual of the first "
                    "selection was not white); the selection was repeated with residuals whitened accordingly"
                )
                bar.set_postfix_str("selection (input noise)")
                # what the input-noise model leaves correlated in time is discounted as well (Newey-West)
                correct = config.correlation_correction != "off"
                sel = forward_selection(
                    model, candidates, config.alpha, config.max_effects, progress=tick, correct_correlation=correct,
                    signatures=imu, robust_states=imu,
                )  # fmt: skip
                w_before = whiteness(data, sel.nominal, lag_span, config.mc_draws, rng)
                w_final = whiteness(data, sel.final, lag_span, config.mc_draws, rng) if sel.accepted else w_before
        bar.update(1)
        bar.set_postfix_str("locate")
        traj_before = model.trajectories(sel.nominal)
        traj_after = model.trajectories(sel.final) if sel.accepted else traj_before
        gap_before = gap(data, sel.nominal)
        gap_final = gap(data, sel.final)
        n = data.n_measurements
        white_final = w_final.p_value >= config.whiteness_alpha
        entries = []
        for e, values, stderr in sel.accepted:
            ev = _evidence(sel, e, n, config)
            if e.name == "road_superelevation" and data.kind == "camera":
                # the cap is identified only where it binds: say whether it was reached on this log
                reached = float(values[0] * np.max(np.abs(data.kappa)))
                ev["largest_superelevation_on_this_log_rad"] = min(reached, float(values[1]))
                if reached <= 1.02 * values[1]:  # within 2 %: the cap touches at most the sharpest curve
                    ev["note"] = (
                        f"the cap is not reached on this log (rate x largest |kappa| = {reached:.3g} rad): the log "
                        "bounds the cap from below only; its value and standard error are not an estimate"
                    )
            entries.append(_effect_entry(e, values, stderr, ev, data.channels, data.kind))
        ambiguous: list[dict] = []
        manoeuvre = None
        if sel.accepted and white_final:
            ambiguous = _ambiguous_alternatives(sel, entries, n, config)
        if ambiguous:
            # the best-fitting candidate and the alternatives the log cannot tell apart from it
            verdict, partial = "ambiguous", []
            best = ambiguous[0]
            effects = [e for e in entries if e["name"] != best["name"]]
            gap_after, gap_partial, final = gap_final, None, sel.final
            manoeuvre = propose(best["name"], ambiguous[1]["name"])
            if config.verify_separation and data.kind == "camera":
                bar.set_postfix_str("separating manoeuvre")
                manoeuvre["check_by_simulation"] = verify_separation(
                    _Partial(data, vehicle, tire_info, config), best, ambiguous[1], manoeuvre["recipe"]
                )
            notes.append(
                f"{len(ambiguous)} candidates explain the log about equally well (BIC within {config.ambiguity_bic:g} "
                f"of the best): {[c['name'] for c in ambiguous]}; no single one is named"
            )
        elif sel.accepted and white_final:
            verdict, effects, partial = "found", entries, []
            gap_after, gap_partial, final = gap_final, None, sel.final
        elif sel.accepted:
            verdict, effects, partial = "unexplained", [], entries
            gap_after, gap_partial, final = gap_before, gap_final, sel.nominal
            notes.append(
                "effects were accepted on the way but the residual is still structured (whiteness p = "
                f"{w_final.p_value:.3g}); they explain part of the gap only and are listed as partial_effects"
            )
        elif w_before.p_value >= config.whiteness_alpha:
            verdict, effects, partial = "none", [], []
            gap_after, gap_partial, final = gap_before, None, sel.nominal
        else:
            verdict, effects, partial = "unexplained", [], []
            gap_after, gap_partial, final = gap_before, None, sel.nominal
            notes.append(
                f"the nominal residual is structured (whiteness p = {w_before.p_value:.3g}) but no candidate "
                "effect explains it significantly"
            )
        result = DiscrepancyResult(
            verdict=verdict,
            effects=effects,
            partial_effects=partial,
            gap_before=gap_before,
            gap_after=gap_after,
            gap_after_partial=gap_partial,
            whiteness_before=w_before,
            whiteness_after=w_final if verdict in ("found", "ambiguous") else w_before if verdict == "none" else w_final,
            selection=sel,
            data=data,
            model=model,
            nominal=sel.nominal,
            final=final,
            trajectories_before=traj_before,
            trajectories_after=traj_after if verdict in ("found", "ambiguous") else traj_before,
            windows_before=locate_windows(data, sel.nominal),
            windows_after=locate_windows(data, final),
            regimes_before=regimes(data, sel.nominal, traj_before),
            regimes_after=regimes(data, final, traj_after if verdict in ("found", "ambiguous") else traj_before),
            cross_correlation_before=cross_correlation(data, sel.nominal),
            cross_correlation_after=cross_correlation(data, final),
            tire=tire_info,
            vehicle=vehicle,
            config=config,
            source=log.source,
            runtime_s=0.0,
            notes=notes,
            steering_mode=steering_mode,
            input_noise=model.input_noise,
            candidates=ambiguous,
            separating_manoeuvre=manoeuvre,
        )
        if imu:
            result.turn_braking_before = turn_and_braking(data, sel.nominal)
            result.turn_braking_after = turn_and_braking(data, sel.final) if sel.accepted else None
        bar.update(1)
    finally:
        bar.close()
    result.runtime_s = time.perf_counter() - t_start
    return result


@dataclass
class _Partial:
    """What :func:`.separation.verify_separation` needs of a result that is still being built."""

    data: ModelData
    vehicle: VehicleParams
    tire: dict
    config: DiscrepancyConfig


def _ambiguous_alternatives(sel: SelectionResult, entries: list[dict], n: int, config: DiscrepancyConfig) -> list[dict]:
    """The accepted effect with candidates that fit its round about equally well, best first (else empty).

    An alternative qualifies when it was fitted in the round that accepted an effect, passed the
    acceptance test itself, is not accepted in the end, and its BIC is within ``config.ambiguity_bic``
    of the accepted effect's. Each entry: name, parameters, chi2, BIC difference to the best, evidence.
    """
    final = {e["name"] for e in entries}
    for st in sel.steps:
        if st.accepted is None or st.accepted not in final:
            continue
        best = st.tried[st.accepted]
        level = config.alpha / len(st.tried)
        bic_best = best["chi2"] + best["k"] * math.log(n)
        group = []
        for name, info in st.tried.items():
            if name == st.accepted or name in final or not info.get("fitted"):
                continue
            bic = info["chi2"] + info["k"] * math.log(n)
            if info["p_value"] < level and info["delta_bic"] < 0.0 and bic - bic_best < config.ambiguity_bic:
                group.append((bic - bic_best, name, info))
        if not group:
            continue
        entry = next(e for e in entries if e["name"] == st.accepted)
        out = [{
            "name": st.accepted, "parameters": entry["parameters"], "units": entry["units"],
            "standard_errors": entry["standard_errors"], "delta_bic_to_best": 0.0, "chi2": best["chi2"],
            "likelihood_ratio": best["lr"], "p_value": best["p_value"], "description": entry["description"],
        }]  # fmt: skip
        for dbic, name, info in sorted(group, key=lambda g: g[0]):
            eff = next(c for c in library_for(_sel_kind(sel)) if c.name == name)
            out.append({
                "name": name, "parameters": info["parameters"], "units": eff.units_dict(),
                "delta_bic_to_best": float(dbic), "chi2": info["chi2"], "likelihood_ratio": info["lr"],
                "p_value": info["p_value"], "description": eff.description,
            })  # fmt: skip
        return out
    return []


def _sel_kind(sel: SelectionResult) -> str:
    """Log kind of a selection (the IMU model state has 2 entries, the camera model 4)."""
    return "imu" if sel.nominal.x0.shape[1] == 2 else "camera"


def _prepare_model(model: ResidualModel, config: DiscrepancyConfig, notes: list[str]):
    """Steering between rows (``auto``: the better of ``curvature`` and ``linear`` on the nominal residual)
    and the errors-in-variables model of the steering the rows do not show (:mod:`.noise`)."""
    from .data import steering_slope
    from .noise import estimate_input_noise

    data = model.data
    if data.kind != "camera":
        return _imu_steering(config), None
    mode = config.steering
    nominal = model.converged()
    dt_row = float(np.median(np.diff(data.t)))
    if mode == "auto" and dt_row <= SPARSE_ROWS_DT:
        # rows this dense resolve a sampled controller; the two modes differ by half a row interval of
        # steering delay, which a lag effect (latency, relaxation) would otherwise absorb
        mode = "curvature"
    elif mode == "auto":
        curvature_slope = data.dslope
        data.dslope = steering_slope(data.t, data.delta, data.kappa, data.vx, "linear")
        linear = model.converged()
        if linear.chi2 < nominal.chi2:
            mode, nominal = "linear", linear
        else:
            mode, data.dslope = "curvature", curvature_slope
        notes.append(
            f"steering between rows: {mode} (rows every {1e3 * dt_row:.3g} ms: the smaller nominal residual of "
            "curvature and linear)"
        )
    return mode, None


def _evidence(sel: SelectionResult, effect: CandidateEffect, n: int, config: DiscrepancyConfig) -> dict:
    """Why ``effect`` was accepted: its round's statistics and the runner-up."""
    for st in sel.steps:
        if st.accepted == effect.name:
            info = st.tried[effect.name]
            k = effect.n_parameters
            fitted = {name: v for name, v in st.tried.items() if v.get("fitted") and name != effect.name}
            runner = min(fitted, key=lambda nm: fitted[nm]["chi2"]) if fitted else None
            out = {
                "round": st.round,
                "chi2_before": st.chi2_before,
                "chi2_with_effect": info["chi2"],
                "likelihood_ratio": info["lr"],
                "p_value": info["p_value"],
                "delta_bic": info["delta_bic"],
                "acceptance_threshold": acceptance_threshold(k, n, config.alpha / len(st.tried)),
                "runner_up": None,
            }
            if "inflation" in info:
                out["likelihood_ratio_raw"] = info["lr_raw"]
                out["inflation"] = info["inflation"]
            if "signature_correlation" in info:
                out["signature_correlation"] = info["signature_correlation"]
            if runner is not None:
                out["runner_up"] = {
                    "name": runner,
                    "chi2": fitted[runner]["chi2"],
                    "delta_bic_vs_accepted": (fitted[runner]["chi2"] + fitted[runner]["k"] * math.log(n))
                    - (info["chi2"] + k * math.log(n)),
                }
            return out
    return {}


def _vehicle_source() -> str:
    """Where the nominal vehicle came from: the CLI's ``--vehicle`` path or its built-in default
    (recorded by ``vehicle_from_args``), else a caller of the library."""
    from ..io import current_run_context

    info = current_run_context().info.get("vehicle")
    return str(info["source"]) if isinstance(info, dict) and "source" in info else "given by the caller (VehicleParams)"
