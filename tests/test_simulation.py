import numpy as np
import pytest

from tire_learning_env.dynamics import BicyclePlant, PlantEffects
from tire_learning_env.params import CameraParams, DriverParams, VehicleParams
from tire_learning_env.roads import make_road
from tire_learning_env.simulation import Simulator, simulate
from tire_learning_env.tires import CallableTire, PacejkaTire, axle_tires
from tire_learning_env.wrappers.excitation import ExcitationConfig


@pytest.mark.parametrize(
    "camera, effects",
    [
        (CameraParams(), PlantEffects()),
        (
            CameraParams(rate=30.0, latency=0.07, noise="gaussian", e1_noise=0.02, e2_noise=0.01, dropout_probability=0.2, e2_bias=0.002),
            PlantEffects(relaxation_length=0.5, bank_angle=0.01, crosswind_force=300.0, crosswind_arm=0.3, load_transfer=1.0, steering_offset=0.002),
        ),
    ],
)
@pytest.mark.parametrize("guard", [False, True])
def test_compiled_and_python_loops_give_the_same_log(camera, effects, guard, python_only_plant):
    v = VehicleParams()
    logs = []
    for wrap in (lambda p: p, python_only_plant):
        plant = wrap(BicyclePlant(v, *axle_tires(v), effects))
        sim = Simulator(plant, make_road("lane_changes"), camera, DriverParams())
        if guard:  # tight enough to act in this drive
            sim.driver.set_ay_guard(1.5, 100.0, 160.0)
        sim.reset(np.random.default_rng(5))
        chunks = [sim.advance(50, steering_offset=0.003 * k) for k in range(40)]
        logs.append(chunks)
    for a, b in zip(*logs):
        for key in a.sensors:
            np.testing.assert_allclose(a.sensors[key], b.sensors[key], rtol=1e-12, atol=1e-14, equal_nan=True)
        for key in a.truth:
            np.testing.assert_allclose(a.truth[key], b.truth[key], rtol=1e-12, atol=1e-14)


def test_ay_guard_clamps_the_steering_at_every_tick():
    """A 0.05 rad steering-offset step reaches about 6.7 m/s^2 at once; with the guard the IMU a_y
    never exceeds its limit, and it is off by default."""
    v = VehicleParams()
    gain = 2 * v.Cf / v.m
    peaks = {}
    for guard in (False, True):
        sim = Simulator(BicyclePlant(v, *axle_tires(v)), make_road("straight"), CameraParams(), DriverParams())
        if guard:
            sim.driver.set_ay_guard(3.0, 0.8 * gain, 1.2 * gain)
        sim.reset(np.random.default_rng(0))
        logs = [sim.advance(50, steering_offset=0.05 if k < 20 else -0.05) for k in range(40)]
        peaks[guard] = max(float(np.max(np.abs(log.sensors["ay"]))) for log in logs)
    assert peaks[False] > 5.0
    # the guard acts on the last IMU reading, so a_y may move on by one tick of the lateral
    # dynamics (1 ms): ExcitationConfig.safety_tick_margin (0.05 m/s^2) is that room
    assert peaks[True] <= 3.0 + ExcitationConfig().safety_tick_margin
    with pytest.raises(ValueError, match="gain_low"):
        sim.driver.set_ay_guard(3.0, 2.0, 1.0)


def test_custom_tire_runs_through_the_compiled_loop():
    v = VehicleParams()
    pac = PacejkaTire.for_axle(v, __import__("tire_learning_env").TireParams(), "front")
    custom = CallableTire(pac.lateral_force)
    a = simulate("study1", 20.0, tires=(pac, axle_tires(v)[1]))
    b = simulate("study1", 20.0, tires=(custom, axle_tires(v)[1]))
    np.testing.assert_allclose(a.truth["true_state"], b.truth["true_state"], atol=1e-6)


def test_blow_up_raises_with_time_and_state():
    v = VehicleParams(vx=30.0)
    plant = BicyclePlant(v, *axle_tires(v, "linear"))
    sim = Simulator(plant, make_road("straight"), CameraParams(), DriverParams(max_steering=0.5))
    sim.reset(np.random.default_rng(0), xi0=[0.0, 1e308, 0.0, 1e308])
    with pytest.raises(FloatingPointError, match=r"t=0\.0000 s"):
        sim.advance(5)


def test_speed_profile_runs_keep_their_midpoint_lookup():
    """The base simulator's speed-profile runs look the RK4 midpoint curvature up at s + vx dt/2
    (``midpoint_ax_factor=0``), the compiled loop at the exact s + vx dt/2 + ax dt^2/8: the two
    differ by that term only, so the logs agree closely but not to the bit."""
    import math

    from tire_learning_env import _kernels as K
    from tire_learning_env.simulation import advance_ticks_python

    v = VehicleParams()
    profile = lambda t: (30.0 + 3.0 * math.sin(0.5 * t), 1.5 * math.cos(0.5 * t))  # noqa: E731
    logs = {}
    for factor in (0.0, 0.125):
        sim = Simulator(BicyclePlant(v, *axle_tires(v)), make_road("sine"), CameraParams(), DriverParams())
        sim.reset(np.random.default_rng(0))
        out = np.empty((3000, K.N_LOG))
        advance_ticks_python(3000, sim.dt, 0, sim.plant, 0.0, 30.0, 1.5, sim.table.lookup, sim.camera, sim.driver,
                             0.0, math.nan, 0.0, out, speed_profile=profile, midpoint_ax_factor=factor)  # fmt: skip
        logs[factor] = out
    assert not np.array_equal(logs[0.0], logs[0.125], equal_nan=True)
    np.testing.assert_allclose(logs[0.0], logs[0.125], rtol=1e-6, atol=1e-5)  # forces [N] of order 1e3
    a = simulate("sine", 3.0, speed_profile=profile)
    np.testing.assert_array_equal(a.truth["true_state"], logs[0.0][:, K.LOG_TRUE_E1 : K.LOG_TRUE_E2_DOT + 1])
