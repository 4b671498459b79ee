"""IMU variant: model, speed-polytope certificate, observer on simulated data, log reader, real-log slice."""

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from tire_learning_env.io import LogFormatError, read_log, write_log
from tire_learning_env.imu import (
    ESTIMATE_COLUMNS,
    ImuConfig,
    ImuObserver,
    InfeasibleLMIError,
    LinearKalmanBaseline,
    clean_imu_log,
    estimate_imu,
    imu_basis,
    simulate_imu_drive,
    synthesize_imu_gains,
)
from tire_learning_env.imu.estimate import _check_basis_in_box
from tire_learning_env.imu.gains import STATE_SCALE, slope_box
from tire_learning_env.imu.model import body_matrices, slip_angles
from tire_learning_env.metrics import curve_nrmse, excited_range
from tire_learning_env.observer.basis import two_sided_basis
from tire_learning_env.params import ParameterError, TireParams, VehicleParams

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
REVS_LOG = DATA / "revs_250lm_part1.csv"
REVS_VEHICLE = DATA / "revs_250lm_vehicle.json"
V = VehicleParams(m=982.0, Iz=1605.0, lf=1.33, lr=1.07, Cf=35000.0, Cr=60000.0)  # revs_250lm_vehicle.json


@pytest.fixture(scope="module")
def cache_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("imu_gains")


@pytest.fixture(scope="module")
def gains(cache_dir):
    return synthesize_imu_gains(V, 0.01, cache=cache_dir)


# ---- model -----------------------------------------------------------------------------------
def _rhs_linear(x, delta, vx, kf, kr, vehicle):
    af, ar = slip_angles(x[0], x[1], delta, vx, vehicle)
    Ff, Fr = kf * af, kr * ar
    return np.array([(Ff + Fr) / vehicle.m - vx * x[1], (vehicle.lf * Ff - vehicle.lr * Fr) / vehicle.Iz]), (Ff + Fr) / vehicle.m


def test_body_matrices_are_the_jacobians_of_the_nonlinear_model():
    kf, kr, vx = 60000.0, 110000.0, 27.0
    A, C, E, D = body_matrices(V, vx, kf, kr)
    x0 = np.array([0.3, 0.2])
    h = 1e-6
    for j in range(2):
        dx = np.zeros(2)
        dx[j] = h
        fp, ayp = _rhs_linear(x0 + dx, 0.0, vx, kf, kr, V)
        fm, aym = _rhs_linear(x0 - dx, 0.0, vx, kf, kr, V)
        np.testing.assert_allclose((fp - fm) / (2 * h), A[:, j], rtol=1e-6)
        assert (ayp - aym) / (2 * h) == pytest.approx(C[0, j], rel=1e-6)
    assert C[1].tolist() == [0.0, 1.0]
    # force error enters the dynamics through E and a_y directly through D (the feedthrough)
    np.testing.assert_allclose(E @ [1.0, 0.0], [1 / V.m, V.lf / V.Iz])
    np.testing.assert_allclose(D @ [1.0, 1.0], [2 / V.m, 0.0])


def test_steady_state_yaw_gain_matches_the_understeer_formula():
    vx = 30.0
    A, C, E, D = body_matrices(V, vx, 2 * V.Cf, 2 * V.Cr)
    B = np.array([2 * V.Cf / V.m, 2 * V.Cf * V.lf / V.Iz])  # steering input (linear tires)
    x_ss = -np.linalg.solve(A, B)
    assert x_ss[1] == pytest.approx(vx / (V.wheelbase + V.understeer_gradient * vx**2), rel=1e-9)


# ---- certificate over the speed range ----------------------------------------------------------
def test_imu_lmi_certificate_holds_over_the_whole_speed_range(gains, cache_dir):
    s = gains.summary()
    assert gains.certified and s["certified"]
    assert gains.speed_range[0] <= 16.0 and gains.speed_range[1] >= 61.0  # the Revs log's 16-61 m/s
    assert gains.max_vertex_eig <= gains.tolerance
    assert gains.decay_rate >= 0.1 * 0.999  # requested decay (worst vertex, worst cell)
    assert gains.dense_check["ok"] and gains.dense_check["points"] >= 1000
    assert s["n_vertices"] == 16 * gains.n_cells
    # independent random check on the physical set (1/vx tied to vx): the common Lyapunov
    # function decreases at the certified rate with the gain of the cell the speed is in
    rng = np.random.default_rng(1)
    box = gains.slope_box
    S, Si = np.diag(STATE_SCALE), np.diag(1 / STATE_SCALE)
    P = gains.P
    rho = math.exp(-gains.decay_rate * gains.dt)
    for _ in range(400):
        v = rng.uniform(*gains.speed_range)
        kf, kr = rng.uniform(*box[0]), rng.uniform(*box[1])
        A, C, _, _ = body_matrices(V, v, kf, kr)
        Acl = Si @ (np.eye(2) + gains.dt * A - gains.gain(v) @ C) @ S
        M = Acl.T @ P @ Acl - rho**2 * P
        assert np.linalg.eigvalsh(0.5 * (M + M.T)).max() <= 1e-9 * np.abs(P).max()
    # speeds outside the range use the nearest cell's gain (reported as uncertified rows)
    np.testing.assert_array_equal(gains.gain(5.0), gains.L[0])
    np.testing.assert_array_equal(gains.gain(90.0), gains.L[-1])
    # a cache hit is re-certified, not trusted
    again = synthesize_imu_gains(V, 0.01, cache=cache_dir)
    assert again.cache_hit and again.certified
    np.testing.assert_allclose(again.L, gains.L)
    for f in Path(cache_dir).glob("imu_*.json"):
        data = json.loads(f.read_text())
        data["Ls"] = [(np.array(L) * 50).tolist() for L in data["Ls"]]
        f.write_text(json.dumps(data))
    tampered = synthesize_imu_gains(V, 0.01, cache=cache_dir)
    assert not tampered.cache_hit and tampered.certified  # re-solved


