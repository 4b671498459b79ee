import math

import numpy as np
import pytest
import scipy.linalg as sla

from tire_learning_env.dynamics import error_state_matrices, slip_jacobian
from tire_learning_env.observer import (
    InfeasibleLMIError,
    NeuroAdaptiveObserver,
    ObserverConfig,
    build_observer,
    estimate,
    least_squares_weights,
    make_basis,
    paper_basis,
    synthesize_gains,
    two_sided_basis,
)
from tire_learning_env.observer.gains import discretize
from tire_learning_env.observer.neuro_adaptive import ObserverTrace
from tire_learning_env.params import CameraParams, VehicleParams
from tire_learning_env.simulation import simulate

V = VehicleParams()


# ---- basis ---------------------------------------------------------------------------
def test_soft_clip_matches_eq30_and_its_bounds():
    b = paper_basis()
    a = np.linspace(-0.3, 0.3, 2001)
    lam = b.sharpness
    direct = a[:, None] + np.log((1 + np.exp(-lam * (a[:, None] - b.lower[0]))) / (1 + np.exp(lam * (a[:, None] - b.upper[0])))) / lam
    np.testing.assert_allclose(b.activations(a, 0), direct, atol=1e-12)
    lo, hi = b.value_bounds
    sig = b.activations(np.linspace(-5, 5, 20001), 0)
    assert np.all(sig >= lo[0] - 1e-12) and np.all(sig <= hi[0] + 1e-12)
    slo, shi = b.slope_bounds
    sl = b.slopes(np.linspace(-1, 1, 200001), 0)
    assert np.all(sl >= slo[0] - 1e-12) and np.all(sl <= shi[0] + 1e-9)
    # the constant member (b_lo == b_hi) is the bias
    np.testing.assert_allclose(sig[:, 3], 0.1)


def test_two_sided_basis_learns_both_signs_and_its_slope_box_is_tight():
    b = two_sided_basis(V)
    w = np.zeros(b.n_weights)
    w[: b.n_per_axle - 1] = -0.3  # all slip segments of the front axle
    a = np.linspace(-0.15, 0.15, 301)
    f = b.nonlinear_force(a, w, 0)
    np.testing.assert_allclose(f, -b.nonlinear_force(-a, w, 0), atol=1e-6)  # odd
    box = b.force_slope_bounds()
    slopes = []
    rng = np.random.default_rng(0)
    for _ in range(200):  # random admissible weights never leave the box
        ww = rng.uniform(b.weight_lower.ravel(), b.weight_upper.ravel())
        slopes.append(b.nonlinear_slope(np.linspace(-0.3, 0.3, 6001), ww, 0))
    slopes = np.concatenate(slopes)
    assert box[0, 0] <= slopes.min() and slopes.max() <= box[0, 1]
    assert box[0, 0] > -0.6 * 2 * V.Cf  # tight: about the -0.5 slope fraction, not N times it


# ---- gains ---------------------------------------------------------------------------
@pytest.mark.parametrize("basis, period, noise", [("two_sided", 1e-3, None), ("two_sided", 0.05, (0.0058, 0.01)), ("paper", 1e-3, None)])
def test_gain_certificate_checked_independently(basis, period, noise):
    b = make_basis(basis, V)
    g = synthesize_gains(V, b, period, noise_std=noise, cache=False)
    assert g.certified and g.max_vertex_eig <= g.tolerance
    # independent check: the closed-loop posterior error map is a strict contraction in
    # the P-norm at every vertex of the slope box, with the reported rate
    A, *_, C = error_state_matrices(V)
    d = discretize(V, period)
    H = slip_jacobian(V)
    S = np.diag([0.05, 0.05, 0.005, 0.02])
    P = g.P
    for dv in g.vertices:
        Av = d.Ad + d.Fd @ np.diag(dv) @ H
        Acl = np.linalg.inv(S) @ (np.eye(4) - g.L @ C) @ Av @ S
        rho2 = sla.eigh(Acl.T @ P @ Acl, P, eigvals_only=True).max()
        assert math.sqrt(rho2) <= math.exp(-g.decay_rate * period) * (1 + 1e-9)
    assert g.decay_rate >= 1.0  # the requested decay rate


def test_infeasible_request_raises_naming_the_failure():
    b = paper_basis()
    with pytest.raises(InfeasibleLMIError, match=r"vertex|LMI_v >= -"):
        synthesize_gains(V, b, 0.05, decay_rate=200.0, noise_std=(0.0058, 0.01), cache=False)


def test_cache_hit_is_recertified_not_resolved(tmp_path):
    b = two_sided_basis(V)
    first = synthesize_gains(V, b, 0.05, cache=tmp_path)
    second = synthesize_gains(V, b, 0.05, cache=tmp_path)
    assert not first.cache_hit and second.cache_hit and second.solve_s == 0.0 and second.certified
    np.testing.assert_allclose(first.L, second.L)


# ---- observer ------------------------------------------------------------------------
def state_error(trace, log, t_from):
    keep = log.sensors["t"] >= t_from
    return np.abs(trace.xi[keep] - log.truth["true_state"][keep]).max(axis=0)


def test_linear_tire_no_mismatch_weights_stay_near_zero_and_error_converges():
    log = simulate("lane_changes", 30.0, tire_model="linear")
    obs = build_observer(V, CameraParams(), ObserverConfig())
    obs.reset(xi0=[0.3, 0.2, 0.02, 0.01])  # start wrong
    trace = obs.run(log.sensors)
    assert np.abs(trace.weights[-1]).max() < 0.01  # 1 % of the nominal stiffness
    scale = np.array([1e-3, 1e-3, 1e-4, 1e-4])  # 1 mm, 1 mm/s, 0.1 mrad, 0.1 mrad/s
    err0 = np.abs(trace.xi[0] - log.truth["true_state"][0]) / scale
    err_end = state_error(trace, log, 20.0) / scale
    assert np.all(err_end < 1.0)
    assert np.linalg.norm(err_end) < 1e-2 * np.linalg.norm(err0)


