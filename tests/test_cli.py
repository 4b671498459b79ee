import json
import subprocess
import sys

import numpy as np
import pytest

from tire_learning_env.cli import main
from tire_learning_env.params import ParameterError


def test_simulate_then_estimate_a_camera_log(tmp_path, capsys):
    log = tmp_path / "lc.csv"
    assert main(["simulate", "--road", "lane_changes", "--duration", "30", "--camera-rate", "20", "--out", str(log)]) == 0
    out = tmp_path / "est"
    assert main(["estimate", str(log), "--out", str(out)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["lmi"]["certified"]
    assert metrics["ground_truth"]["tire_curve_nrmse"]["front"] < 0.02
    # the package's own single-track truth: no model error, so no evidence and no warning on the line
    assert metrics["summary"]["model_error_detected"] is False and metrics["summary"]["model_error_evidence"] is None
    assert "MODEL ERROR" not in capsys.readouterr().out
    header = (out / "estimates.csv").read_text().splitlines()[0]
    assert header.startswith("t,e1_hat,e1_dot_hat,e2_hat,e2_dot_hat,alpha_f_hat,alpha_r_hat,Fyf_hat,Fyr_hat")
    assert (out / "tire_curves.png").stat().st_size > 1000


def test_errors_name_the_problem_and_return_2(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,vx,delta,kappa,e1\n0,30,0,0,0\n1,30,0,0,0\n")
    assert main(["estimate", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "'e2'" in capsys.readouterr().err
    vehicle = tmp_path / "v.json"
    vehicle.write_text('{"m": 1500, "mass": 3}')
    assert main(["simulate", "--duration", "1", "--vehicle", str(vehicle), "--out", str(tmp_path / "x.csv")]) == 2
    assert "mass" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_reproduce_study1_writes_metrics_and_figures(tmp_path):
    # 10 s of the study's 60 (the files written do not depend on the length; the full study's targets:
    # test_observer.py::test_study1_meets_the_targets and test_output_safety's reproduce test, both slow).
    # 10 s, not 20: the same files and keys (stiffness read -0.07 / -0.00 %), 13 s instead of 21 s
    out = tmp_path / "s1"
    assert main(["reproduce", "--study", "1", "--duration", "10", "--out", str(out)]) == 0
    m = json.loads((out / "metrics.json").read_text())
    for key in ("state_rmse", "slip_rmse_deg", "force_nonlinear_nrmse", "tire_curve_nrmse", "excited_slip_range_deg",
                "cornering_stiffness", "lmi", "runtime_s"):
        assert key in m
    for fig in ("path_and_steering", "states", "slip_angles", "nonlinear_force", "weights", "tire_curves"):
        assert (out / f"{fig}.png").stat().st_size > 1000


def test_console_script_is_installed():
    res = subprocess.run([sys.executable, "-m", "tire_learning_env.cli", "--help"], capture_output=True, text=True)
    assert res.returncode == 0 and "simulate" in res.stdout and "reproduce" in res.stdout


# --- issue 17 item 6: one CLI grammar --------------------------------------------------------------

COMMANDS = ("simulate", "estimate", "discrepancy", "reproduce")


def _help(command: str, capsys) -> str:
    """The help text on one line (no line wrapping, which would split HALF-WIDTH)."""
    mp = pytest.MonkeyPatch()
    mp.setenv("COLUMNS", "100000")
    try:
        with pytest.raises(SystemExit):
            main([command, "--help"])
    finally:
        mp.undo()
    return " ".join(capsys.readouterr().out.split())


def test_every_command_has_seed_quiet_and_no_progress(capsys):
    for command in COMMANDS:
        text = _help(command, capsys)
        for option in ("--seed", "--quiet", "--no-progress", "--overwrite"):
            assert option in text, (command, option)
    assert "no effect: 'estimate' is deterministic" in _help("estimate", capsys)


def test_camera_noise_help_states_units_and_std_or_half_width(capsys):
    simulate = _help("simulate", capsys)
    for option in ("--e1-noise E1_NOISE e1 noise [m]", "--e2-noise E2_NOISE e2 noise [rad]"):
        assert option in simulate
    assert simulate.count("HALF-WIDTH for --noise uniform, the STANDARD DEVIATION for --noise gaussian") == 2
    assert "paper = uniform, HALF-WIDTH 1 cm and 1 deg" in simulate
    estimate = _help("estimate", capsys)
    assert "camera noise STANDARD DEVIATION (not a half-width), e1 [m] and e2 [rad]" in estimate
    assert "h/sqrt(3)" in estimate
    reproduce = _help("reproduce", capsys)
    assert "paper = uniform, HALF-WIDTH 1 cm and 1 deg (STANDARD DEVIATION 0.577 cm, 0.577 deg" in reproduce


def test_quiet_silences_stdout_but_never_errors(tmp_path, capsys):
    log = tmp_path / "a.csv"
    assert main(["simulate", "--duration", "1", "--out", str(log), "--quiet"]) == 0
    captured = capsys.readouterr()
    assert captured.out == "" and log.read_text().startswith("t,")
    assert main(["simulate", "--duration", "1", "--out", str(log)]) == 2  # exists, no --overwrite
    assert main(["simulate", "--duration", "1", "--out", str(log), "--quiet"]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("error:") == 2
    assert main(["simulate", "--duration", "1", "--out", str(tmp_path / "b.csv")]) == 0
    assert "wrote" in capsys.readouterr().out  # without --quiet the line is there


def test_seed_is_accepted_everywhere_and_seeds_numpy(tmp_path, capsys):
    import numpy as np

    from tire_learning_env.cli import build_parser

    parser = build_parser()
    for argv in (["simulate", "--out", "x.csv"], ["estimate", "x.csv", "--out", "o"],
                 ["discrepancy", "x.csv", "--out", "o"], ["reproduce", "--study", "1", "--out", "o"]):
        assert parser.parse_args(argv + ["--seed", "7"]).seed == 7
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    for path in (a, b):
        assert main(["simulate", "--duration", "2", "--noise", "paper", "--seed", "5", "--out", str(path), "-q"]) == 0
        draw = np.random.random()
    assert a.read_text() == b.read_text()
    np.random.seed(5)
    assert draw == np.random.random()


def test_reproduce_all_refuses_options_it_would_ignore(tmp_path, capsys, monkeypatch):
    started = []
    monkeypatch.setattr("tire_learning_env.report.reproduce_all", lambda *a, **k: started.append(1))
    assert main(["reproduce", "--all", "--seed", "3", "--out", str(tmp_path / "r")]) == 2
    assert "--seed apply with --study N only" in capsys.readouterr().err and not started


# --- issue 17 item 3: the vehicle used and its source in every report --------------------------------


VEHICLE = {"m": 1500.0, "Iz": 2900.0, "lf": 1.2, "lr": 1.6, "Cf": 80000.0, "Cr": 90000.0}


@pytest.fixture(scope="module")
def short_log(tmp_path_factory):
    folder = tmp_path_factory.mktemp("vehicle_source")
    log = folder / "lc.csv"
    assert main(["simulate", "--road", "lane_changes", "--duration", "20", "--camera-rate", "20", "--noise", "paper",
                 "--out", str(log), "-q"]) == 0
    return log


def test_estimate_metrics_name_the_vehicle_and_its_source(tmp_path, short_log):
    vehicle = tmp_path / "v.json"
    vehicle.write_text(json.dumps(VEHICLE))
    out = tmp_path / "cam"
    assert main(["estimate", str(short_log), "--out", str(out), "--vehicle", str(vehicle), "-q"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["calibration"]["vehicle_source"] == str(vehicle) and m["calibration"]["vehicle"]["m"] == 1500.0


def test_estimate_on_an_imu_log_names_the_vehicle_and_its_source(tmp_path, short_log):
    import csv

    rows = list(csv.DictReader(short_log.open()))
    keep = [c for c in rows[0] if c not in ("e1", "e2", "kappa")]
    imu = tmp_path / "imu.csv"
    with imu.open("w", newline="") as f:
        w = csv.DictWriter(f, keep, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    assert "yaw_rate" in keep and "ay" in keep
    for args, source in (([], "built-in default"), (["--vehicle", "VEH"], "VEH")):
        vehicle = tmp_path / "v.json"
        vehicle.write_text(json.dumps(VEHICLE))
        args = [str(vehicle) if a == "VEH" else a for a in args]
        out = tmp_path / f"imu_out{len(args)}"
        assert main(["estimate", str(imu), "--out", str(out), "-q"] + args) == 0
        m = json.loads((out / "metrics.json").read_text())
        assert m["log_kind"] == "imu" and "m" in m["vehicle"]
        assert m["vehicle_source"].startswith(str(vehicle) if args else source)


def test_discrepancy_report_names_the_vehicle_and_its_source(tmp_path, short_log):
    out = tmp_path / "disc"
    assert main(["discrepancy", str(short_log), "--out", str(out), "--tire", "linear", "--no-progress", "-q"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["nominal_model"]["vehicle"]["m"] > 0
    assert report["nominal_model"]["vehicle_source"].startswith("built-in default")
    assert "built-in default" in (out / "report.md").read_text()


def test_one_noise_grammar_on_every_command(tmp_path, capsys):
    """simulate, reproduce and estimate take the same --noise KIND --e1-noise --e2-noise (issue 17)."""
    for command in ("simulate", "reproduce", "estimate"):
        text = _help(command, capsys)
        assert "--noise {" in text and "--e1-noise E1_NOISE e1 noise [m]" in text and "--e2-noise E2_NOISE e2 noise [rad]" in text
    from tire_learning_env.commands.estimate import config_from_args
    from tire_learning_env.cli import build_parser

    parser = build_parser()
    args = parser.parse_args(["estimate", "x.csv", "--out", str(tmp_path / "o"), "--noise", "uniform",
                              "--e1-noise", "0.02", "--e2-noise", "0.01"])  # fmt: skip
    cfg = config_from_args(args, "camera")
    np.testing.assert_allclose(cfg.camera_noise, (0.02 / 3**0.5, 0.01 / 3**0.5))  # half-widths -> std
    args = parser.parse_args(["estimate", "x.csv", "--out", str(tmp_path / "o")])
    assert config_from_args(args, "camera").camera_noise is None  # default: measured from the log
    args = parser.parse_args(["estimate", "x.csv", "--out", str(tmp_path / "o"), "--noise", "paper",
                              "--camera-noise", "0.01", "0.01"])  # fmt: skip
    with pytest.raises(ParameterError, match="not both"):
        config_from_args(args, "camera")


def test_estimate_without_the_offline_pass_scores_the_causal_one(tmp_path, short_log):
    """--no-offline on a log with truth columns: the causal scores are the reported ground truth
    (they were once stored inside themselves: "Circular reference detected" on writing)."""
    out = tmp_path / "online"
    assert main(["estimate", str(short_log), "--out", str(out), "--no-offline", "-q"]) == 0
    gt = json.loads((out / "metrics.json").read_text())["ground_truth"]
    assert "online" not in gt and set(gt["stiffness_inside_2sigma_band"]) == {"front", "rear"}


# --- issue 16: the fused run writes the linear KF baseline and its reference scores -------------------


def _columns(path) -> dict:
    import csv

    rows = list(csv.DictReader(path.open()))
    return {c: np.array([float(r[c]) if r[c] != "" else np.nan for r in rows]) for c in rows[0]}


def test_fused_estimate_writes_the_imu_paths_kf_baseline_and_reference_scores(tmp_path, short_log, capsys):
    """--sensors both: estimates.csv holds beta_kf (the IMU-only path's KF, the same numbers on the same rows,
    the vehicle file's imu_x applied), metrics.json the sideslip RMSE of the fused estimate and the KF against
    the log's true_beta (recomputed here from the written columns), with the comparison flagged; a camera-only
    run writes none of it. Before 2026-11-29 the fused run wrote neither."""
    import csv

    vehicle = tmp_path / "v.json"
    vehicle.write_text(json.dumps(dict(VEHICLE, imu_x=0.5)))
    fused = tmp_path / "fused"
    capsys.readouterr()
    assert main(["estimate", str(short_log), "--out", str(fused), "--sensors", "both", "--latency", "0",
                 "--vehicle", str(vehicle)]) == 0  # fmt: skip
    printed = capsys.readouterr().out
    est, log = _columns(fused / "estimates.csv"), _columns(short_log)
    m = json.loads((fused / "metrics.json").read_text())
    assert {"beta_hat", "beta_observer_online", "beta_kf"} <= set(est) and set(m["estimates_csv"]) == {
        "beta_hat", "beta_observer_online", "beta_kf"}
    assert m["baseline_linear_kf"]["cleaning"]["imu_position"]["imu_x_m"] == 0.5
    ref = m["reference_scores"]
    t, beta_ref = log["t"], log["true_beta"]
    mid = 0.5 * (t[0] + t[-1])
    parts = {"whole": np.ones(len(t), bool), "first_half": t < mid, "second_half": t >= mid}
    for key, column in (("observer_refined", "beta_hat"), ("observer_online_causal", "beta_observer_online"),
                        ("linear_kf_baseline", "beta_kf")):  # fmt: skip
        for part, sel in parts.items():
            rmse = np.degrees(np.sqrt(np.mean((est[column][sel] - beta_ref[sel]) ** 2)))
            assert ref["sideslip_rmse_deg"][key][part] == pytest.approx(rmse, rel=1e-6), (key, part)
    rep, kf = ref["sideslip_rmse_deg"]["observer_refined"], ref["sideslip_rmse_deg"]["linear_kf_baseline"]
    cmp = ref["reported_vs_linear_kf"]
    assert cmp["reported"] == "observer_refined"
    assert cmp["reported_worse_than_linear_kf"] == {p: rep[p] > kf[p] for p in parts}
    assert ref["targets"]["reported_no_worse_than_linear_kf"] == (rep["whole"] <= kf["whole"])
    assert f"linear_kf_baseline {kf['whole']:.3f}" in printed and "beta_kf" in printed
    # the IMU-only path on the same rows (camera columns dropped) writes the same KF
    rows = list(csv.DictReader(short_log.open()))
    imu = tmp_path / "imu.csv"
    with imu.open("w", newline="") as f:
        w = csv.DictWriter(f, [c for c in rows[0] if c not in ("e1", "e2", "kappa")], extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    assert main(["estimate", str(imu), "--out", str(tmp_path / "imu"), "--vehicle", str(vehicle), "--no-offline",
                 "-q"]) == 0  # fmt: skip
    np.testing.assert_array_equal(_columns(tmp_path / "imu" / "estimates.csv")["beta_kf"], est["beta_kf"])
    # camera only: none of it
    cam = tmp_path / "cam"
    assert main(["estimate", str(short_log), "--out", str(cam), "--latency", "0", "-q"]) == 0
    assert "beta_kf" not in _columns(cam / "estimates.csv")
    assert not {"reference_scores", "baseline_linear_kf"} & set(json.loads((cam / "metrics.json").read_text()))