def test_both_axles_fully_saturated_is_infeasible_and_named(tmp_path):
    # at zero slope on both axles the lateral velocity is unobservable from (a_y, r)
    with pytest.raises(InfeasibleLMIError, match="k_f=0, k_r=0"):
        synthesize_imu_gains(V, 0.01, n_cells=2, slope_fractions=(0.0, 1.5), decay_rate=0.5, cache=tmp_path)


def test_learnable_curves_stay_inside_the_certified_box(gains):
    basis = imu_basis(V)
    assert basis.n_per_axle == 12  # segments only: no bias member
    _check_basis_in_box(basis, gains, V)
    rng = np.random.default_rng(0)
    box = slope_box(V, (0.1, 1.5), max_steer=0.0)
    a = np.linspace(-0.3, 0.3, 3001)
    for _ in range(50):
        w = rng.uniform(basis.weight_lower.ravel(), basis.weight_upper.ravel())
        for i in (0, 1):
            slope = 2 * (V.Cf, V.Cr)[i] + basis.nonlinear_slope(a, w, i)
            assert box[i, 0] - 1e-6 <= slope.min() and slope.max() <= box[i, 1] + 1e-6
    wide = two_sided_basis(V, slope_range=(-1.0, 0.5), bias_bound=0.0)
    with pytest.raises(ParameterError, match="outside the certified box"):
        _check_basis_in_box(wide, gains, V)


# ---- observer on simulated IMU data (Pacejka truth, varying speed) -----------------------------
@pytest.fixture(scope="module")
def simulated(cache_dir):
    truth_vehicle = V.replace(Cf=0.85 * V.Cf, Cr=0.9 * V.Cr)  # stiffness the observer does not know
    sensors, truth, tires = simulate_imu_drive(
        V, duration=90.0, true_vehicle=truth_vehicle, tire=TireParams(mu=0.9), ay_max=8.3, speed_range=(18.0, 55.0)
    )
    result = estimate_imu(sensors, V, ImuConfig(warm_start=False), cache=cache_dir)
    return sensors, truth, tires, truth_vehicle, result


def test_observer_recovers_the_pacejka_curve_and_stiffness(simulated):
    sensors, truth, (front, rear), tv, result = simulated
    assert sensors["vx"].min() < 19 and sensors["vx"].max() > 54
    true_curve = {"front": front.lateral_force, "rear": rear.lateral_force}
    for i, axle in enumerate(("front", "rear")):
        lo, hi = excited_range(truth["true_alpha_f" if i == 0 else "true_alpha_r"])
        learned = curve_nrmse(result.axle_force, lambda a, ax: true_curve[ax](a), axle, lo, hi)
        nominal = curve_nrmse(result.nominal_axle_force, lambda a, ax: true_curve[ax](a), axle, lo, hi)
        assert learned < 0.03, (axle, learned)
        assert learned < 0.3 * nominal, (axle, learned, nominal)  # learning, not the nominal curve
    # the test drive goes well into the nonlinear range (nominal curve off by > 5 %)
    lo, hi = excited_range(truth["true_alpha_f"])
    assert curve_nrmse(result.nominal_axle_force, lambda a, ax: front.lateral_force(a), "front", lo, hi) > 0.05
    kf, kr = result.cornering_stiffness()
    assert kf == pytest.approx(tv.Cf, rel=0.05) and kr == pytest.approx(tv.Cr, rel=0.05)
    err = np.degrees(result.online.beta - truth["true_beta"])
    err_nominal = np.degrees(result.nominal.beta - truth["true_beta"])
    assert np.sqrt(np.mean(err**2)) < 0.05
    assert np.sqrt(np.mean(err**2)) < 0.6 * np.sqrt(np.mean(err_nominal**2))
    assert not result.online.diverged


