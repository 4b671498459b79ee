"""The metrics of :mod:`tire_learning_env.metrics`: short logs, and the perfect-state diagnostics on a plant
that is the bicycle model."""

import math

import numpy as np
import pytest

from tire_learning_env.dynamics import BicyclePlant
from tire_learning_env.metrics import (
    basis_regressors,
    bicycle_implied_axle_forces,
    compute_metrics,
    oracle_cornering_stiffness,
    stiffness_error_pct,
)
from tire_learning_env.observer.basis import make_basis
from tire_learning_env.params import CameraParams, VehicleParams
from tire_learning_env.simulation import simulate
from tire_learning_env.tires import axle_tires


@pytest.fixture(scope="module")
def lane_change_log():
    vehicle = VehicleParams()
    plant = BicyclePlant(vehicle, *axle_tires(vehicle))
    log = simulate("lane_changes", 20.0, vehicle=vehicle, camera=CameraParams(rate=1000.0), plant=plant)
    return vehicle, log


def test_implied_forces_equal_the_bicycle_plants_own_forces(lane_change_log):
    vehicle, log = lane_change_log
    s, truth = log.sensors, log.truth
    forces = bicycle_implied_axle_forces(
        s["t"], truth["true_state"], s["vx"], s["psi_dot_des"], s["psi_ddot_des"], vehicle
    )
    true_force = np.asarray(truth["true_force"])
    inner = slice(10, -10)  # one-sided differences at the ends
    rms_error = np.sqrt(np.mean((forces[inner] - true_force[inner]) ** 2, axis=0))
    rms_force = np.sqrt(np.mean(true_force[inner] ** 2, axis=0))
    assert np.all(rms_force > 300.0)  # the manoeuvre does load the tires
    assert np.all(rms_error < 2e-3 * rms_force)


def test_implied_forces_see_a_wrong_yaw_inertia(lane_change_log):
    vehicle, log = lane_change_log
    s, truth = log.sensors, log.truth
    args = (s["t"], truth["true_state"], s["vx"], s["psi_dot_des"], s["psi_ddot_des"])
    right = bicycle_implied_axle_forces(*args, vehicle)
    wrong = bicycle_implied_axle_forces(*args, vehicle.replace(Iz=1.2 * vehicle.Iz))
    true_force = np.asarray(truth["true_force"])
    assert np.sqrt(np.mean((wrong - true_force) ** 2)) > 10 * np.sqrt(np.mean((right - true_force) ** 2))


def test_oracle_stiffness_recovers_the_tire_with_a_wrong_nominal(lane_change_log):
    vehicle, log = lane_change_log
    s, truth = log.sensors, log.truth
    keep = np.asarray(s["t"]) >= 2.0
    forces = bicycle_implied_axle_forces(
        s["t"], truth["true_state"], s["vx"], s["psi_dot_des"], s["psi_ddot_des"], vehicle
    )
    nominal = (1.136 * vehicle.Cf, 1.165 * vehicle.Cr)
    basis = make_basis("two_sided", vehicle.replace(Cf=nominal[0], Cr=nominal[1]))
    cf, cr = oracle_cornering_stiffness(np.asarray(truth["true_slip"])[keep], forces[keep], basis, nominal)
    assert cf == pytest.approx(vehicle.Cf, rel=2e-3)
    assert cr == pytest.approx(vehicle.Cr, rel=2e-3)


def _score(lane_change_log, n_rows, stiffness_true=None):
    vehicle, log = lane_change_log
    s, truth = log.sensors, log.truth
    rows = slice(0, n_rows)
    truth = {k: np.asarray(truth[k])[rows] for k in ("true_state", "true_slip", "true_force")}

    def curve(alpha, axle):
        return 2.0 * (vehicle.Cf if axle == "front" else vehicle.Cr) * np.asarray(alpha)

    return compute_metrics(
        t=np.asarray(s["t"])[rows], xi_hat=truth["true_state"], slip_hat=truth["true_slip"],
        force_nonlinear_hat=np.zeros((len(truth["true_slip"]), 2)), truth=truth, curve=curve,
        true_curve=curve, stiffness_hat=(vehicle.Cf, vehicle.Cr),
        stiffness_true=stiffness_true or (vehicle.Cf, vehicle.Cr), nominal_stiffness=(vehicle.Cf, vehicle.Cr),
    )  # fmt: skip


def test_metrics_of_a_log_shorter_than_the_burn_in_score_its_second_half(lane_change_log):
    """A 0.5 s log (burn-in 2 s): scored after half the log, not a crash on empty arrays."""
    m = _score(lane_change_log, 501)
    assert m["burn_in_s"] == pytest.approx(0.25)
    assert m["state_rmse"]["e1"] == 0.0 and m["slip_rmse_deg"]["front"] == 0.0  # the truth fed back
    # the lane changes start after 5 s: no slip excited yet, so no curve score rather than a made-up one
    assert m["excited_slip_range_deg"]["front"] == [0.0, 0.0]
    assert all(math.isnan(v) for v in m["tire_curve_nrmse"].values())
    assert m["cornering_stiffness"]["front"]["error_pct"] == 0.0
    full = _score(lane_change_log, None)
    assert full["burn_in_s"] == 2.0
    with pytest.raises(ValueError, match="at least 2 rows"):
        _score(lane_change_log, 1)


def test_zero_true_stiffness_gives_a_nan_error_not_a_crash(lane_change_log):
    vehicle, _ = lane_change_log
    m = _score(lane_change_log, 3000, stiffness_true=(0.0, vehicle.Cr))
    assert math.isnan(m["cornering_stiffness"]["front"]["error_pct"])
    assert m["cornering_stiffness"]["rear"]["error_pct"] == 0.0
    assert stiffness_error_pct(1.1, 1.0) == pytest.approx(10.0)


def test_basis_regressors_reproduce_the_basis_force(lane_change_log):
    vehicle, log = lane_change_log
    basis = make_basis("two_sided", vehicle)
    w = np.random.default_rng(1).uniform(basis.weight_lower.ravel(), basis.weight_upper.ravel())
    slip = np.asarray(log.truth["true_slip"])
    for axle in (0, 1):
        X = basis_regressors(basis, slip[:, axle], axle)
        assert X.shape == (len(slip), basis.n_per_axle)
        np.testing.assert_allclose(X @ w.reshape(2, -1)[axle], basis.nonlinear_force(slip[:, axle], w, axle), rtol=1e-12)


def test_state_columns_are_those_of_the_state_index():
    """metrics.py sits below dynamics.py, so it names the error-state columns itself; they must agree."""
    from tire_learning_env import metrics
    from tire_learning_env.dynamics import StateIndex

    assert (metrics.STATE_E1_DOT, metrics.STATE_E2_DOT) == (StateIndex.E1_DOT, StateIndex.E2_DOT)
