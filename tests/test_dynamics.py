import numpy as np
import pytest

from tire_learning_env.dynamics import BicyclePlant, error_state_derivative, error_state_matrices, slip_angles
from tire_learning_env.params import VehicleParams
from tire_learning_env.simulation import simulate
from tire_learning_env.tires import axle_tires


def spec_matrices(v: VehicleParams):
    """SPEC §1 written out independently."""
    m, Iz, lf, lr, vx, Cf, Cr = v.m, v.Iz, v.lf, v.lr, v.vx, v.Cf, v.Cr
    A = np.array([
        [0, 1, 0, 0],
        [0, -(2*Cf + 2*Cr)/(m*vx), (2*Cf + 2*Cr)/m, (-2*Cf*lf + 2*Cr*lr)/(m*vx)],
        [0, 0, 0, 1],
        [0, (-2*Cf*lf + 2*Cr*lr)/(Iz*vx), (2*Cf*lf - 2*Cr*lr)/Iz, -(2*Cf*lf**2 + 2*Cr*lr**2)/(Iz*vx)],
    ])
    B1 = np.array([0, 2*Cf/m, 0, 2*Cf*lf/Iz])
    B2 = np.array([0, (-2*Cf*lf + 2*Cr*lr)/(m*vx) - vx, 0, -(2*Cf*lf**2 + 2*Cr*lr**2)/(Iz*vx)])
    B3 = np.array([0, 0, 0, -1.0])
    F = np.array([[0, 0], [1/m, 1/m], [0, 0], [lf/Iz, -lr/Iz]])
    C = np.array([[1, 0, 0, 0], [0, 0, 1, 0.0]])
    return A, B1, B2, B3, F, C


@pytest.mark.parametrize("vehicle", [VehicleParams(), VehicleParams(m=982, Iz=1605, lf=1.33, lr=1.07, Cf=35000, Cr=60000, vx=45)])
def test_error_state_matrices_equal_spec(vehicle):
    for got, want in zip(error_state_matrices(vehicle), spec_matrices(vehicle)):
        np.testing.assert_allclose(got, want, rtol=1e-14, atol=0)


def test_finite_difference_linearisation_equals_matrices():
    v = VehicleParams()
    front, rear = axle_tires(v, "linear")
    A, B1, B2, B3, F, C = error_state_matrices(v)

    def f(x, delta, pdd, pddd):
        af, ar = slip_angles(x, delta, pdd, v.vx, v.lf, v.lr)
        return error_state_derivative(x, pdd, pddd, front.lateral_force(af), rear.lateral_force(ar), v)

    x0 = np.array([0.1, -0.2, 0.01, 0.02])
    u0 = (0.01, 0.05, 0.001)
    h = 1e-6
    J = np.column_stack([(f(x0 + h * e, *u0) - f(x0 - h * e, *u0)) / (2 * h) for e in np.eye(4)])
    np.testing.assert_allclose(J, A, rtol=1e-6, atol=1e-6)
    for k, B in enumerate((B1, B2, B3)):
        du = np.zeros(3)
        du[k] = h
        col = (f(x0, *(np.add(u0, du))) - f(x0, *(np.subtract(u0, du)))) / (2 * h)
        np.testing.assert_allclose(col, B, rtol=1e-6, atol=1e-6)
    # and the whole derivative is affine: A x + B u exactly
    np.testing.assert_allclose(f(x0, *u0), A @ x0 + B1 * u0[0] + B2 * u0[1] + B3 * u0[2], rtol=1e-12, atol=1e-12)


def test_plant_rk4_step_matches_matrix_exponential():
    from scipy.linalg import expm

    v = VehicleParams()
    plant = BicyclePlant(v, *axle_tires(v, "linear"))
    A, B1, *_ = error_state_matrices(v)
    x0 = np.array([0.2, 0.1, 0.01, -0.02])
    plant.reset(x0)
    dt, delta = 1e-3, 0.01
    for _ in range(1000):
        plant.step(delta, dt, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    M = expm(np.block([[A, B1[:, None]], [np.zeros((1, 5))]]) * 1.0)
    expected = M[:4, :4] @ x0 + M[:4, 4] * delta
    np.testing.assert_allclose(plant.xi, expected, rtol=1e-8, atol=1e-10)


def test_steady_state_cornering_matches_textbook_steering():
    """Linear tire on a circle: delta_ss = L/R + K_us a_y (Rajamani eq. 3.15)."""
    v = VehicleParams()
    radius = 300.0
    log = simulate("study1", 60.0, vehicle=v, tire_model="linear")
    t = log.sensors["t"]
    on_circle = (t > 25.0) & (t < 34.0)  # well inside the R = 300 m arc
    delta = log.sensors["delta"][on_circle].mean()
    ay = v.vx**2 / radius
    assert delta == pytest.approx(v.wheelbase / radius + v.understeer_gradient * ay, rel=2e-3)
    assert np.abs(log.truth["true_state"][on_circle, 0]).max() < 2e-3
