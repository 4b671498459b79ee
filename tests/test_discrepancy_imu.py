"""Discrepancy workflow on IMU-only logs (issue 9 item 6): body-frame model, IMU effect library,
hidden effects named with their size, clean data gives ``none``, an effect outside the library is
``unexplained``, the command on an IMU log, and the real Revs log.

Simulated logs come from :mod:`tire_learning_env.discrepancy.imu_truth` (a race-car drive with
braking at up to 8 m/s^2 and cornering at up to 9 m/s^2, Pacejka tires with mu = 1.4, IMU noise of
the Revs log's size), written to CSV and read back strictly, as the command sees them. The truth
implements every effect independently of the compiled model. The workflow never reads ``true_*``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from tire_learning_env.cli import main
from tire_learning_env.discrepancy import DiscrepancyConfig, analyze
from tire_learning_env.discrepancy._body_model import N_STATE, OUT_R, OUT_VY, simulate_body_rows
from tire_learning_env.discrepancy._model import N_OUT, THETA_NOMINAL
from tire_learning_env.discrepancy.data import IMU_LOG, prepare
from tire_learning_env.discrepancy.effects import (
    EFFECT_NAMES,
    IMU_CONFOUNDED,
    IMU_EFFECT_NAMES,
    IMU_LIBRARY,
    LIBRARY,
    get_effect,
    library_for,
    theta_of,
)
from tire_learning_env.discrepancy.imu_truth import (
    HIDDEN_IMU_EFFECTS,
    REVS_LIKE_VEHICLE as V,
    parse_imu_effects,
    simulate_hidden_imu,
)
from tire_learning_env.discrepancy.residuals import ResidualModel
from tire_learning_env.discrepancy.criteria import long_run_variance, signature_correlation
from tire_learning_env.io import DrivingLog, LogFormatError, read_log, write_log
from tire_learning_env.params import ParameterError, TireParams
from tire_learning_env.tires import axle_tires

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
REVS_LOG = DATA / "revs_250lm_part1.csv"
REVS_VEHICLE = DATA / "revs_250lm_vehicle.json"
TIRE = TireParams(mu=1.4)  # the truth's (and the nominal model's) racing tire

# realistic sizes, chosen before measuring: hidden effects -> (library name, true library parameters)
CASES = {
    "tire_relaxation": ({"tire_relaxation": 0.5}, [0.5]),
    "cornering_stiffness_scale": ({"cornering_stiffness_scale_front": 0.85}, [0.85, 1.0]),
    "longitudinal_load_transfer": ({"longitudinal_load_transfer": 0.35}, [0.35]),
    "lateral_load_transfer": ({"lateral_load_transfer_front": 0.12, "lateral_load_transfer_rear": 0.06}, [0.12, 0.06]),
    "steering_offset": ({"steering_offset": 0.002}, [0.002]),
    "steering_compliance": ({"steering_compliance": 1e-6}, [1e-6]),
    "steering_ratio_nonlinearity": ({"steering_ratio_nonlinearity": 0.1}, [0.1]),
    "steering_delay": ({"steering_delay": 0.03}, [0.03]),
    "yaw_rate_bias": ({"yaw_rate_bias": 0.005}, [0.005]),
    "ay_bias": ({"ay_bias": 0.2}, [0.2]),
    "ay_scale": ({"ay_scale": 0.03}, [0.03]),
    "road_bank": ({"road_bank": 0.02}, [0.02]),
    "accelerometer_offset": ({"accelerometer_offset": 1.0}, [1.0]),
    "yaw_inertia_scale": ({"yaw_inertia_scale": 1.25}, [1.25]),
    "speed_dependent_stiffness": ({"speed_dependent_stiffness": -5e-5}, [-5e-5]),
}
FAST_CASES = ("longitudinal_load_transfer", "steering_offset", "yaw_rate_bias")


def _log(tmp_path: Path, effects: dict, seed: int = 1, duration: float = 60.0, name: str = "imu.csv") -> DrivingLog:
    path = tmp_path / name
    write_log(path, simulate_hidden_imu(effects, duration=duration, seed=seed))
    return read_log(path)


def _deviation_error(effect_name: str, fitted: dict, truth) -> float:
    """Largest relative error of the fitted deviation from 'absent' against the true deviation."""
    eff = get_effect(effect_name, "imu")
    true_dev = eff.size(truth)
    fit_dev = eff.size([fitted[p] for p in eff.parameters])
    return float(np.max(np.abs(fit_dev - true_dev)) / np.max(np.abs(true_dev)))


def _analyze(log: DrivingLog, **kwargs):
    return analyze(log, V, "pacejka", progress=False, tire_params=TIRE, **kwargs)


# ---------------------------------------------------------------- the library


def test_imu_library_registry():
    assert set(CASES) == set(IMU_EFFECT_NAMES)
    assert library_for("imu") is IMU_LIBRARY and library_for("camera") is LIBRARY
    assert EFFECT_NAMES[0] == "tire_relaxation" and "crosswind" not in IMU_EFFECT_NAMES
    seen = {}
    for e in IMU_LIBRARY:
        assert len(e.parameters) == len(e.units) == len(e.bounds) == len(e.theta_index) == len(e.absent)
        for i, (lo, hi), a in zip(e.theta_index, e.bounds, e.absent):
            assert lo <= a <= hi and THETA_NOMINAL[i] == a
            assert i not in seen, f"{e.name} and {seen.get(i)} share theta[{i}]"
            seen[i] = e.name
        vals = np.array([0.5 * (lo + hi) for lo, hi in e.bounds])
        np.testing.assert_allclose(e.values_in(e.apply(THETA_NOMINAL, vals)), vals)
    # shared physics is the same object; the speed effect keeps 1 - c vx^2 > 0 up to 70 m/s
    assert get_effect("tire_relaxation", "imu") is get_effect("tire_relaxation", "camera")
    c_max = max(abs(b) for b in get_effect("speed_dependent_stiffness", "imu").bounds[0])
    assert 1.0 - c_max * 70.0**2 > 0
    assert get_effect("speed_dependent_stiffness") is get_effect("speed_dependent_stiffness", "camera")
    with pytest.raises(KeyError, match="unknown effect"):
        get_effect("crosswind", "imu")
    assert all(len(pair) == 2 and pair <= set(IMU_EFFECT_NAMES) | {"cornering_stiffness_scale"} for pair in IMU_CONFOUNDED)
    assert set(HIDDEN_IMU_EFFECTS) >= set(IMU_EFFECT_NAMES) | {"combined_slip"}
    with pytest.raises(ParameterError, match="unknown IMU effect 'gremlins'"):
        parse_imu_effects({"gremlins": 1.0})


def _chi2_per_sample(hidden: dict, *effects: dict | None) -> list[float]:
    """chi2 / n of the model with each of ``effects`` (None: the nominal model) on one 40 s log with ``hidden``
    effects (same noise, same drive; the log is simulated once, each model built afresh)."""
    cols = simulate_hidden_imu(hidden, duration=40.0, seed=3)
    log = DrivingLog({k: cols[k] for k in ("t", "vx", "delta", "yaw_rate", "ay", "ax")}, {}, "imu", "sim")
    cfg = DiscrepancyConfig()
    data = prepare(log, cfg)
    if not CLEAN_WEIGHT.any():  # the clean log's noise estimate (hidden = {} is the first call)
        assert not hidden
        CLEAN_WEIGHT[2:] = 1.0 / data.sigma[2:]
    out = []
    for eff in effects:
        model = ResidualModel(data, V, *axle_tires(V, "pacejka", TIRE), cfg)
        ev = model.best_of(theta_of(eff, "imu"), [None]) if eff else model.nominal_start()
        # chi2 in units of the clean log's noise estimate, so that logs with different effects compare
        out.append(float(np.sum((ev.resid / data.meas_w) ** 2 * CLEAN_WEIGHT[data.meas_chan] ** 2) / data.n_measurements))
    return out


CLEAN_WEIGHT = np.zeros(4)
CLEAN_CHI2: list[float] = []  # the nominal model's chi2 / n on the clean drive, computed once for every case


@pytest.mark.parametrize("name", list(CASES))
def test_truth_and_model_implement_each_effect_identically(name):
    """The compiled body-frame model with the true parameters reproduces the independently
    implemented truth to the noise level: the same chi2 as the nominal model on the same drive
    without the effect."""
    if not CLEAN_CHI2:
        CLEAN_CHI2.extend(_chi2_per_sample({}, None))
    hidden, truth = CASES[name]
    clean = CLEAN_CHI2[0]
    with_effect, nominal = _chi2_per_sample(hidden, {name: truth}, None)
    # 1.5 % of chi2 for the longitudinal load transfer: the model's a_x input is estimated from the log
    # (slope of vx + slow part of the noisy logged a_x), the truth uses the exact specific force
    assert with_effect == pytest.approx(clean, rel=1.5e-2 if name == "longitudinal_load_transfer" else 1e-3)
    assert nominal >= with_effect - 1e-4


def test_body_model_follows_the_true_state():
    """From the true initial state the model tracks the truth's yaw rate and lateral velocity."""
    cols = simulate_hidden_imu({}, duration=20.0, noise_std=(1e-9, 1e-9, 1e-9))
    log = DrivingLog({k: cols[k] for k in ("t", "vx", "delta", "yaw_rate", "ay", "ax")}, {}, "imu", "sim")
    data = prepare(log, DiscrepancyConfig())
    model = ResidualModel(data, V, *axle_tires(V, "pacejka", TIRE), DiscrepancyConfig())
    for w in range(data.n_windows):
        j0, j1 = int(data.win_sim[w]), int(data.win_end[w])
        x0 = np.array([cols["true_vy"][j0], cols["yaw_rate"][j0]])
        traj = np.empty((j1 - j0 + 1, N_OUT))
        assert simulate_body_rows(x0, j0, j1, data.t, data.delta, data.dslope, data.vx, data.ax, model.veh,
                                  model.tf, model.tr, model.tabf, model.tabr, THETA_NOMINAL.copy(), 0.01, traj)  # fmt: skip
        assert np.max(np.abs(traj[:, OUT_R] - cols["yaw_rate"][j0 : j1 + 1])) < 2e-4
        assert np.max(np.abs(traj[:, OUT_VY] - cols["true_vy"][j0 : j1 + 1])) < 5e-3
    assert N_STATE == 2 and data.kind == "imu" and data.channels == ("yaw_rate", "ay")


