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

import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..io import DrivingLog
from ..params import ParameterError, TireParams, VehicleParams
from .config import DiscrepancyConfig
from .data import ModelData, prepare
from .diagnostics import cross_correlation, gap, locate_windows, regimes, turn_and_braking, whiteness
from .effects import library_for
from .evidence import ambiguous_alternatives, effect_entry, evidence_of
from .nominal import TIRE_CHOICES, nominal_tires
from .residuals import ResidualModel
from .result import VERDICT_RULES, DiscrepancyResult, imu_steering
from .selection import forward_selection
from .separation import propose, verify_separation

__all__ = ["TIRE_CHOICES", "VERDICT_RULES", "DiscrepancyResult", "analyze", "nominal_tires"]

#: rows at most this far apart [s] (40 Hz and more) resolve the road-wheel angle of a car (the steering system's
#: bandwidth is a few Hz): ``steering="auto"`` uses ``curvature`` (a sampled controller logged at its rate) and no
#: steering error between rows is estimated. Sparser rows take the better of ``curvature`` and ``linear`` on the
#: nominal residual, and the steering error between rows is estimated from the log when the residual is
#: structured (:mod:`.noise`)
SPARSE_ROWS_DT = 0.025


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

        # checks (units, signs) and causal cleaning of steering / yaw-rate spikes, reported; a pause (a stretch
        # without rows) is no error: the windows below split at it as they do for a camera log
        log, cleaning = clean_imu_log(log, vehicle, allow_gaps=True)
        notes += [f"IMU log cleaning: {n}" for n in cleaning.notes()]
    data = prepare(log, config, camera_x=vehicle.camera_x)  # a camera ahead of the CG: its e1 is measured there
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
            ev = evidence_of(sel, e, n, config)
            if e.name == "road_superelevation" and data.kind == "camera":
                # the cap is identified only where it binds: say whether it was reached on this log
                reached = float(values[0] * np.max(np.abs(data.kappa)))
                ev["largest_superelevation_on_this_log_rad"] = min(reached, float(values[1]))
                if reached <= 1.02 * values[1]:  # within 2 %: the cap touches at most the sharpest curve
                    ev["note"] = (
                        f"the cap is not reached on this log (rate x largest |kappa| = {reached:.3g} rad): the log "
                        "bounds the cap from below only; its value and standard error are not an estimate"
                    )
            entries.append(effect_entry(e, values, stderr, ev, data.channels, data.kind))
        ambiguous: list[dict] = []
        manoeuvre = None
        if sel.accepted and white_final:
            ambiguous = ambiguous_alternatives(sel, entries, n, config)
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


def _prepare_model(model: ResidualModel, config: DiscrepancyConfig, notes: list[str]):
    """Steering between rows (``auto``: the better of ``curvature`` and ``linear`` on the nominal residual)
    and the errors-in-variables model of the steering the rows do not show (:mod:`.noise`)."""
    from .data import steering_slope
    from .noise import estimate_input_noise

    data = model.data
    if data.kind != "camera":
        return imu_steering(config), None
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
