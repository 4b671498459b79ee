"""Where Study 2's cornering-stiffness error comes from (issue 4), printed as JSON.

Study 2's target is a stiffness error <= 0.5 % on both axles. This script splits the
measured error into what the plant's structure allows and what the estimator adds:

- ``observer``: Study 2 as ``tire-learning reproduce --study 2`` runs it (high-order
  plant, scored against the effective axle stiffness, docs/high_order.md §6).
- ``observer_no_relaxation``: the same with the plant's tire relaxation length set to 0.
- ``observer_low_order``: the same road, driver, camera, observer settings and
  stiffness ratios (+13.6 % / +16.5 %), but the truth is the low-order bicycle plant with
  Pacejka tires, i.e. the observer's own model class. What is left here is the
  estimator's own error on this manoeuvre.
- ``observer_yaw_inertia_x1.05``: Study 2 with the nominal yaw inertia 5 % high.
- ``observer_start_from_effective_x``: Study 2 started from the effective stiffness times
  0.9, 1.0, 1.05 instead of the paper's ratios.
- ``curve_error_n_at_deg`` (low-order run): learned minus true axle force [N] at
  0.1, 0.2, 0.4 deg of slip.
- ``e1_dot_gain``: slope of the estimated ``e1_dot`` regressed on the true one (1 = unbiased).
- ``oracle``: a bicycle-model estimator with *perfect* states. The axle forces the
  bicycle model needs to reproduce the true state trajectory
  (:func:`~tire_learning_env.metrics.bicycle_implied_axle_forces`) are fitted against the
  true slip with the observer's basis
  (:func:`~tire_learning_env.metrics.oracle_cornering_stiffness`), over the whole band
  (``full_band``) and after the same zero-phase low-pass on force and slip
  (``lowpass_<f>hz``: 2nd-order Butterworth). Ground truth is used here for scoring
  only; no estimator sees it. The oracle reads the stiffness as half the slope at zero
  slip of its unregularised fit; the estimator reads it from a polynomial over the whole
  linear range (:meth:`~tire_learning_env.observer.EstimationResult.cornering_stiffness`): on
  the high-order plant, whose implied forces are not a bicycle curve, the two figures are
  not directly comparable.

All errors are ``100 (estimate / reference - 1)`` [%], ``[front, rear]``.

Run: ``python benchmarks/bench_study2_error_budget.py``
"""

from __future__ import annotations

import time
from dataclasses import replace

from _bench_common import emit

import numpy as np  # noqa: E402
from scipy.signal import butter, filtfilt  # noqa: E402

from tire_learning_env.high_order import HighOrderConfig, MultiBodyPlant  # noqa: E402
from tire_learning_env.observer import estimate  # noqa: E402
from tire_learning_env.metrics import bicycle_implied_axle_forces, oracle_cornering_stiffness  # noqa: E402
from tire_learning_env.observer.basis import make_basis  # noqa: E402
from tire_learning_env.simulation import simulate  # noqa: E402
from tire_learning_env.dynamics import BicyclePlant  # noqa: E402
from tire_learning_env.studies import study_spec  # noqa: E402
from tire_learning_env.tires import axle_tires  # noqa: E402

PAPER_RATIOS = (102466.1678 / 90211.1436, 102466.1678 / 87945.9970)
LOWPASS_HZ = (2.0, 1.0)
START_SCALES = (0.9, 1.0, 1.05)
MISFIT_SLIP_DEG = (0.1, 0.2, 0.4)


def _errors(stiffness, reference) -> list[float]:
    return [round(100.0 * (float(stiffness[i]) / float(reference[i]) - 1.0), 3) for i in range(2)]


def _log(spec, plant):
    """Simulate ``spec`` on ``plant`` as ``run_study`` does."""
    return simulate(spec.road, spec.duration, vehicle=spec.true_vehicle, camera=spec.camera, seed=spec.seed, plant=plant)


