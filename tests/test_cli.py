import json
import subprocess
import sys

import pytest

from tire_learning_env.cli import main


def test_simulate_then_estimate_a_camera_log(tmp_path, capsys):
    log = tmp_path / "lc.csv"
    assert main(["simulate", "--road", "lane_changes", "--duration", "30", "--camera-rate", "20", "--out", str(log)]) == 0
    out = tmp_path / "est"
    assert main(["estimate", str(log), "--out", str(out)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["lmi"]["certified"]
    assert metrics["ground_truth"]["tire_curve_nrmse"]["front"] < 0.02
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
    out = tmp_path / "s1"
    assert main(["reproduce", "--study", "1", "--out", str(out)]) == 0
    m = json.loads((out / "metrics.json").read_text())
    for key in ("state_rmse", "slip_rmse_deg", "force_nonlinear_nrmse", "tire_curve_nrmse", "excited_slip_range_deg",
                "cornering_stiffness", "lmi", "runtime_s"):
        assert key in m
    for fig in ("path_and_steering", "states", "slip_angles", "nonlinear_force", "weights", "tire_curves"):
        assert (out / f"{fig}.png").stat().st_size > 1000


def test_console_script_is_installed():
    res = subprocess.run([sys.executable, "-m", "tire_learning_env.cli", "--help"], capture_output=True, text=True)
    assert res.returncode == 0 and "simulate" in res.stdout and "reproduce" in res.stdout
