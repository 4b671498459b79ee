"""Joint UKF peer baseline: convergence, API, sensor-only input, bad input."""

import numpy as np
import pytest

from tire_learning_env import CameraParams, VehicleParams, simulate
from tire_learning_env.baselines import JointUKF
from tire_learning_env.params import ParameterError

ASSUMED = 1.13  # the filter starts 13 % too stiff (Study 2's mismatch)


@pytest.fixture(scope="module")
def lane_changes():
    return simulate("lane_changes", 60.0)


def test_converges_on_the_low_order_plant(lane_changes):
    v = VehicleParams()
    ukf = JointUKF(v.replace(Cf=ASSUMED * v.Cf, Cr=ASSUMED * v.Cr))
    res = ukf.run(lane_changes.sensors)
    cf, cr = ukf.cornering_stiffness()
    # measured: +0.10 % / +0.10 % after 60 s (from +13 %)
    assert cf == pytest.approx(v.Cf, rel=0.01) and cr == pytest.approx(v.Cr, rel=0.01)
    assert ukf.peak_friction() == pytest.approx((1.0, 1.0), abs=0.05)  # measured 1.008, 1.007
    err = res.xi[5000:] - lane_changes.truth["true_state"][5000:]
    rms = np.sqrt(np.mean(err**2, axis=0))
    assert rms[0] < 1e-4 and rms[2] < 1e-4  # measured 3e-6 m, 2e-6 rad
    assert rms[1] < 1e-3 and rms[3] < 1e-3  # measured 1.3e-4 m/s, 5.7e-5 rad/s
    force_rms = np.sqrt(np.mean((res.force[5000:] - lane_changes.truth["true_force"][5000:]) ** 2, axis=0))
    assert np.all(force_rms < 20.0)  # measured 3.1 N, 2.2 N
    np.testing.assert_allclose(res.params[-1, :2], (cf, cr))
    assert res.xi.shape == (len(lane_changes), 4) and res.slip.shape == res.force.shape == (len(lane_changes), 2)


def test_converges_with_a_noisy_30hz_camera():
    cam = CameraParams.paper_noise(rate=30.0)
    log = simulate("lane_changes", 60.0, camera=cam, seed=1)
    v = VehicleParams()
    ukf = JointUKF.for_camera(v.replace(Cf=ASSUMED * v.Cf, Cr=ASSUMED * v.Cr), cam)
    ukf.run(log.sensors)
    cf, cr = ukf.cornering_stiffness()
    assert cf == pytest.approx(v.Cf, rel=0.03) and cr == pytest.approx(v.Cr, rel=0.03)  # measured +1.2 %, +0.8 %


def test_recovers_the_effective_stiffness_of_the_high_order_plant():
    from tire_learning_env.high_order import simulate_high_order

    log = simulate_high_order("lane_changes", 60.0)
    v = log.vehicle  # equivalent bicycle; Cf/Cr = tire-level stiffness at static load
    ukf = JointUKF(v.replace(Cf=ASSUMED * v.Cf, Cr=ASSUMED * v.Cr))
    ukf.run(log.sensors)
    cf, cr = ukf.cornering_stiffness()
    # effective (steady-state) stiffness of this plant: 72933 / 57658 N/rad per tire
    assert cf == pytest.approx(72933.0, rel=0.02) and cr == pytest.approx(57658.0, rel=0.02)  # measured -0.6 %, -1.3 %


def test_predict_update_reproduce_run_on_a_curved_road_and_uneven_rows():
    """The single-tick verbs (the observer's signatures) give :meth:`JointUKF.run`: the path's
    yaw rate is ``vx kappa`` and its rate ``ax kappa + vx kappa_rate`` with the backward
    difference of ``kappa``; rows of any spacing (a log's ``t``, not a fixed tick)."""
    log = simulate("sine", 20.0, camera=CameraParams(rate=20.0), physics_rate=100.0, seed=4)
    keep = np.sort(np.r_[0, np.random.default_rng(5).choice(np.arange(1, len(log)), 1400, replace=False)])
    rows = {k: log.sensors[k][keep] for k in ("t", "delta", "vx", "ax", "kappa", "e1", "e2")}
    assert np.ptp(np.diff(rows["t"])) > 0.01 and np.ptp(rows["kappa"]) > 0  # uneven rows, a curved path
    v = VehicleParams().replace(Cf=1.1e5, Cr=0.95e5)
    res = JointUKF(v).run(rows)
    ukf = JointUKF(v)
    t, kappa = rows["t"], rows["kappa"]
    xs = []
    for j in range(len(t)):
        ukf.update([rows["e1"][j], rows["e2"][j]], delta=rows["delta"][j], vx=rows["vx"][j])
        xs.append(ukf.x_.copy())
        if j + 1 < len(t):
            rate = (kappa[j] - kappa[j - 1]) / (t[j] - t[j - 1]) if j else 0.0
            ukf.predict(t[j + 1] - t[j], rows["delta"][j], rows["vx"][j], kappa[j], rows["ax"][j], kappa_rate=rate)
    np.testing.assert_allclose(np.array(xs)[:, :4], res.xi, rtol=1e-10, atol=1e-13)
    cf, cr = res.cornering_stiffness()
    assert abs(cf / log.vehicle.Cf - 1) < 0.01 and abs(cr / log.vehicle.Cr - 1) < 0.01  # measured -0.06 %, -0.11 % (from +7 %, -7 %)


