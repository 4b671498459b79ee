"""The contract every estimator keeps (issue 16): the neuro-adaptive observer with each
measurement model (camera, IMU, both), the joint UKF and the linear Kalman filter have the
same verbs with the same argument order, continue across calls, refuse ground truth and
return the one result type, :class:`~tire_learning_env.observer.EstimateTrace`."""

import inspect

import numpy as np
import pytest

from tire_learning_env import simulate
from tire_learning_env.baselines import JointUKF, LinearKalmanFilter, UKFResult
from tire_learning_env.observer import EstimateTrace, ObserverConfig, build_observer
from tire_learning_env.params import CameraParams, VehicleParams

V = VehicleParams()
DT = 0.01  # the rows' spacing (100 Hz)
CAMERA = CameraParams(rate=20.0)
#: the verbs' leading parameters, in order, on every estimator
SIGNATURES = {
    "reset": ["state", "weights"],
    "predict": ["dt", "delta", "vx", "kappa", "ax"],
    "update": ["z", "delta", "vx"],
    "run": ["sensors", "predict_last"],
}
ESTIMATORS = {
    "camera_observer": lambda: build_observer(V, CAMERA, ObserverConfig(), DT),
    "imu_observer": lambda: build_observer(V, None, ObserverConfig(sensors="imu"), DT, sensors="imu",
                                           noise_std=(0.01, 0.005, 0.5, 0.003), frame_period=DT),  # fmt: skip
    "fused_observer": lambda: build_observer(V, CAMERA, ObserverConfig(sensors="both"), DT, sensors="both", imu_period=DT),
    "joint_ukf": lambda: JointUKF.for_camera(V.replace(Cf=1.08 * V.Cf, Cr=0.94 * V.Cr), CAMERA, dt=DT),
    "linear_kf": lambda: LinearKalmanFilter(V, physics_dt=DT),
}


@pytest.fixture(scope="module")
def drive():
    """12 s of lane changes, rows at 100 Hz with a 20 Hz camera and the IMU on every row."""
    log = simulate("lane_changes", 12.0, camera=CAMERA, physics_rate=100.0, seed=2)
    rows = {k: log.sensors[k] for k in ("t", "delta", "vx", "ax", "kappa", "e1", "e2", "ay", "yaw_rate")}
    return rows, log.truth


@pytest.mark.parametrize("name", list(ESTIMATORS))
def test_every_estimator_has_the_same_verbs_and_returns_the_one_trace(drive, name):
    rows, truth = drive
    est = ESTIMATORS[name]()
    for verb, leading in SIGNATURES.items():
        params = list(inspect.signature(getattr(est, verb)).parameters)
        assert params[: len(leading)] == leading, f"{name}.{verb}{tuple(params)}"
    n = len(rows["t"])
    assert est.reset() is est
    full = est.run(rows)
    assert isinstance(full, EstimateTrace)
    for field in ("t", "state", "slip", "force", "force_nonlinear", "weights", "std", "health", "innovation", "nis", "vx", "kappa"):
        assert getattr(full, field).shape[0] == n, field
    assert full.state_names[:2] == ("vy", "yaw_rate") and full.state.shape[1] == len(full.state_names)
    assert full.std.shape == full.state.shape and full.innovation.shape == (n, 4) and full.health.dtype == np.int8
    # the sideslip every estimator reports follows the truth's on this gentle drive (after 2 s)
    xs = truth["true_state"]  # [e1, e1_dot, e2, e2_dot]: vy = e1_dot - vx e2
    true_beta = np.arctan2(xs[:, 1] - rows["vx"] * xs[:, 2], rows["vx"])
    assert np.sqrt(np.mean(np.degrees(full.beta[200:] - true_beta[200:]) ** 2)) < 0.3
    assert np.all(np.isfinite(full.state))

    # two calls continue where the first stopped: the same rows as one call
    k = n // 2 + 7
    est.reset()
    a = est.run({c: v[:k] for c, v in rows.items()})
    b = est.run({c: v[k:] for c, v in rows.items()})
    np.testing.assert_allclose(np.vstack([a.state, b.state]), full.state, rtol=1e-9, atol=1e-9)

    # the single-tick verbs give the run: correct at a row, then predict to the next with its inputs
    est.reset()
    states = []
    for i in range(60):
        z = [rows[c][i] for c in ("e1", "e2", "ay", "yaw_rate")]
        est.update(z, delta=rows["delta"][i], vx=rows["vx"][i])
        states.append(np.array(est.state))
        est.predict(rows["t"][i + 1] - rows["t"][i], delta=rows["delta"][i], vx=rows["vx"][i], kappa=rows["kappa"][i],
                    ax=rows["ax"][i])  # fmt: skip
    np.testing.assert_allclose(np.array(states), full.state[:60], rtol=1e-9, atol=1e-9)

    with pytest.raises(ValueError, match="ground truth"):
        est.reset().run({**rows, "true_beta": np.zeros(n)})


def test_the_ukf_trace_keeps_its_parameters_and_its_error_state(drive):
    rows, truth = drive
    res = ESTIMATORS["joint_ukf"]().run(rows)
    assert isinstance(res, UKFResult) and isinstance(res, EstimateTrace)
    n = len(rows["t"])
    assert res.params.shape == (n, 4) and res.filter_std.shape == (n, 8) and res.weights.shape == (n, 4)
    np.testing.assert_allclose(res.params[:, 0], V.Cf * 1.08 * np.exp(res.weights[:, 0]))
    # the state and the error state are the same estimate in two coordinates: vy = e1_dot - vx e2
    np.testing.assert_allclose(res.state[:, 0], res.xi[:, 1] - rows["vx"] * res.xi[:, 2], atol=1e-12)
    np.testing.assert_array_equal(res.state[:, 2], res.xi[:, 0])
    np.testing.assert_allclose(res.force_nonlinear, res.force - 2.0 * res.slip * [1.08 * V.Cf, 0.94 * V.Cr], atol=1e-9)
    frames = np.isfinite(rows["e1"])
    assert np.all(np.isfinite(res.nis[frames])) and np.all(np.isnan(res.nis[~frames]))
    assert np.all(np.isnan(res.innovation[:, 2:]))  # camera-only: no IMU innovations
    # the error-state std of vy takes the covariance of e1_dot and e2 (not their variances alone)
    assert res.std.shape == (n, 4) and np.all(res.std > 0)