# ---------------------------------------------------------------- hidden effects, clean data


@pytest.mark.parametrize("name", FAST_CASES)
def test_hidden_effect_is_named_with_its_size(tmp_path, name):
    hidden, truth = CASES[name]
    res = _analyze(_log(tmp_path, hidden))
    assert res.verdict == "found", (res.verdict, [e["name"] for e in res.partial_effects])
    assert [e["name"] for e in res.effects] == [name]
    assert _deviation_error(name, res.effects[0]["parameters"], truth) <= 0.20, res.effects[0]["parameters"]
    assert res.gap_ratio > 1.2, res.gap_ratios()
    ev = res.effects[0]["evidence"]
    assert ev["p_value"] < 1e-6 and ev["delta_bic"] < 0 and ev["inflation"] >= 1.0


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_every_hidden_effect_is_named_with_its_size(tmp_path, name):
    hidden, truth = CASES[name]
    res = _analyze(_log(tmp_path, hidden, duration=90.0))
    assert res.verdict == "found", (res.verdict, [e["name"] for e in res.partial_effects])
    assert [e["name"] for e in res.effects] == [name]
    assert _deviation_error(name, res.effects[0]["parameters"], truth) <= 0.20, res.effects[0]["parameters"]


@pytest.mark.slow
def test_two_effects_at_once_are_both_named(tmp_path):
    res = _analyze(_log(tmp_path, {"longitudinal_load_transfer": 0.35, "ay_bias": 0.2}, duration=90.0))
    assert res.verdict == "found"
    found = {e["name"]: e["parameters"] for e in res.effects}
    assert set(found) == {"longitudinal_load_transfer", "ay_bias"}
    assert _deviation_error("longitudinal_load_transfer", found["longitudinal_load_transfer"], [0.35]) <= 0.2
    assert _deviation_error("ay_bias", found["ay_bias"], [0.2]) <= 0.2


