"""The Ray runner and ``tire-learning batch``: failures as rows, streaming, resume, worker/node death."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ray = pytest.importorskip("ray")
pytest.importorskip("pyarrow")

from tire_learning_env.cli import main  # noqa: E402
from tire_learning_env.fleet import ResultStore, run_items  # noqa: E402
from tire_learning_env.fleet.batch import expand_logs, output_names  # noqa: E402


@pytest.fixture(scope="module")
def local_ray():
    """One local Ray instance (2 CPUs, no dashboard) for the module; run_items uses it and leaves it running."""
    from tire_learning_env.fleet import THREAD_ENV

    # the workers import this test module to unpickle its functions: put tests/ on their path
    env = dict(THREAD_ENV, PYTHONPATH=os.pathsep.join([str(Path(__file__).parent), os.environ.get("PYTHONPATH", "")]))
    if not ray.is_initialized():
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False,
                 object_store_memory=128 * 1024**2, runtime_env={"env_vars": env})  # fmt: skip
    yield
    ray.shutdown()


def _square(x):
    if x == 3:
        raise ValueError("item 3 is corrupt\n(second line)")
    return {"x": x, "square": x * x, "pid": os.getpid()}


def test_run_items_failure_is_a_row_and_resume_skips_done(local_ray, tmp_path):
    store = tmp_path / "store.jsonl"
    seen = []
    res = run_items(_square, list(range(6)), store=store, workers=2, progress=False, on_result=seen.append)
    assert [r.key for r in res] == [str(i) for i in range(6)]
    assert [r.status for r in res] == ["ok", "ok", "ok", "failed", "ok", "ok"]
    assert res[3].error == "ValueError: item 3 is corrupt (second line)" and res[3].result is None
    assert [r.result["square"] for r in res if r.status == "ok"] == [0, 1, 4, 16, 25]
    assert all(r.result["pid"] != os.getpid() and r.node for r in res if r.status == "ok")  # ran in Ray workers
    assert sorted(r.key for r in seen) == [str(i) for i in range(6)]
    assert len(store.read_text().splitlines()) == 6
    # re-run: done items are skipped with their stored result; the failed one runs again
    res2 = run_items(_square, list(range(6)), store=store, workers=2, progress=False)
    assert [r.status for r in res2] == ["skipped", "skipped", "skipped", "failed", "skipped", "skipped"]
    assert res2[4].result["square"] == 16
    # a changed fingerprint re-runs the item
    res3 = run_items(_square, list(range(6)), store=store, fingerprints=["a"] + [""] * 5, engine="serial", progress=False)
    assert res3[0].status == "ok" and res3[1].status == "skipped"


def _die_once(arg):
    marker, how = arg
    if how == "always" or not os.path.exists(marker):
        Path(marker).write_text("died")
        os._exit(1)  # the worker process dies, as if killed
    return "survived"


def test_dead_worker_is_retried_then_recorded(local_ray, tmp_path):
    items = [(str(tmp_path / "a"), "once"), (str(tmp_path / "b"), "always")]
    res = run_items(_die_once, items, store=tmp_path / "s.jsonl", max_retries=1, progress=False)
    assert res[0].status == "ok" and res[0].result == "survived"
    assert res[1].status == "failed" and "worker or node lost after 2 attempts" in res[1].error
    assert len(ResultStore(tmp_path / "s.jsonl").load()) == 2


def test_store_ignores_a_line_cut_by_a_kill(tmp_path):
    store = ResultStore(tmp_path / "s.jsonl")
    res = run_items(lambda x: x + 1, [1, 2], store=store, engine="serial", progress=False)
    store.close()
    with open(tmp_path / "s.jsonl", "a") as fh:
        fh.write('{"key": "2", "status": "ok", "res')  # a kill in the middle of a write
    loaded = ResultStore(tmp_path / "s.jsonl").load()
    assert sorted(loaded) == ["0", "1"] and loaded["1"].result == 3
    res = run_items(lambda x: x + 1, [1, 2, 3], store=tmp_path / "s.jsonl", engine="serial", progress=False)
    assert [r.status for r in res] == ["skipped", "skipped", "ok"]
    assert len(ResultStore(tmp_path / "s.jsonl").load()) == 3
    with pytest.raises(Exception, match="duplicate item keys"):
        run_items(lambda x: x, [1, 2], keys=["a", "a"], engine="serial")


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """Two tiny camera logs (CSV and Parquet) and two broken ones (bad cell, junk MF4)."""
    from tire_learning_env.formats import write_logger_log
    from tire_learning_env.io import write_log
    from tire_learning_env.params import CameraParams
    from tire_learning_env.simulation import simulate

    folder = tmp_path_factory.mktemp("fleet")
    (folder / "car_b").mkdir()
    # the CSV drive long enough (16 s) to identify its stiffness, its latency's uncertainty included; 8 s is not
    for seed, path, duration in ((1, folder / "drive.csv", 16.0), (2, folder / "car_b" / "drive.parquet", 8.0)):
        log = simulate("study1", duration, camera=CameraParams.paper_noise(rate=20.0), physics_rate=1000.0, seed=seed)
        cols = log.to_columns()
        keep = np.zeros(len(cols["t"]), dtype=bool)
        keep[::20] = True
        keep |= np.isfinite(cols["e1"])
        cols = {k: v[keep] for k, v in cols.items()}
        if path.suffix == ".csv":
            write_log(path, cols)
        else:
            write_logger_log(path, cols, channel_map=path.with_name("drive.channels.yaml"))
    (folder / "broken.csv").write_text("t,vx,delta,kappa,e1,e2\n0,20,0,0,0,0\n0.1,20,x,0,0,0\n")
    (folder / "junk.mf4").write_bytes(b"\x00not an MDF file" * 50)
    return folder


def _summary(out: Path) -> dict[str, dict]:
    with open(out / "summary.csv", newline="") as fh:
        return {row["name"]: row for row in csv.DictReader(fh)}


def test_batch_on_local_ray_with_broken_logs_and_resume(local_ray, fleet, tmp_path, capsys):
    out = tmp_path / "batch"
    argv = ["batch", str(fleet), "--out", str(out), "--workers", "2", "--no-progress", "--args=--sensors camera"]
    assert main(argv) == 1  # a log failed: exit code 1, every other log finished
    rows = _summary(out)
    # the same stem in two folders: each named <folder>__<stem>
    assert set(rows) == {"broken", "junk", f"{fleet.name}__drive", "car_b__drive"}
    ok = {k: r for k, r in rows.items() if k.endswith("drive")}
    assert all(r["status"] == "ok" and r["error"] == "" for r in ok.values())
    assert rows["broken"]["status"] == "failed" and "column 'delta', line 3: 'x' is not a number" in rows["broken"]["error"]
    assert rows["junk"]["status"] == "failed" and "not a readable MF4 file" in rows["junk"]["error"]
    for name, r in ok.items():
        assert r["kind"] == "camera" and r["verdict"] in ("identified", "not_identifiable")
        lo, hi = (float(r[f"stiffness_front{s}_N_per_rad"]) for s in ("_lo", "_hi"))
        assert 5e4 < lo < hi < 2e5  # the band is always reported
        if r["stiffness_front_N_per_rad"]:  # a value only where the estimator names one
            assert lo < float(r["stiffness_front_N_per_rad"]) < hi
        assert 0 <= float(r["curve_nrmse_front"]) < 1.0  # the simulated logs carry truth
        folder = out / name
        assert {"metrics.json", "estimates.csv", "tire_curves.csv", "tire_curves.png",
                ".tire_learning_manifest.json"} <= {p.name for p in folder.iterdir()}  # fmt: skip
        metrics = json.loads((folder / "metrics.json").read_text())
        assert metrics["summary"]["verdict"] == r["verdict"]
        assert metrics["summary"]["stiffness_front_2sigma_N_per_rad"] == pytest.approx([lo, hi], rel=1e-5)
    assert any(r["stiffness_front_N_per_rad"] for r in ok.values())
    import pyarrow.parquet as pq

    table = pq.read_table(out / "summary.parquet").to_pydict()
    assert sorted(table["name"]) == sorted(rows)
    assert (out / "fleet.png").stat().st_size > 1000
    with open(out / "vehicles.csv", newline="") as fh:
        pooled = list(csv.DictReader(fh))
    assert {(v["vehicle"], v["axle"]) for v in pooled} == {(".", "front"), (".", "rear"), ("car_b", "front"),
                                                           ("car_b", "rear")}  # fmt: skip
    assert rows["car_b__drive"]["vehicle"] == "car_b"
    assert "failed: broken" in capsys.readouterr().err
    first = {k: r["stiffness_front_N_per_rad"] for k, r in ok.items()}

    # re-run: the done logs are skipped (their figures kept), the failed ones run again
    assert main(argv) == 1
    rows = _summary(out)
    assert {k: r["status"] for k, r in rows.items() if k.endswith("drive")} == dict.fromkeys(ok, "skipped")
    assert {k: r["stiffness_front_N_per_rad"] for k, r in rows.items() if k.endswith("drive")} == first
    assert rows["broken"]["status"] == "failed"

    # a batch folder of another command is refused in one line
    assert main(["batch", str(fleet / "drive.csv"), "--out", str(out), "--command", "discrepancy"]) == 2
    assert "holds a batch of 'estimate'" in capsys.readouterr().err


def test_killed_batch_loses_no_finished_row(fleet, tmp_path):
    """SIGKILL the batch command after its first result: that row is on disk and is not re-run."""
    out = tmp_path / "killed"
    logs = [str(fleet / "drive.csv"), str(fleet / "broken.csv"), str(fleet / "junk.mf4")]  # serial: in this order
    env = dict(os.environ, OMP_NUM_THREADS="1")
    proc = subprocess.Popen([sys.executable, "-m", "tire_learning_env.cli", "batch", *logs, "--out", str(out),
                             "--serial", "--no-progress", "--args=--sensors camera"],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    store = out / "batch_results.jsonl"
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None:
        if store.exists() and len(store.read_text().splitlines()) >= 1:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    finished = ResultStore(store).load()
    assert finished["drive"].status == "ok"
    rows = _summary(out)
    assert set(finished) <= set(rows)  # every finished result is also a row of summary.csv
    assert main(["batch", *logs, "--out", str(out), "--serial", "--no-progress", "--args=--sensors camera"]) == 1
    rows = _summary(out)
    assert set(rows) == {"broken", "junk", "drive"}
    assert rows["drive"]["status"] == "skipped"  # finished before the kill: not run again
    assert rows["broken"]["status"] == "failed"


def test_batch_errors_are_one_line(tmp_path, capsys):
    assert main(["batch", str(tmp_path / "nope.csv"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"tire-learning batch: error: no such log or folder: {tmp_path / 'nope.csv'}"
    (tmp_path / "a.csv").write_text("t\n")
    assert main(["batch", str(tmp_path / "a.csv"), "--out", str(tmp_path / "o"), "--args=--tire linear"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "not valid for estimate" in err and "--tire" in err
    import socket

    with socket.socket() as sock:  # a port nothing listens on
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    (tmp_path / "b.csv").write_text("t\n")
    assert main(["batch", str(tmp_path / "b.csv"), "--out", str(tmp_path / "o2"), "--address", f"127.0.0.1:{port}"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"cannot reach the Ray cluster at 127.0.0.1:{port}" in err


def test_expand_logs_and_names(tmp_path):
    for p in ("a/x.csv", "b/x.mf4", "b/y.parquet", "b/.hidden/z.csv", "c/notes.txt", "b/bag1/metadata.yaml",
              "b/bag1/bag1_0.mcap"):  # fmt: skip
        (tmp_path / p).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / p).write_text("")
    logs = expand_logs([tmp_path / "a", str(tmp_path / "b" / "*.parquet"), tmp_path / "b"])
    # a ROS 2 bag folder is one log (its .mcap is not listed apart)
    assert [p.relative_to(tmp_path).as_posix() for p in logs] == ["a/x.csv", "b/y.parquet", "b/bag1", "b/x.mf4"]
    assert output_names(logs) == ["a__x", "y", "bag1", "b__x"]
    with pytest.raises(Exception, match="holds no log"):
        expand_logs([tmp_path / "c"])


@pytest.mark.slow
def test_multi_node_kill_loses_no_result(tmp_path):
    """Three raylets on one machine (ray.cluster_utils.Cluster); a worker node is killed mid-batch."""
    code = ("import json, sys; from tire_learning_env.fleet.cluster import kill_node_run; "
            "print('RESULT' + json.dumps(kill_node_run(sys.argv[1], n_items=10, task_s=1.0)))")  # fmt: skip
    proc = subprocess.run([sys.executable, "-c", code, str(tmp_path / "store.jsonl")], capture_output=True, text=True,
                          timeout=600, env=dict(os.environ, OMP_NUM_THREADS="1"))  # fmt: skip
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT")]
    assert line, proc.stderr[-2000:]
    r = json.loads(line[0][6:])
    assert r["killed"] and r["recorded_before_kill"] >= 3
    assert r["lost"] == 0 and r["ok"] == 10 and r["failed"] == 0 and r["stored_records"] == 10
    # the dead node finishes nothing after the kill: its unfinished tasks ran elsewhere (a result it finished
    # just before dying may still reach the driver after the kill, which is why collection time is not the test)
    assert r["finished_after_kill_on_killed_node"] == 0


# -- agents/train.py: several seeds as tasks of the same runner, resumable ---------------------
AGENTS = Path(__file__).resolve().parents[1] / "agents"


def _tiny_config(tmp_path: Path) -> Path:
    cfg = {"algo": "PPO", "n_envs": 1, "vec_env": "dummy", "total_timesteps": 32, "env_kwargs": {"record": False},
           "policy_kwargs": {"net_arch": [8]}, "algo_kwargs": {"n_steps": 16, "batch_size": 16, "n_epochs": 1}}  # fmt: skip
    path = tmp_path / "tiny_ppo.json"
    path.write_text(json.dumps(cfg))
    return path


def _train_script():
    import importlib.util

    spec = importlib.util.spec_from_file_location("agents_train_under_test", AGENTS / "train.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _sweep_and_resume(tmp_path: Path, engine_args: list[str]) -> None:
    train = _train_script()
    cfg = _tiny_config(tmp_path)
    out = tmp_path / "sweep"
    argv = ["--config", str(cfg), "--seeds", "0", "1", "--out", str(out), "--no-progress", *engine_args]
    assert train.main(argv) == 0
    runs = {r.key: r for r in ResultStore(out / "runs.jsonl").load().values()}
    assert set(runs) == {"tiny_ppo_seed0", "tiny_ppo_seed1"} and all(r.status == "ok" for r in runs.values())
    for seed in (0, 1):
        run = json.loads((out / f"tiny_ppo_seed{seed}" / "run.json").read_text())
        assert run["seed"] == seed and run["timesteps"] >= 32
        assert (out / f"tiny_ppo_seed{seed}" / "final_model.zip").is_file()
    mtime = (out / "tiny_ppo_seed0" / "final_model.zip").stat().st_mtime_ns
    # resume: the finished runs are skipped (not retrained); a new seed runs
    assert train.main(argv[:5] + ["2"] + argv[5:]) == 0
    with open(out / "runs.csv", newline="") as fh:
        status = {row["run"]: row["status"] for row in csv.DictReader(fh)}
    assert status == {"tiny_ppo_seed0": "skipped", "tiny_ppo_seed1": "skipped", "tiny_ppo_seed2": "ok"}
    assert (out / "tiny_ppo_seed0" / "final_model.zip").stat().st_mtime_ns == mtime


def test_training_sweep_resumes(tmp_path):
    """Two seeds (serial engine: the same runner, store and resume as on Ray), then a third."""
    _sweep_and_resume(tmp_path, ["--serial"])


@pytest.mark.slow
def test_training_sweep_on_ray(tmp_path):
    """The same sweep as Ray tasks on a local 2-CPU Ray started by the script."""
    if ray.is_initialized():
        pytest.skip("needs its own Ray start (a module Ray instance is running)")
    _sweep_and_resume(tmp_path, ["--workers", "2"])


def test_batch_discrepancy_rows(fleet, tmp_path):
    """--command discrepancy: report.json per log, verdict and effects in the row (serial engine: no Ray start)."""
    out = tmp_path / "disc"
    assert main(["batch", str(fleet / "drive.csv"), str(fleet / "broken.csv"), "--out", str(out), "--command",
                 "discrepancy", "--serial", "--no-progress", "--seed", "3"]) == 1  # fmt: skip
    rows = _summary(out)
    assert rows["broken"]["status"] == "failed"
    r = rows["drive"]
    assert r["status"] == "ok" and r["kind"] == "camera" and int(r["rows"]) > 100
    report = json.loads((out / "drive" / "report.json").read_text())
    assert r["verdict"] == report["verdict"] in ("none", "found", "unexplained")
    assert float(r["gap_ratio"]) == pytest.approx(report["gap_ratio"], rel=1e-5)
    assert [e.split("(")[0] for e in r["effects"].split("; ") if e] == [e["name"] for e in report["effects"]]
    assert json.loads((out / "batch.json").read_text())["args"] == ["--seed", "3"]  # --seed reaches the command


def test_pooled_stiffness_per_vehicle():
    """Inverse-variance pooling of a vehicle's identified logs; a log without a value is not pooled."""
    from tire_learning_env.fleet.batch import pooled_by_vehicle, vehicle_ids

    def row(vehicle, k, lo, hi, status="ok"):
        return {"vehicle": vehicle, "status": status, "stiffness_front_N_per_rad": k,
                "stiffness_front_lo_N_per_rad": lo, "stiffness_front_hi_N_per_rad": hi}  # fmt: skip

    rows = [row("car_a", 100e3, 98e3, 102e3), row("car_a", 104e3, 100e3, 108e3), row("car_a", "", 90e3, 120e3),
            row("car_a", 50e3, 40e3, 60e3, status="failed"), row("car_b", 90e3, 85e3, 95e3)]  # fmt: skip
    front = {v["vehicle"]: v for v in pooled_by_vehicle(rows) if v["axle"] == "front"}
    a = front["car_a"]
    assert a["logs"] == 3 and a["identified_logs"] == 2  # the failed log is not a log of the estimate
    assert a["stiffness_N_per_rad"] == pytest.approx((100e3 / 1e6 + 104e3 / 4e6) / (1 / 1e6 + 1 / 4e6))
    assert a["hi_N_per_rad"] - a["lo_N_per_rad"] == pytest.approx(4 * 1e3 / np.sqrt(1.25))
    assert (a["min_log_estimate_N_per_rad"], a["max_log_estimate_N_per_rad"]) == (100e3, 104e3)
    assert front["car_b"]["stiffness_N_per_rad"] == 90e3
    assert vehicle_ids([Path("f/car_a/1.csv"), Path("f/car_b/x/2.csv")]) == ["car_a", "car_b/x"]
    assert vehicle_ids([Path("f/1.csv"), Path("f/2.csv")]) == ["1", "2"]  # one folder: a log is a vehicle


def test_batch_without_the_fleet_extra(tmp_path, monkeypatch, capsys):
    """The lean install (no Ray, no pyarrow): batch names the extra and --serial; --serial runs and writes
    summary.csv and fleet.png, says that summary.parquet is missing, and does not claim to have written it."""
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError, as without the extra
    monkeypatch.setitem(sys.modules, "pyarrow", None)
    log = tmp_path / "bad.csv"
    log.write_text("t,vx,delta,kappa,e1,e2\n0,20,0,0,0,0\n0.1,20,x,0,0,0\n")
    assert main(["batch", str(log), "--out", str(tmp_path / "a"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "needs Ray" in err and "tire_learning_env[fleet]" in err and "--serial" in err
    assert main(["batch", str(log), "--out", str(tmp_path / "b"), "--serial", "--no-progress"]) == 1  # the log failed
    out, err = capsys.readouterr()
    assert "pyarrow is not installed: no summary.parquet" in err and "failed: bad" in err
    assert not (tmp_path / "b" / "summary.parquet").exists() and (tmp_path / "b" / "summary.csv").is_file()
    assert "summary.parquet" not in out and "summary.csv" in out and "fleet.png" in out
