import numpy as np
import pytest

from tire_learning_env.params import TireParams, VehicleParams
from tire_learning_env.tires import LinearTire, PacejkaTire, axle_tires


@pytest.fixture(params=["front", "rear"])
def pacejka(request):
    return PacejkaTire.for_axle(VehicleParams(), TireParams(), request.param), request.param


def test_pacejka_is_odd(pacejka):
    tire, _ = pacejka
    a = np.linspace(-0.3, 0.3, 601)
    np.testing.assert_allclose(tire.lateral_force(-a), -tire.lateral_force(a), atol=1e-9)


def test_pacejka_slope_at_zero_is_axle_stiffness(pacejka):
    tire, axle = pacejka
    v = VehicleParams()
    expected = 2 * (v.Cf if axle == "front" else v.Cr)
    h = 1e-7
    slope = (tire.lateral_force(h) - tire.lateral_force(-h)) / (2 * h)
    assert slope == pytest.approx(expected, rel=1e-6)
    assert tire.cornering_stiffness == pytest.approx(expected, rel=1e-12)


def test_pacejka_peak_close_to_mu_fz(pacejka):
    tire, axle = pacejka
    v, tp = VehicleParams(), TireParams(mu=0.9)
    tire = PacejkaTire.for_axle(v, tp, axle)
    fz = v.static_axle_loads[0 if axle == "front" else 1]
    peak = tire.lateral_force(np.linspace(0, 0.5, 50001)).max()
    assert peak == pytest.approx(0.9 * fz, rel=1e-3)


def test_scalar_and_vectorised_paths_agree(pacejka):
    tire, _ = pacejka
    a = np.linspace(-0.2, 0.2, 41)
    np.testing.assert_allclose([tire.force(x) for x in a], tire.lateral_force(a), rtol=1e-12)


def test_linear_tire_and_factory():
    v = VehicleParams()
    front, rear = axle_tires(v, "linear")
    assert isinstance(front, LinearTire)
    assert front.lateral_force(0.01) == pytest.approx(2 * v.Cf * 0.01)
    assert rear.cornering_stiffness == 2 * v.Cr
