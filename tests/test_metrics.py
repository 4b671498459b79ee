"""The perfect-state diagnostics of :mod:`tire_learning_env.metrics` on a plant that is the bicycle model."""

import numpy as np
import pytest

from tire_learning_env.dynamics import BicyclePlant
from tire_learning_env.metrics import bicycle_implied_axle_forces, oracle_cornering_stiffness
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