# seed 12 is slow: seed 11 keeps the property in the default run, test_clean_imu_data_gives_none_in_19_of_20_seeds
# (slow) takes 20 more seeds
@pytest.mark.parametrize("seed", [11, pytest.param(12, marks=pytest.mark.slow)])
def test_clean_imu_data_gives_none(tmp_path, seed):
    res = _analyze(_log(tmp_path, {}, seed=seed))
    assert res.verdict == "none", [(k, v.get("lr")) for st in res.selection.steps for k, v in st.tried.items()]
    assert res.effects == [] and res.gap_ratio == pytest.approx(1.0)


def test_a_pause_in_a_clean_imu_log_splits_the_windows_and_gives_none(tmp_path):
    """A logger pause (3 s without rows) was refused ('non-uniform sampling with a gap'); the windows split at it."""
    log = _log(tmp_path, {}, seed=11)
    t = log.sensors["t"]
    keep = (t < 27.0) | (t >= 30.0)
    path = tmp_path / "paused.csv"
    write_log(path, {k: np.asarray(v)[keep] for k, v in {**log.sensors, **log.truth}.items()})
    res = _analyze(read_log(path))
    log_notes = res.to_json()["log"]["notes"]
    assert any("gap(s) longer than" in n and "split the windows" in n for n in log_notes), log_notes
    assert res.verdict == "none", [(k, v.get("lr")) for st in res.selection.steps for k, v in st.tried.items()]