def _observer(spec, log, reference, true_curve=None) -> dict:
    """Estimate as ``run_study`` does; stiffness error, the ``e1_dot`` gain and, given
    ``true_curve(alpha, axle)``, the learned minus the true axle force at small slips."""
    result = estimate(log.sensors, spec.nominal_vehicle, spec.camera, spec.config, physics_dt=log.dt)
    keep = result.trace.t >= result.trace.t[0] + 2.0
    true_rate = np.asarray(log.truth["true_state"])[keep, 1]
    gain = float(np.polyfit(true_rate, result.trace.xi[keep, 1], 1)[0])  # estimated e1_dot per true e1_dot
    out = {"error_pct": _errors(result.cornering_stiffness(), reference), "e1_dot_gain": round(gain, 4)}
    if true_curve is not None:
        slips = np.radians(np.array(MISFIT_SLIP_DEG))
        out["curve_error_n_at_deg"] = {
            f"{d:g}": [round(float(result.axle_force(np.array([a]), axle)[0] - true_curve(np.array([a]), axle)[0]), 2)
                       for axle in ("front", "rear")]
            for d, a in zip(MISFIT_SLIP_DEG, slips)
        }  # fmt: skip
    return out


def _oracle(spec, log, reference) -> dict:
    s, truth = log.sensors, log.truth
    t = np.asarray(s["t"], dtype=float)
    keep = t >= t[0] + 2.0
    forces = bicycle_implied_axle_forces(t, truth["true_state"], s["vx"], s["psi_dot_des"], s["psi_ddot_des"], spec.nominal_vehicle)
    slip = np.asarray(truth["true_slip"], dtype=float)
    basis = make_basis(spec.config.basis, spec.nominal_vehicle)
    nominal = (spec.nominal_vehicle.Cf, spec.nominal_vehicle.Cr)
    out = {"full_band": _errors(oracle_cornering_stiffness(slip[keep], forces[keep], basis, nominal), reference)}
    for fc in LOWPASS_HZ:
        b, a = butter(2, fc, fs=1.0 / log.dt)
        fitted = oracle_cornering_stiffness(
            filtfilt(b, a, slip, axis=0)[keep], filtfilt(b, a, forces, axis=0)[keep], basis, nominal
        )
        out[f"lowpass_{fc:g}hz"] = _errors(fitted, reference)
    return out


def main() -> None:
    t0 = time.perf_counter()
    spec = study_spec(2)

    def high(config: HighOrderConfig | None = None) -> MultiBodyPlant:
        return MultiBodyPlant(spec.road, config=config, vx=spec.true_vehicle.vx)

    effective = high().true_cornering_stiffness(reference="effective")
    truth = spec.true_vehicle  # tire-level stiffness: the low-order plant's own
    low_spec = replace(spec, nominal_vehicle=truth.replace(Cf=truth.Cf * PAPER_RATIOS[0], Cr=truth.Cr * PAPER_RATIOS[1]))

    def low() -> BicyclePlant:
        return BicyclePlant(truth, *axle_tires(truth))

    def with_nominal(**changes):
        return replace(spec, nominal_vehicle=spec.nominal_vehicle.replace(**changes))

    nominal = spec.nominal_vehicle
    low_plant = low()
    study2, low_order = _log(spec, high()), _log(low_spec, low_plant)  # each used by the observer and the oracle
    result = {
        "target_pct": 0.5,
        "reference": {"high_order": "effective axle stiffness", "low_order": "tire stiffness"},
        "effective_stiffness": [round(float(c), 1) for c in effective],
        "observer": _observer(spec, study2, effective),
        "observer_no_relaxation": _observer(spec, _log(spec, high(HighOrderConfig(relaxation_length=0.0))), effective),
        "observer_low_order": _observer(low_spec, low_order, (truth.Cf, truth.Cr), low_plant.true_axle_curve),
        "observer_yaw_inertia_x1.05": _observer(with_nominal(Iz=1.05 * nominal.Iz), study2, effective),
        "observer_start_from_effective_x": {
            f"{k:g}": _observer(with_nominal(Cf=k * effective[0], Cr=k * effective[1]), study2, effective)["error_pct"]
            for k in START_SCALES
        },
        "oracle": _oracle(spec, study2, effective),
        "oracle_low_order": _oracle(low_spec, low_order, (truth.Cf, truth.Cr)),
    }
    result["wall_s"] = round(time.perf_counter() - t0, 1)
    emit(result)


if __name__ == "__main__":
    main()