def test_learned_curve_slope_is_twice_the_per_tire_stiffness():
    ukf = JointUKF(VehicleParams().replace(Cf=9e4, Cr=8e4))
    h = 1e-7
    for axle, c in zip(("front", "rear"), ukf.cornering_stiffness()):
        f = ukf.axle_force(np.array([-h, h]), axle)
        assert (f[1] - f[0]) / (2 * h) == pytest.approx(2 * c, rel=1e-6)
        big = ukf.axle_force(np.array([-1.0, 1.0]), axle)
        assert big[1] == -big[0] and big[1] < 1.01 * VehicleParams().static_axle_loads[0 if axle == "front" else 1]
    with pytest.raises(ParameterError, match="axle"):
        ukf.axle_force(0.01, "middle")


def test_reads_only_the_sensor_log(lane_changes):
    class LogWithoutTruth:
        sensors = {k: a[:500] for k, a in lane_changes.sensors.items()}

        @property
        def truth(self):
            raise AssertionError("the baseline must not read ground truth")

    res = JointUKF(VehicleParams()).run(LogWithoutTruth())
    assert res.xi.shape == (500, 4)
    sensors = dict(LogWithoutTruth.sensors)
    del sensors["e2"]
    with pytest.raises(ParameterError, match="e2"):
        JointUKF(VehicleParams()).run(sensors)


def test_nan_frames_are_skipped_and_bad_settings_are_named():
    ukf = JointUKF(VehicleParams())
    x0, p0 = ukf.x_.copy(), ukf.P_.copy()
    ukf.update([np.nan, np.nan])
    np.testing.assert_array_equal(ukf.x_, x0)
    np.testing.assert_array_equal(ukf.P_, p0)
    with pytest.raises(ParameterError, match="measurement_std"):
        JointUKF(VehicleParams(), measurement_std=(0.0, 1e-3))
    with pytest.raises(ParameterError, match="accel_noise"):
        JointUKF(VehicleParams(), accel_noise=(1e-3,))
    with pytest.raises(ParameterError, match="stiffness_std"):
        JointUKF(VehicleParams(), stiffness_std=-1.0)
    with pytest.raises(ParameterError, match="vx"):
        JointUKF(VehicleParams()).run({"delta": [0.0], "vx": [0.0], "psi_dot_des": [0.0], "psi_ddot_des": [0.0], "e1": [0.0], "e2": [0.0]})


def test_run_ukf_baseline_result_carries_the_learned_curve(lane_changes):
    from tire_learning_env.baselines import run_ukf_baseline

    v = VehicleParams()
    nominal = v.replace(Cf=ASSUMED * v.Cf, Cr=ASSUMED * v.Cr)
    res = run_ukf_baseline(lane_changes.sensors, nominal, CameraParams())
    ukf = JointUKF(nominal)
    ukf.run(lane_changes.sensors)
    assert res.cornering_stiffness() == pytest.approx(ukf.cornering_stiffness(), rel=1e-12)
    a = np.linspace(-0.02, 0.02, 9)
    for axle in ("front", "rear"):
        np.testing.assert_allclose(res.axle_force(a, axle), ukf.axle_force(a, axle), rtol=1e-12)
        # the first row still holds the prior: the nominal (13 % too stiff) curve near zero
        assert res.axle_force(1e-6, axle, k=0) == pytest.approx(2 * ASSUMED * v.Cf * 1e-6, rel=1e-3)
    times, curve_at = res.curve_history(step_s=10.0)
    assert len(times) == 6 and times[0] == 0.0
    assert curve_at(5)(0.01, "front") == pytest.approx(res.axle_force(0.01, "front", k=50000))
    assert res.runtime_s > 0


def test_the_filter_state_is_indexed_by_its_names():
    """The UKF's kernels index the state by ``X_*``: each is its entry of STATE_NAMES, the error state in
    StateIndex's order."""
    from tire_learning_env.baselines import ukf
    from tire_learning_env.dynamics import StateIndex

    for name in ukf.STATE_NAMES:
        assert ukf.STATE_NAMES[getattr(ukf, "X_" + name.upper())] == name
    assert [ukf.X_E1, ukf.X_E1_DOT, ukf.X_E2, ukf.X_E2_DOT] == list(StateIndex) and ukf.N_ERR == len(StateIndex)
    assert len(ukf.STATE_NAMES) == ukf.N_X