@pytest.mark.slow
def test_clean_imu_data_gives_none_in_19_of_20_seeds(tmp_path):
    verdicts = [_analyze(_log(tmp_path, {}, seed=100 + s)).verdict for s in range(20)]
    assert verdicts.count("none") >= 19, verdicts


@pytest.mark.slow
def test_learned_tire_nominal_gives_none_on_clean_data(tmp_path):
    # was a strict xfail (a spurious small lag effect); passes since the observer's learned curve improved
    # (issue 18 check: seeds 101 and 102 give none, largest likelihood ratio 3.3 / 3.6)
    res = analyze(_log(tmp_path, {}, seed=101, duration=90.0), V, "learned", progress=False)
    assert res.verdict == "none", [e["name"] for e in res.effects]


@pytest.mark.slow
def test_effect_outside_the_imu_library_is_unexplained(tmp_path):
    res = _analyze(_log(tmp_path, {"combined_slip": 1.3}, duration=90.0))
    assert res.verdict == "unexplained"
    assert res.effects == []


def test_workflow_never_reads_ground_truth_of_an_imu_log(tmp_path):
    class Poisoned(dict):
        def _boom(self, *args, **kwargs):
            raise AssertionError("the discrepancy workflow read ground truth")

        __getitem__ = __iter__ = __contains__ = keys = values = items = get = _boom

    log = _log(tmp_path, {"yaw_rate_bias": 0.005}, duration=40.0)
    assert log.kind == "imu" and log.truth  # the CSV has true_vy, true_beta, ...
    log.truth = Poisoned(log.truth)
    res = _analyze(log)
    assert [e["name"] for e in res.effects] == ["yaw_rate_bias"]


# ---------------------------------------------------------------- the command, reports, errors


def test_command_on_an_imu_log_writes_the_report(tmp_path, capsys):
    log = tmp_path / "imu.csv"
    write_log(log, simulate_hidden_imu({"steering_offset": 0.002}, duration=40.0, seed=5))
    vehicle = tmp_path / "vehicle.json"
    vehicle.write_text(json.dumps({"m": V.m, "Iz": V.Iz, "lf": V.lf, "lr": V.lr, "Cf": V.Cf, "Cr": V.Cr}))
    out = tmp_path / "report"
    assert main(["discrepancy", str(log), "--vehicle", str(vehicle), "--tire", "pacejka", "--mu", "1.4",
                 "--out", str(out), "--no-progress"]) == 0  # fmt: skip
    doc = json.loads((out / "report.json").read_text())
    assert doc["verdict"] == "found" and doc["log"]["kind"] == "imu"
    eff = doc["effects"][0]
    assert eff["name"] == "steering_offset" and eff["units"] == {"offset": "rad"}
    assert abs(eff["parameters"]["offset"] - 0.002) < 0.0004
    assert set(eff["evidence"]) >= {"likelihood_ratio", "likelihood_ratio_raw", "inflation", "p_value", "delta_bic",
                                    "signature_correlation", "separation_from"}  # fmt: skip
    assert doc["comparison"]["channels"] == ["yaw_rate", "ay"] and doc["gap_before"]["units"]["ay"] == "m/s^2"
    assert {e["name"] for e in doc["library"]} == set(IMU_EFFECT_NAMES)
    assert doc["identifiability"] and "turn_and_braking_before" in doc["locate"]
    assert set(doc["figures"]) >= {"regime_residuals.png", "worst_window.png", "residuals.png", "whiteness.png"}
    for fig in doc["figures"]:
        assert (out / fig).stat().st_size > 1000
    md = (out / "report.md").read_text()
    assert "steering_offset" in md and "cannot tell apart" in md and "IMU (yaw_rate, ay)" in md
    assert json.loads(capsys.readouterr().out.splitlines()[-2])["verdict"] == "found"