def test_observer_is_causal_and_refuses_truth(simulated, gains):
    sensors, truth, _, _, _ = simulated
    rows = {k: sensors[k] for k in ("t", "delta", "vx", "ay", "yaw_rate")}
    obs = ImuObserver(V, imu_basis(V), gains)
    full = obs.run(rows)
    # changing the future never changes the past
    k = 3000
    future = {key: v.copy() for key, v in rows.items()}
    future["ay"][k:] += 3.0
    future["delta"][k:] *= -1
    obs.reset()
    changed = obs.run(future)
    np.testing.assert_array_equal(changed.x[:k], full.x[:k])
    np.testing.assert_array_equal(changed.weights[:k], full.weights[:k])
    # processing in two chunks equals one pass
    obs.reset()
    a = obs.run({key: v[:k] for key, v in rows.items()})
    b = obs.run({key: v[k:] for key, v in rows.items()})
    np.testing.assert_allclose(np.vstack([a.x, b.x]), full.x, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="ground truth"):
        obs.run({**rows, "true_beta": truth["true_beta"]})


def test_missing_imu_samples_are_prediction_only(gains):
    sensors, truth, _ = simulate_imu_drive(V, duration=20.0, seed=3)
    rows = {k: sensors[k].copy() for k in ("t", "delta", "vx", "ay", "yaw_rate")}
    rows["ay"][500:520] = np.nan
    tr = ImuObserver(V, imu_basis(V), gains).run(rows)
    assert np.all(np.isnan(tr.innovation[500:520])) and np.all(np.isfinite(tr.x))
    assert np.sqrt(np.mean(np.degrees(tr.beta - truth["true_beta"]) ** 2)) < 0.1


def test_linear_kalman_baseline_is_exact_on_a_linear_tire_plant():
    # with linear tires of exactly the assumed stiffness the baseline's model is right
    tire = TireParams(mu=50.0)  # peak far away: the Magic Formula is linear over the drive
    sensors, truth, _ = simulate_imu_drive(V, duration=40.0, tire=tire, ay_max=4.0, noise_std=(0.2, 0.001))
    kf = LinearKalmanBaseline(V).run(sensors)
    err = np.degrees(kf.beta - truth["true_beta"])
    assert np.sqrt(np.mean(err[200:] ** 2)) < 0.03
    with pytest.raises(ValueError, match="ground truth"):
        LinearKalmanBaseline(V).run({**sensors, "true_vy": truth["true_vy"]})


# ---- reading and cleaning real IMU logs --------------------------------------------------------
def _imu_columns(n=2000, dt=0.01, seed=0):
    sensors, truth, _ = simulate_imu_drive(V, duration=(n - 1) * dt, dt=dt, seed=seed)
    cols = {k: sensors[k] for k in ("t", "vx", "delta", "yaw_rate", "ay", "ax")}
    cols["true_beta"] = truth["true_beta"]
    return cols


def _write(tmp_path, cols, name="log.csv"):
    path = tmp_path / name
    write_log(path, cols)
    return path


def test_reader_accepts_an_imu_log_and_keeps_truth_apart(tmp_path):
    log = read_log(_write(tmp_path, _imu_columns()))
    assert log.kind == "imu" and "true_beta" in log.truth and "true_beta" not in log.sensors
    cleaned, report = clean_imu_log(log, V)
    assert report.steering_spikes["count"] == 0 and report.checks["ay_vs_vx_r_slope"] == pytest.approx(1.0, abs=0.25)