@pytest.mark.parametrize("rate", [1000.0, 20.0])
def test_discretised_observer_is_stable_at_1khz_and_20hz(rate):
    camera = CameraParams(rate=rate)
    log = simulate("lane_changes", 20.0, camera=camera, tire_model="linear")
    obs = build_observer(V, camera, ObserverConfig())
    obs.reset(xi0=[1.0, 0.5, 0.05, 0.05])
    trace = obs.run(log.sensors)
    err = np.linalg.norm((trace.xi - log.truth["true_state"]) / [1.0, 1.0, 0.05, 0.05], axis=1)
    assert np.all(np.isfinite(err))
    assert err[-1] < 1e-3 * err[0]


def test_missing_frames_skip_the_correction():
    log = simulate("lane_changes", 5.0, camera=CameraParams(rate=1000.0))
    sensors = {k: v.copy() for k, v in log.sensors.items()}
    sensors["e1"][1000:3000] = np.nan
    sensors["e2"][1000:3000] = np.nan
    obs = build_observer(V, CameraParams(rate=1000.0), ObserverConfig())
    trace = obs.run(sensors)
    assert np.all(np.isnan(trace.innovation[1000:3000]))
    assert np.all(np.isfinite(trace.xi))
    # predicting open loop for 2 s from a good estimate stays close
    assert np.abs(trace.xi[2999, 0] - log.truth["true_state"][2999, 0]) < 0.05


def test_divergence_is_flagged():
    log = simulate("straight", 5.0)
    sensors = {k: v.copy() for k, v in log.sensors.items()}
    sensors["e1"][2000:] += 5.0  # the camera jumps by 5 m and stays there
    obs = build_observer(V, CameraParams(), ObserverConfig())
    trace = obs.run(sensors)
    assert trace.diverged and obs.diverged
    assert trace.diverged_at == pytest.approx(2.004, abs=0.01)


def test_observer_refuses_ground_truth():
    log = simulate("straight", 1.0)
    obs = build_observer(V, CameraParams(), ObserverConfig())
    with pytest.raises(ValueError, match="ground truth"):
        obs.run({**log.sensors, "true_e1": log.truth["true_state"][:, 0]})


def test_latency_compensation_helps():
    camera = CameraParams(rate=20.0, latency=0.1)
    log = simulate("lane_changes", 40.0, camera=camera)
    errs = []
    for comp in (False, True):
        res = estimate(log.sensors, V, camera, ObserverConfig(latency_compensation=comp, warm_start=False))
        keep = log.sensors["t"] > 5
        errs.append(np.sqrt(np.mean((res.trace.slip[keep] - log.truth["true_slip"][keep]) ** 2)))
    assert errs[1] < 0.5 * errs[0]


def test_predict_and_update_vocabulary_matches_run():
    log = simulate("lane_changes", 2.0)
    s = log.sensors
    a = build_observer(V, CameraParams(), ObserverConfig())
    b = build_observer(V, CameraParams(), ObserverConfig())
    trace = a.run(s)
    for j in range(len(s["t"])):
        if np.isfinite(s["e1"][j]):
            b.update((s["e1"][j], s["e2"][j]), s["delta"][j], s["psi_dot_des"][j], s["vx"][j])
        b.predict(s["delta"][j], s["psi_dot_des"][j], s["psi_ddot_des"][j], s["vx"][j])
    np.testing.assert_allclose(b.x, a.x, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(b.w, trace.weights[-1], rtol=1e-9, atol=1e-12)


# ---- warm start ----------------------------------------------------------------------
def test_warm_start_recovers_a_known_weight_vector():
    b = two_sided_basis(V)
    rng = np.random.default_rng(1)
    w_true = rng.uniform(-0.3, 0.2, b.n_weights)
    n = 5000
    slip = np.column_stack([rng.uniform(-0.15, 0.15, n), rng.uniform(-0.15, 0.15, n)])
    f = np.column_stack([b.nonlinear_force(slip[:, i], w_true, i) for i in (0, 1)])
    trace = ObserverTrace(np.arange(n) * 1e-3 + 10.0, np.zeros((n, 4)), slip, f, f, np.zeros((n, b.n_weights)), np.zeros((n, 2)))
    w0 = least_squares_weights(b, trace, linear_region=0.0, rho=1e-9)
    np.testing.assert_allclose(w0, w_true, atol=1e-6)


# ---- Study 1 -------------------------------------------------------------------------
def study1(duration):
    from tire_learning_env.studies import run_study, study_spec

    return run_study(study_spec(1, duration), figures=False)


def test_study1_meets_the_targets():
    """The full 60 s study takes a few seconds: no shortened version is needed."""
    m = study1(60.0)
    assert m["lmi"]["certified"] and m["lmi"]["decay_rate"] >= 2.0
    for axle in ("front", "rear"):
        assert m["slip_rmse_deg"][axle] <= 0.01
        assert m["tire_curve_nrmse"][axle] <= 0.02
        assert abs(m["cornering_stiffness"][axle]["error_pct"]) <= 0.5


def test_study1_noisy_20hz_camera_meets_its_target():
    from tire_learning_env.studies import run_study, study_spec

    m = run_study(study_spec(1).with_camera(20.0, "paper"), figures=False)
    for axle in ("front", "rear"):
        assert m["tire_curve_nrmse"][axle] <= 0.05
