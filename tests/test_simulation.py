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


def test_camera_rate_latency_and_dropouts():
    camera = CameraParams(rate=20.0, latency=0.1, dropout_probability=0.3)
    log = simulate("study1", 10.0, camera=camera, seed=1)
    t, e1 = log.sensors["t"], log.sensors["e1"]
    arrived = ~np.isnan(e1)
    # 20 Hz frames, each delivered 0.1 s after it showed
    frame_times = np.round(np.arange(0.0, 10.0 - 0.1 - 1e-9, 0.05) + 0.1, 6)
    delivered = np.round(t[arrived], 6)
    assert set(delivered) <= set(frame_times)
    lost = 1 - len(delivered) / len(frame_times)
    assert 0.2 < lost < 0.4
    # a delivered frame equals the truth 0.1 s earlier (no noise configured)
    idx = np.flatnonzero(arrived)
    np.testing.assert_allclose(e1[idx], log.truth["true_state"][idx - 100, 0], atol=1e-12)


def test_uniform_noise_has_the_configured_width():
    log = simulate("straight", 20.0, camera=CameraParams.paper_noise(rate=100.0), seed=2)
    err = log.sensors["e1"] - log.truth["true_state"][:, 0]
    err = err[~np.isnan(err)]
    assert np.abs(err).max() <= 0.01
    assert np.std(err) == pytest.approx(0.01 / np.sqrt(3), rel=0.1)


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


def test_log_rows_have_one_named_index_per_column():
    """The loops write rows through ``LOG_*`` names (``record_tick``); each name is its column."""
    from tire_learning_env import _kernels as K

    assert [getattr(K, "LOG_" + name.upper()) for name in K.LOG_COLUMNS] == list(range(K.N_LOG))
    assert K.LOG_INDEX == {name: i for i, name in enumerate(K.LOG_COLUMNS)}
    values = dict(t=1.0, delta=2.0, vx=3.0, ax=4.0, kappa=5.0, psi_dot_des=6.0, psi_ddot_des=7.0, e1=8.0, e2=9.0,
                  yaw_rate=10.0, ay=11.0, true_e1=12.0, true_e1_dot=13.0, true_e2=14.0, true_e2_dot=15.0,
                  alpha_f=16.0, alpha_r=17.0, Fyf=18.0, Fyr=19.0, s=20.0)  # fmt: skip
    for delivered in (True, False):
        out = np.full((2, K.N_LOG), -1.0)
        K.record_true_state(out, 1, np.array([values[k] for k in ("true_e1", "true_e1_dot", "true_e2", "true_e2_dot")] + [0.0, 0.0]))
        K.record_tick(out, 1, *(values[k] for k in ("t", "delta", "vx", "ax", "kappa", "psi_dot_des", "psi_ddot_des")),
                      delivered, values["e1"], values["e2"],
                      *(values[k] for k in ("yaw_rate", "ay", "alpha_f", "alpha_r", "Fyf", "Fyr", "s")))  # fmt: skip
        row = dict(zip(K.LOG_COLUMNS, out[1]))
        assert np.all(out[0] == -1.0)
        if not delivered:  # no frame delivered: NaN camera columns
            assert np.isnan(row.pop("e1")) and np.isnan(row.pop("e2"))
        assert row == {k: values[k] for k in row}


def test_speed_profile_runs_keep_their_midpoint_lookup():
    """The base simulator's speed-profile runs look the RK4 midpoint curvature up at s + vx dt/2
    (``midpoint_ax_factor=0``), the compiled loop at the exact s + vx dt/2 + ax dt^2/8: the two
    differ by that term only, so the logs agree closely but not to the bit."""
    import math

    from tire_learning_env.simulation import advance_ticks_python

    v = VehicleParams()
    profile = lambda t: (30.0 + 3.0 * math.sin(0.5 * t), 1.5 * math.cos(0.5 * t))  # noqa: E731
    logs = {}
    for factor in (0.0, 0.125):
        sim = Simulator(BicyclePlant(v, *axle_tires(v)), make_road("sine"), CameraParams(), DriverParams())
        sim.reset(np.random.default_rng(0))
        out = np.empty((3000, 20))
        advance_ticks_python(3000, sim.dt, 0, sim.plant, 0.0, 30.0, 1.5, sim.table.lookup, sim.camera, sim.driver,
                             0.0, math.nan, 0.0, out, speed_profile=profile, midpoint_ax_factor=factor)  # fmt: skip
        logs[factor] = out
    assert not np.array_equal(logs[0.0], logs[0.125], equal_nan=True)
    np.testing.assert_allclose(logs[0.0], logs[0.125], rtol=1e-6, atol=1e-5)  # forces [N] of order 1e3
    a = simulate("sine", 3.0, speed_profile=profile)
    np.testing.assert_array_equal(a.truth["true_state"], logs[0.0][:, 11:15])