def test_single_sample_steering_spike_is_removed_and_reported(tmp_path):
    cols = _imu_columns()
    cols["delta"] = cols["delta"].copy()
    clean = cols["delta"].copy()
    cols["delta"][300] += 0.1365  # the Revs decimation defect
    cleaned, report = clean_imu_log(read_log(_write(tmp_path, cols)), V)
    assert report.steering_spikes["count"] == 1 and report.steering_spikes["t"] == [round(cols["t"][300], 4)]
    np.testing.assert_allclose(cleaned.sensors["delta"][299:302], [clean[299], clean[299], clean[301]])
    assert any("steering: 1 spike" in n for n in cleaned.notes)
    # a persistent jump (not a spike) is accepted after 3 samples and counted
    cols["delta"] = clean.copy()
    cols["delta"][400:] += 0.05
    _, report = clean_imu_log(read_log(_write(tmp_path, cols, "step.csv")), V)
    assert report.steering_spikes["count"] == 3 and report.steering_spikes["level_jumps_accepted"] == 1


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda c: c.pop("ay"), "needs columns yaw_rate"),
        (lambda c: c.__setitem__("yaw_rate", np.degrees(c["yaw_rate"]) * 20), "deg/s"),
        (lambda c: c.__setitem__("ay", c["ay"] / 9.81), "ay in g"),
        (lambda c: c.__setitem__("ay", -c["ay"]), "opposite sign convention of ay"),
        (lambda c: c.__setitem__("delta", -c["delta"]), "opposite steering sign"),
        (lambda c: c.__setitem__("t", np.r_[c["t"][:300], c["t"][300:] + 0.5]), "non-uniform sampling"),
        (lambda c: c.__setitem__("vx", np.r_[c["vx"][:10] * 0 - 1, c["vx"][10:]]), "forward motion"),
    ],
)
def test_reader_errors_on_malformed_imu_logs(tmp_path, mutate, message):
    cols = _imu_columns()
    mutate(cols)
    if "ay" not in cols:  # io.read_log needs yaw_rate and ay (or camera columns)
        with pytest.raises(LogFormatError, match="yaw_rate and ay"):
            read_log(_write(tmp_path, cols))
        from tire_learning_env.io import DrivingLog

        log = DrivingLog({k: v for k, v in cols.items() if not k.startswith("true")}, {}, "imu", "mem")
        with pytest.raises(LogFormatError, match=message):
            clean_imu_log(log, V)
        return
    with pytest.raises(LogFormatError, match=message):
        clean_imu_log(read_log(_write(tmp_path, cols)), V)


def test_physically_impossible_ay_becomes_nan_and_is_counted(tmp_path):
    cols = _imu_columns()
    cols["ay"] = cols["ay"].copy()
    cols["ay"][[100, 200]] = 400.0
    cleaned, report = clean_imu_log(read_log(_write(tmp_path, cols)), V)
    assert report.ay_out_of_range["count"] == 2 and np.isnan(cleaned.sensors["ay"][[100, 200]]).all()
    assert report.missing["ay"] == 2


# ---- the real log, end to end ------------------------------------------------------------------
@pytest.mark.skipif(not REVS_LOG.exists(), reason="shared Revs data not available")
def test_real_log_slice_runs_end_to_end(tmp_path):
    from tire_learning_env.cli import main

    full = read_log(REVS_LOG)
    piece = full.slice(195.0, 235.0)  # contains the steering spike at t = 207.27 s
    cols = {**piece.sensors, **piece.truth}
    path = tmp_path / "slice.csv"
    write_log(path, cols)
    out = tmp_path / "out"
    assert main(["estimate", str(path), "--vehicle", str(REVS_VEHICLE), "--out", str(out)]) == 0
    with open(out / "estimates.csv") as fh:
        header = next(csv.reader(fh))
    assert tuple(header[: len(ESTIMATE_COLUMNS)]) == ESTIMATE_COLUMNS
    m = json.loads((out / "metrics.json").read_text())
    assert m["cleaning"]["steering_spikes"]["count"] == 1
    assert m["lmi"]["certified"] and m["speed_coverage"]["rows_outside_certified_speed_range"] == 0
    ref = m["reference_scores"]
    for key in ("observer_online_causal", "linear_kf_baseline"):
        assert set(ref["sideslip_rmse_deg"][key]) == {"whole", "first_half", "second_half"}
        assert ref["sideslip_rmse_deg"][key]["whole"] < 2.0
    assert set(ref["tire_curve_nrmse"]["final_learned_curve"]) == {"front", "rear"}
    for name in ("tire_curves.csv", "tire_curves.png", "tire_curve_front.png", "tire_curve_rear.png", "sideslip.png"):
        assert (out / name).stat().st_size > 0
    k = m["cornering_stiffness"]["final"]
    assert k["per_axle_N_per_rad"]["front"] == pytest.approx(2 * k["per_tire_N_per_rad"]["front"])


@pytest.mark.slow
@pytest.mark.skipif(not REVS_LOG.exists(), reason="shared Revs data not available")
def test_full_real_log_targets(tmp_path):
    from tire_learning_env.imu import estimate_imu_log

    m = estimate_imu_log(read_log(REVS_LOG), VehicleParams.from_json(REVS_VEHICLE), tmp_path / "out")
    ref = m["reference_scores"]
    assert ref["sideslip_rmse_deg"]["observer_online_causal"]["whole"] <= 0.5
    assert ref["sideslip_rmse_deg"]["observer_online_causal"]["whole"] < ref["sideslip_rmse_deg"]["linear_kf_baseline"]["whole"]
    for axle in ("front", "rear"):
        assert ref["tire_curve_nrmse"]["final_learned_curve"][axle]["whole"] <= 0.10
    assert m["runtime_s"]["observer_all_passes"] <= 10.0


def test_module_doctest_runs():
    import doctest

    import tire_learning_env.imu.estimate as mod

    result = doctest.testmod(mod, optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0
