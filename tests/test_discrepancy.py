"""Discrepancy workflow (issue 6): every library effect hidden and found, two at once, clean data,
an effect outside the library, and bad inputs.

Logs are simulated by the low-order truth (Pacejka tires, built-in driver) on the
identification road, written to CSV and read back strictly, as the command sees them;
camera noise is uniform +/-1 cm / +/-0.1 deg. The workflow never reads the true_* columns.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from tire_learning_env.cli import main
from tire_learning_env.discrepancy import EFFECT_NAMES, DiscrepancyConfig, analyze, get_effect, write_report
from tire_learning_env.discrepancy._model import N_OUT, THETA_NOMINAL, simulate_rows
from tire_learning_env.discrepancy.data import prepare
from tire_learning_env.discrepancy.effects import LIBRARY, theta_of
from tire_learning_env.discrepancy.residuals import ResidualModel
from tire_learning_env.scenarios import simulate_hidden
from tire_learning_env.io import LogFormatError, read_log, write_log
from tire_learning_env.params import ParameterError, TireParams, VehicleParams
from tire_learning_env.tires import axle_tires


def _log(tmp_path: Path, effects: dict, seed: int = 1, rate: float = 100.0, speed: str = "constant",
         duration: float = 60.0, name: str = "log.csv"):  # fmt: skip
    path = tmp_path / name
    write_log(path, simulate_hidden(effects, "identification", duration, camera_rate=rate, seed=seed, speed=speed))
    return read_log(path)


def _deviation_error(effect_name: str, fitted: dict, truth) -> float:
    """Largest relative error [-] of the fitted deviation from 'absent' against the true deviation
    (for the superelevation: of each parameter, rate and cap, against its true value)."""
    eff = get_effect(effect_name)
    if effect_name == "road_superelevation":
        return max(abs(fitted[p] - t) / abs(t) for p, t in zip(eff.parameters, truth))
    true_dev = eff.size(truth)
    fit_dev = eff.size([fitted[p] for p in eff.parameters])
    ref = np.max(np.abs(true_dev))
    return float(np.max(np.abs(fit_dev - true_dev)) / ref)


# one case per library effect, at a realistic size: (hidden effects, library truth, camera rate, speed profile)
EFFECT_CASES = {
    "tire_relaxation": ({"tire_relaxation": 0.5}, [0.5], 100.0, "constant"),
    "camera_latency": ({"camera_latency": 0.1}, [0.1], 100.0, "constant"),
    "road_bank": ({"road_bank": 0.02}, [0.02], 20.0, "constant"),
    "steering_offset": ({"steering_offset": 0.002}, [0.002], 20.0, "constant"),
    "camera_heading_bias": ({"camera_heading_bias": 0.003}, [0.003], 20.0, "constant"),
    "cornering_stiffness_scale": ({"cornering_stiffness_scale_front": 0.85}, [0.85, 1.0], 50.0, "constant"),
    "load_transfer": ({"load_transfer": 6.0}, [6.0], 50.0, "constant"),
    "crosswind": ({"crosswind": 300.0}, [300.0], 20.0, "constant"),
    "speed_dependent_stiffness": ({"speed_dependent_stiffness": 1e-4}, [1e-4], 50.0, "sine"),
    # issue 18: superelevation that follows the curves (capped at 4 deg), a drifting heading bias, a steering ratio
    "road_superelevation": ({"superelevation_rate": 20.0, "superelevation_cap": 0.07}, [20.0, 0.07], 50.0, "constant"),
    "camera_heading_drift": ({"camera_heading_drift": 5e-5}, [5e-5], 100.0, "constant"),
    "steering_ratio_error": ({"steering_ratio_error": 0.05}, [0.05], 20.0, "constant"),
}


def test_every_library_effect_has_a_test_case():
    assert set(EFFECT_CASES) == set(EFFECT_NAMES)


@pytest.mark.parametrize("name", list(EFFECT_CASES))
def test_hidden_effect_is_named_with_its_size_and_the_gap_closes(tmp_path, name):
    hidden, truth, rate, speed = EFFECT_CASES[name]
    log = _log(tmp_path, hidden, rate=rate, speed=speed)
    res = analyze(log, progress=False)
    assert res.verdict == "found", (res.verdict, [e["name"] for e in res.partial_effects])
    assert [e["name"] for e in res.effects] == [name]
    err = _deviation_error(name, res.effects[0]["parameters"], truth)
    assert err <= 0.20, (res.effects[0]["parameters"], truth)
    assert res.gap_ratio >= 3.0, res.gap_ratios()
    # after adding the effect the residual is at the noise level in every window
    assert not any(w["flagged"] for w in res.windows_after)


@pytest.mark.slow
@pytest.mark.parametrize("rate", [20.0, 30.0])
def test_superelevation_with_a_6_deg_cap_is_measured_where_the_log_reaches_the_cap(tmp_path, rate):
    """Issue 18: a 6 deg cap. At 20 rad m the identification road's curves (R 250 m) bank at most 0.080 rad, so
    the log bounds the cap from below only: the rate is measured, the fitted cap respects the bound and the report
    says the cap was not reached. At 30 rad m the cap binds in the curves and both parameters are measured."""
    cap = math.radians(6.0)
    log = _log(tmp_path, {"superelevation_rate": rate, "superelevation_cap": cap}, rate=50.0)
    res = analyze(log, progress=False)
    assert res.verdict == "found" and [e["name"] for e in res.effects] == ["road_superelevation"], res.verdict
    fit = res.effects[0]["parameters"]
    largest = rate * float(np.max(np.abs(log.sensors["kappa"])))
    assert abs(fit["rate"] - rate) <= 0.2 * rate, fit
    note = res.effects[0]["evidence"].get("note", "")
    if largest < cap:
        assert fit["cap"] >= 0.98 * largest and "not reached" in note, (fit, largest, note)
    else:
        assert abs(fit["cap"] - cap) <= 0.2 * cap and "not reached" not in note, (fit, note)


def test_two_effects_at_once_are_both_named(tmp_path):
    log = _log(tmp_path, {"tire_relaxation": 0.5, "crosswind": 300.0}, rate=50.0)
    res = analyze(log, progress=False)
    assert res.verdict == "found"
    found = {e["name"]: e["parameters"] for e in res.effects}
    assert set(found) == {"tire_relaxation", "crosswind"}
    assert _deviation_error("tire_relaxation", found["tire_relaxation"], [0.5]) <= 0.2
    assert _deviation_error("crosswind", found["crosswind"], [300.0]) <= 0.2
    assert res.gap_ratio >= 3.0


# seed 13 (100 Hz, like 11) is slow: seed 11 keeps a 100 Hz log in the default run, seed 12 the 20 Hz one, and
# test_clean_data_gives_none_in_19_of_20_seeds (slow) takes 20 more 100 Hz seeds
@pytest.mark.parametrize("seed", [11, 12, pytest.param(13, marks=pytest.mark.slow)])
def test_clean_data_gives_none(tmp_path, seed):
    res = analyze(_log(tmp_path, {}, seed=seed, rate=100.0 if seed % 2 else 20.0), progress=False)
    assert res.verdict == "none", [(k, v.get("lr")) for st in res.selection.steps for k, v in st.tried.items()]
    assert res.effects == [] and res.gap_ratio == pytest.approx(1.0)


@pytest.mark.slow
def test_clean_data_gives_none_in_19_of_20_seeds(tmp_path):
    verdicts = [analyze(_log(tmp_path, {}, seed=100 + s), progress=False).verdict for s in range(20)]
    assert verdicts.count("none") >= 19, verdicts


def test_effect_outside_the_library_is_unexplained_not_misnamed(tmp_path):
    log = _log(tmp_path, {"steering_nonlinearity": 100.0})
    res = analyze(log, progress=False)
    assert res.verdict == "unexplained"
    assert res.effects == []  # whatever helped partially is not given as the answer
    assert res.whiteness_after.p_value < res.config.whiteness_alpha


def test_without_imu_bank_and_crosswind_are_ambiguous_and_the_imu_separates_them(tmp_path):
    log = _log(tmp_path, {"road_bank": 0.02}, rate=50.0, duration=40.0)
    res = analyze(log, config=DiscrepancyConfig(use_imu=False), progress=False)
    assert res.verdict == "ambiguous" and res.effects == []
    names = [c["name"] for c in res.candidates]
    assert set(names) == {"road_bank", "crosswind"}
    # the same lateral force either way: m g sin(0.02) = 300 N
    for c in res.candidates:
        p = c["parameters"]
        force = p.get("force", -1529.95 * 9.81 * math.sin(p.get("bank_angle", 0.0)))
        assert abs(-force - 1529.95 * 9.81 * math.sin(0.02)) < 0.2 * 300.0
    sm = res.separating_manoeuvre
    assert sm["recipe"] == "imu" and sm["check_by_simulation"]["verified"] is True
    doc = res.to_json()
    assert doc["verdict"] == "ambiguous" and doc["candidates"] and doc["separating_manoeuvre"]["manoeuvre"]


def _confounded_log(tmp_path, speed: str):
    """Superelevation of 8 rad m (2.3 deg in a 200 m curve) on a road of steady curves, linear tires, a 20 Hz
    camera with +/-3 cm / +/-0.3 deg noise and no IMU: at constant speed it looks like a stiffer car."""
    cols = simulate_hidden({"superelevation_rate": 8.0}, "curves", 60.0, camera_rate=20.0, seed=1, speed=speed,
                           tire="linear", e1_noise=0.03, e2_noise=math.radians(0.3))  # fmt: skip
    cols = {k: v for k, v in cols.items() if k not in ("yaw_rate", "ay")}
    write_log(tmp_path / f"confounded_{speed}.csv", cols)
    return read_log(tmp_path / f"confounded_{speed}.csv")


def test_confounded_superelevation_is_ambiguous_and_the_speed_change_resolves_it(tmp_path):
    res = analyze(_confounded_log(tmp_path, "constant"), tire="linear", progress=False)
    assert res.verdict == "ambiguous", (res.verdict, [e["name"] for e in res.effects])
    names = [c["name"] for c in res.candidates]
    assert "road_superelevation" in names and "cornering_stiffness_scale" in names
    assert all(c["delta_bic_to_best"] < res.config.ambiguity_bic for c in res.candidates)
    sm = res.separating_manoeuvre
    assert sm["recipe"] == "speed"
    check = sm["check_by_simulation"]
    assert check["verified"] is True, check
    assert all(r["bic_advantage_of_truth"] > res.config.ambiguity_bic for r in check["runs"])
    # the same drive with the speed varying by +/-25 %: found, and the right one
    res = analyze(_confounded_log(tmp_path, "sine"), tire="linear", progress=False)
    assert res.verdict == "found" and [e["name"] for e in res.effects] == ["road_superelevation"]
    assert abs(res.effects[0]["parameters"]["rate"] - 8.0) <= 0.2 * 8.0


def test_fractional_frame_latency_is_named(tmp_path):
    # 30 ms at a 20 Hz camera: six tenths of a frame
    res = analyze(_log(tmp_path, {"camera_latency": 0.03}, rate=20.0), progress=False)
    assert res.verdict == "found" and [e["name"] for e in res.effects] == ["camera_latency"]
    assert abs(res.effects[0]["parameters"]["latency"] - 0.03) <= 0.2 * 0.03


def _sparse_log(tmp_path, kind: str, seed: int):
    """A clean log at 10 Hz (rows decimated from 100 Hz), with irregular rows (20-120 ms apart, camera and
    controller at 1 kHz) or at 15 Hz with 20 % of the frames dropped."""
    rng = np.random.default_rng(seed + 1000)
    if kind == "decimated_10hz":
        cols = simulate_hidden({}, "identification", 60.0, camera_rate=100.0, seed=seed)
        keep = np.zeros(len(cols["t"]), dtype=bool)
        keep[::10] = True
    elif kind == "non_uniform":
        cols = simulate_hidden({}, "identification", 60.0, camera_rate=1000.0, seed=seed, log_rate=1000.0)
        keep = np.zeros(len(cols["t"]), dtype=bool)
        keep[np.cumsum(rng.integers(20, 121, size=len(cols["t"]) // 20))[:-1].clip(0, len(keep) - 1)] = True
    else:
        cols = simulate_hidden({}, "identification", 60.0, camera_rate=15.0, seed=seed)
        frames = np.flatnonzero(np.isfinite(cols["e1"]))
        drop = frames[rng.random(len(frames)) < 0.2]
        cols["e1"][drop] = np.nan
        cols["e2"][drop] = np.nan
        keep = np.ones(len(cols["t"]), dtype=bool)
    path = tmp_path / f"{kind}_{seed}.csv"
    write_log(path, {k: v[keep] for k, v in cols.items()})
    return read_log(path)


@pytest.mark.parametrize("kind", ["decimated_10hz", "non_uniform", "dropped_frames_15hz"])
def test_clean_low_rate_and_non_uniform_logs_give_none(tmp_path, kind):
    res = analyze(_sparse_log(tmp_path, kind, seed=3), progress=False)
    assert res.verdict == "none", [(k, v.get("lr")) for st in res.selection.steps for k, v in st.tried.items()]


@pytest.mark.slow
@pytest.mark.parametrize("kind", [
    "decimated_10hz",
    pytest.param("non_uniform", marks=pytest.mark.xfail(
        strict=True, reason="known shortfall (docs/discrepancy.md section 7): 18 of 20 none, two whiteness "
        "p-values just below 0.01 after the input-noise whitening (the steering between rows reacts to the rows' own "
        "frame noise; the errors-in-variables model treats it as independent). Seed 109's own camera noise fails the "
        "test (p = 0.006), so every other seed must pass; modelling the reaction exactly leaves the reactions to the "
        "frames between the rows, which a camera latency takes (7/20). Strict, so a fix shows up")),
    "dropped_frames_15hz",
])  # fmt: skip
def test_clean_low_rate_logs_give_none_in_19_of_20_seeds(tmp_path, kind):
    verdicts = [analyze(_sparse_log(tmp_path, kind, seed=100 + s), progress=False).verdict for s in range(20)]
    assert verdicts.count("none") >= 19, verdicts


def test_command_writes_report_json_and_markdown(tmp_path, capsys):
    log = tmp_path / "log.csv"
    assert main(["simulate", "--road", "identification", "--duration", "30", "--noise", "uniform",
                 "--effect", "crosswind=300", "--seed", "3", "--out", str(log)]) == 0  # fmt: skip
    out = tmp_path / "report"
    assert main(["discrepancy", str(log), "--tire", "pacejka", "--out", str(out), "--no-progress"]) == 0
    doc = json.loads((out / "report.json").read_text())
    assert set(doc) >= {"verdict", "effects", "gap_before", "gap_after", "gap_ratio"}
    assert doc["verdict"] == "found"
    eff = doc["effects"][0]
    assert eff["name"] == "crosswind" and eff["units"] == {"force": "N"}
    assert abs(eff["parameters"]["force"] - 300.0) < 60.0
    assert set(eff["evidence"]) >= {"likelihood_ratio", "p_value", "delta_bic"}
    assert doc["gap_ratio"] >= 3.0 and doc["gap_before"]["units"]["e1"] == "m"
    md = (out / "report.md").read_text()
    assert "crosswind" in md and "Verdict" in md
    for fig in doc["figures"]:
        assert (out / fig).stat().st_size > 1000
    assert json.loads(capsys.readouterr().out.splitlines()[-2])["verdict"] == "found"


def test_workflow_never_reads_ground_truth(tmp_path):
    class Poisoned(dict):
        def _boom(self, *args, **kwargs):
            raise AssertionError("the discrepancy workflow read ground truth")

        __getitem__ = __iter__ = __contains__ = keys = values = items = get = _boom

    log = _log(tmp_path, {"crosswind": 300.0}, rate=20.0, duration=30.0)
    assert log.truth  # the CSV has true_* columns
    log.truth = Poisoned(log.truth)
    res = analyze(log, progress=False)
    assert [e["name"] for e in res.effects] == ["crosswind"]


def test_linear_nominal_tire_runs(tmp_path):
    # nominal linear tire on a Pacejka truth at small slip: only the options are exercised here
    res = analyze(_log(tmp_path, {"camera_heading_bias": 0.003}, rate=20.0, duration=30.0), tire="linear", progress=False)
    assert res.tire["kind"] == "linear"
    assert "camera_heading_bias" in [e["name"] for e in res.effects + res.partial_effects]


# ---------------------------------------------------------------- building blocks


def test_model_reproduces_the_truth_plant_without_effects():
    """From the true state, the compiled model follows the truth within a millimetre over a window."""
    cols = simulate_hidden({}, "identification", 20.0, noise="none")
    from tire_learning_env.io import DrivingLog

    sensors = {k: cols[k] for k in ("t", "vx", "delta", "kappa", "e1", "e2", "yaw_rate", "ay")}
    log = DrivingLog(sensors, {}, "camera", "sim")
    v = VehicleParams()
    data = prepare(log, DiscrepancyConfig())
    model = ResidualModel(data, v, *axle_tires(v, "pacejka", TireParams()), DiscrepancyConfig())
    for w in range(data.n_windows):
        j0, j1 = int(data.win_sim[w]), int(data.win_end[w])
        x0 = np.array([cols[k][j0] for k in ("true_e1", "true_e1_dot", "true_e2", "true_e2_dot")])
        traj = np.empty((j1 - j0 + 1, N_OUT))
        simulate_rows(x0, j0, j1, data.t, data.delta, data.dslope, data.vx, data.pdd, model.veh, model.tf, model.tr,
                      model.tabf, model.tabr, THETA_NOMINAL.copy(), 0.01, traj)  # fmt: skip
        assert np.max(np.abs(traj[:, 0] - cols["true_e1"][j0 : j1 + 1])) < 3e-3
        assert np.max(np.abs(traj[:, 4] - cols["yaw_rate"][j0 : j1 + 1])) < 1e-3


def test_windows_skip_gaps_and_standstill():
    from tire_learning_env.io import DrivingLog

    cols = simulate_hidden({}, "identification", 30.0, camera_rate=20.0)
    t, vx = cols["t"].copy(), cols["vx"].copy()
    t[t > 20.0] += 5.0  # a 5 s hole in the log
    vx[(t > 8.0) & (t < 10.0)] = 0.5  # a stretch at (almost) standstill
    sensors = {k: cols[k] for k in ("delta", "kappa", "e1", "e2", "yaw_rate", "ay")}
    sensors.update(t=t, vx=vx)
    data = prepare(DrivingLog(sensors, {}, "camera", "gappy"), DiscrepancyConfig())
    assert data.n_windows >= 5
    for w in range(data.n_windows):
        rows = np.arange(data.win_sim[w], data.win_end[w] + 1)
        assert np.all(vx[rows] >= 3.0)
        assert np.max(np.diff(t[rows])) < 0.25
    assert any("gap" in n for n in data.notes) and any("slower" in n for n in data.notes)


def test_effect_registry_round_trip_and_stable_names():
    assert EFFECT_NAMES == (
        "tire_relaxation", "camera_latency", "road_bank", "steering_offset", "camera_heading_bias",
        "cornering_stiffness_scale", "load_transfer", "crosswind", "speed_dependent_stiffness",
        "road_superelevation", "camera_heading_drift", "steering_ratio_error",
    )  # fmt: skip
    for e in LIBRARY:
        assert len(e.parameters) == len(e.units) == len(e.bounds) == len(e.theta_index)
        vals = np.array([0.5 * (lo + hi) for lo, hi in e.bounds])
        th = e.apply(THETA_NOMINAL, vals)
        np.testing.assert_allclose(e.values_in(th), vals)
        np.testing.assert_allclose(e.values_in(THETA_NOMINAL), e.absent)
    th = theta_of({"crosswind": [100.0], "cornering_stiffness_scale": [0.9, 1.1]})
    assert get_effect("crosswind").values_in(th)[0] == 100.0
    with pytest.raises(KeyError, match="unknown effect"):
        get_effect("gremlins")


# ---------------------------------------------------------------- bad input


def _write_csv(path: Path, header: str, rows: list[str]) -> Path:
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


def _good_rows(n: int = 200) -> list[str]:
    return [f"{0.01 * i:.2f},30,0.001,0.002,0.01,0.001" for i in range(n)]


@pytest.mark.parametrize(
    "header, rows, message",
    [
        ("t,vx,delta,kappa,e1", [f"{0.01 * i:.2f},30,0,0,0" for i in range(50)], "e2"),
        ("t,vx,delta,kappa,e1,e2", ["0,30,0,0,0,0", "0.02,30,0,0,0,0", "0.01,30,0,0,0,0"], "not strictly increasing"),
        ("t,vx,delta,kappa,e1,e2", [f"{0.01 * i:.2f},30,5.0,0,0,0" for i in range(50)], "delta"),
        ("t,vx,delta,kappa,e1,e2", [f"{0.01 * i:.2f},0,0,0,0,0" for i in range(50)], "vx <= 0"),
        ("t,vx,delta,kappa,e1,e2", _good_rows(200), "too short to fit anything"),
        ("t,vx,delta,yaw_rate,ay", [f"{0.01 * i:.2f},30,0,0,0" for i in range(500)], "camera log"),
    ],
    ids=["missing-column", "time-not-increasing", "delta-not-radians", "vx-not-positive", "too-short", "imu-only"],
)
def test_bad_log_is_a_clear_error(tmp_path, capsys, header, rows, message):
    path = _write_csv(tmp_path / "bad.csv", header, rows)
    assert main(["discrepancy", str(path), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert message in err, err
    assert not (tmp_path / "out").exists()


def test_too_short_log_error_from_the_library():
    from tire_learning_env.io import DrivingLog

    t = np.arange(0, 2.0, 0.01)
    s = {"t": t, "vx": np.full_like(t, 30.0), "delta": np.zeros_like(t), "kappa": np.zeros_like(t),
         "e1": np.zeros_like(t), "e2": np.zeros_like(t)}  # fmt: skip
    with pytest.raises(LogFormatError, match="too short to fit anything"):
        prepare(DrivingLog(s, {}, "camera", "short"), DiscrepancyConfig())


@pytest.mark.parametrize("content", ["{not json", '{"m": 1500, "wheels": 4}', None], ids=["bad-json", "unknown-key", "missing"])
def test_unreadable_vehicle_file_is_a_clear_error(tmp_path, capsys, content):
    log = _write_csv(tmp_path / "log.csv", "t,vx,delta,kappa,e1,e2", _good_rows(2000))
    vehicle = tmp_path / "vehicle.json"
    if content is not None:
        vehicle.write_text(content)
    assert main(["discrepancy", str(log), "--vehicle", str(vehicle), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "vehicle" in err.lower() or "VehicleParams" in err, err


def test_existing_output_is_not_clobbered_on_failure(tmp_path, monkeypatch):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("previous results")
    bad = _write_csv(tmp_path / "bad.csv", "t,vx,delta,kappa,e1", ["0,30,0,0,0"])
    assert main(["discrepancy", str(bad), "--out", str(out), "--no-progress"]) == 2
    assert (out / "keep.txt").read_text() == "previous results"
    # a folder the package did not write is refused, never replaced
    res = analyze(_log(tmp_path, {}, rate=20.0, duration=20.0), progress=False)
    from tire_learning_env.io import OutputPathError

    with pytest.raises(OutputPathError, match="not written by"):
        write_report(res, out)
    assert sorted(p.name for p in out.iterdir()) == ["keep.txt"]
    # a failure half-way through rewriting a report folder leaves it as it was
    mine = tmp_path / "mine"
    write_report(res, mine)
    before = sorted(p.name for p in mine.iterdir())
    from tire_learning_env.discrepancy import plots

    def boom(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(plots, "plot_whiteness", boom)
    with pytest.raises(RuntimeError, match="disk full"):
        write_report(res, mine)
    assert sorted(p.name for p in mine.iterdir()) == before
    assert not [p for p in tmp_path.iterdir() if p.name.startswith((".out", ".mine"))]  # no temporary left behind
    monkeypatch.undo()
    write_report(res, mine)  # the package's own folder is replaced
    assert (mine / "report.json").exists()


def test_config_rejects_unknown_keys():
    with pytest.raises(ParameterError, match="unknown key"):
        DiscrepancyConfig.from_dict({"window": 3.0, "colour": "red"})
    with pytest.raises(ParameterError):
        DiscrepancyConfig(alpha=2.0)
    assert math.isclose(DiscrepancyConfig().window, 3.0)


def test_a_camera_ahead_of_the_cg_is_part_of_the_model_not_a_missing_effect(tmp_path):
    """A camera 1.5 m ahead (the simulator's, from the vehicle's camera_x): with camera_x in the vehicle file the
    clean log has no discrepancy and a hidden latency is named and sized; read as the CG's, the camera's position
    is itself what the comparison finds."""
    from tire_learning_env.params import VehicleParams

    ahead = VehicleParams(camera_x=1.5)

    def log_ahead(effects, name):
        path = tmp_path / name
        write_log(path, simulate_hidden(effects, "identification", 30.0, camera_rate=50.0, seed=1, vehicle=ahead))
        return read_log(path)

    clean = log_ahead({}, "clean.csv")
    told = analyze(clean, vehicle=ahead, progress=False)
    assert told.verdict == "none", (told.verdict, [e["name"] for e in told.effects])
    at_cg = analyze(clean, vehicle=VehicleParams(), progress=False)
    assert at_cg.verdict != "none"
    late = analyze(log_ahead({"camera_latency": 0.05}, "late.csv"), vehicle=ahead, progress=False)
    assert [e["name"] for e in late.effects] == ["camera_latency"], late.verdict
    assert late.effects[0]["parameters"]["latency"] == pytest.approx(0.05, rel=0.2)