@pytest.mark.parametrize(
    "header, rows, message",
    [
        ("t,vx,delta,yaw_rate,ay", [f"{0.01 * i:.2f},30,0,0,0" for i in range(300)], "too short to fit anything"),
        ("t,vx,delta,yaw_rate,ay", [f"{0.01 * i:.2f},30,0,0,{'nan' if i > 20 else 0}" for i in range(900)],
         "valid ay samples"),
        ("t,vx,delta,yaw_rate,ay", [f"{0.01 * i:.2f},1.5,0,0,0" for i in range(900)], "needs forward motion"),
    ],
    ids=["too-short", "no-ay", "standstill"],
)
def test_bad_imu_log_is_a_clear_error(tmp_path, capsys, header, rows, message):
    path = tmp_path / "bad.csv"
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    assert main(["discrepancy", str(path), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert message in err, err
    assert not (tmp_path / "out").exists()


def test_imu_log_with_use_imu_off_is_an_error(tmp_path):
    log = _log(tmp_path, {}, duration=20.0)
    with pytest.raises(LogFormatError, match="use_imu is off") as info:
        prepare(log, DiscrepancyConfig(use_imu=False))
    assert IMU_LOG in str(info.value)  # the message says which kind of log it found


# ---------------------------------------------------------------- statistics


def test_long_run_variance_is_one_for_white_noise_and_larger_for_a_correlated_residual():
    log = DrivingLog({k: v for k, v in simulate_hidden_imu({}, duration=30.0).items() if not k.startswith("true")},
                     {}, "imu", "sim")  # fmt: skip
    data = prepare(log, DiscrepancyConfig())
    rng = np.random.default_rng(0)
    white = rng.standard_normal(data.n_measurements)
    assert long_run_variance(data, white) == pytest.approx(1.0, abs=0.15)
    slow = np.repeat(rng.standard_normal(data.n_measurements // 50 + 1), 50)[: data.n_measurements]
    assert long_run_variance(data, slow) > 10.0


def test_signature_correlation():
    rng = np.random.default_rng(1)
    a = rng.standard_normal((500, 1))
    assert signature_correlation(a, 3.0 * a) == pytest.approx(1.0)
    b = rng.standard_normal((500, 2))
    assert signature_correlation(a, np.column_stack([b[:, 0], a[:, 0] + b[:, 1]])) > 0.7
    assert signature_correlation(a, b) < 0.2


# ---------------------------------------------------------------- the real log


@pytest.mark.skipif(not REVS_LOG.exists(), reason="shared data not available")
def test_real_revs_log_slice_runs_and_is_not_misnamed(tmp_path):
    """30 s of the real Ferrari log with the linear nominal tire: the workflow runs, reads no truth,
    and a real car's structured residual is never reported as a clean ``found``. (30 s, not 60: the
    same verdict, unexplained, with p = 0 and a gap of 10.2 against 8.0; the whole log: slow test below.)"""
    full = read_log(REVS_LOG)
    log = full.slice(150.0, 180.0)
    res = analyze(log, read_vehicle_json(), "linear", progress=False)
    assert res.data.kind == "imu" and res.whiteness_before.p_value < 0.01
    assert res.verdict in ("unexplained", "found")
    if res.verdict == "unexplained":
        assert res.effects == []
    assert res.gap_before.normalised_band_rms["all"] > 2.0  # far from the noise level


def read_vehicle_json():
    from tire_learning_env.io import read_vehicle

    return read_vehicle(REVS_VEHICLE)


@pytest.mark.slow
@pytest.mark.skipif(not REVS_LOG.exists(), reason="shared data not available")
def test_real_revs_log_whole_with_the_learned_tire(tmp_path):
    out = tmp_path / "revs"
    assert main(["discrepancy", str(REVS_LOG), "--vehicle", str(REVS_VEHICLE), "--tire", "learned", "--out", str(out),
                 "--no-progress"]) == 0  # fmt: skip
    doc = json.loads((out / "report.json").read_text())
    assert doc["nominal_model"]["tire"]["kind"] == "learned"
    assert doc["verdict"] in ("unexplained", "found", "none")
    # runtime: measured by benchmarks/bench_discrepancy.py --suite imu_real, not asserted on a shared machine
    assert math.isfinite(doc["gap_before"]["normalised_band_rms"]["all"])
