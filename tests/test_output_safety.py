"""Issue 17: nothing a user has is ever lost through ``--out``."""

import json
import os
from pathlib import Path

import pytest

from tire_learning_env import io
from tire_learning_env.cli import main
from tire_learning_env.io import (
    MANIFEST_NAME,
    OutputPathError,
    atomic_directory,
    check_output_dir,
    check_output_file,
    read_manifest,
    run_context,
)


def user_folder(path: Path) -> Path:
    path.mkdir(parents=True)
    (path / "notes.txt").write_text("my notes")
    (path / "sub").mkdir()
    (path / "sub" / "data.bin").write_bytes(b"\x00\x01")
    return path


def no_temporaries(folder: Path) -> bool:
    return not [p for p in folder.iterdir() if p.name.startswith(".") and p.name != MANIFEST_NAME]


# --- check_output_dir ---------------------------------------------------------------------------


def test_new_and_empty_folders_are_accepted(tmp_path):
    assert check_output_dir(tmp_path / "new" / "deeper") == tmp_path / "new" / "deeper"
    (tmp_path / "empty").mkdir()
    check_output_dir(tmp_path / "empty")
    assert not (tmp_path / "new").exists()  # the check creates nothing


def test_foreign_folder_is_refused_naming_it_and_overwrite(tmp_path):
    out = user_folder(tmp_path / "mine")
    with pytest.raises(OutputPathError, match=r"mine.*not written by tire-learning.*notes\.txt.*--overwrite"):
        check_output_dir(out)
    check_output_dir(out, overwrite=True)


def test_folder_holding_an_input_is_never_replaced(tmp_path):
    out = tmp_path / "data"
    out.mkdir()
    log = out / "drive.csv"
    log.write_text("t\n")
    with pytest.raises(OutputPathError, match=r"holds the input.*drive\.csv.*even with --overwrite"):
        check_output_dir(out, overwrite=True, inputs=[log])
    # also when the input sits deeper inside, or is named by a relative path
    deep = tmp_path / "results"
    (deep / "a").mkdir(parents=True)
    (deep / "a" / "v.json").write_text("{}")
    with pytest.raises(OutputPathError, match="holds the input"):
        check_output_dir(deep, overwrite=True, inputs=[Path(os.path.relpath(deep / "a" / "v.json"))])


def test_cwd_its_parents_and_home_are_never_replaced(tmp_path, monkeypatch):
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    for out in (".", str(work), str(tmp_path / "a"), "..", "/"):
        with pytest.raises(OutputPathError, match="current directory or one of its parents"):
            check_output_dir(out, overwrite=True)
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    with pytest.raises(OutputPathError, match="home directory"):
        check_output_dir(home, overwrite=True)


def test_unwritable_destinations_are_refused_before_work(tmp_path):
    blocker = tmp_path / "file.txt"
    blocker.write_text("x")
    with pytest.raises(OutputPathError, match=r"file\.txt is a file, not a folder"):
        check_output_dir(blocker / "out")
    with pytest.raises(OutputPathError, match="is a file, not a folder"):
        check_output_dir(blocker)
    if Path("/proc/self").exists():  # not writable even for root
        with pytest.raises(OutputPathError, match="not writable"):
            check_output_dir("/proc/tire_learning_out")


def test_check_output_file(tmp_path):
    out = tmp_path / "drive.csv"
    check_output_file(out)
    out.write_text("t\n")
    with pytest.raises(OutputPathError, match=r"existing file .*drive\.csv.*--overwrite"):
        check_output_file(out)
    check_output_file(out, overwrite=True)
    with pytest.raises(OutputPathError, match="is an input"):
        check_output_file(out, overwrite=True, inputs=[out])
    with pytest.raises(OutputPathError, match="is a folder"):
        check_output_file(tmp_path)


# --- atomic_directory ---------------------------------------------------------------------------


def test_atomic_directory_writes_a_manifest_and_replaces_only_its_own_folder(tmp_path):
    out = tmp_path / "out"
    with run_context(command="test", argv=("a", "b")):
        with atomic_directory(out) as tmp:
            (tmp / "metrics.json").write_text("{}")
            (tmp / "figs").mkdir()
            (tmp / "figs" / "a.png").write_bytes(b"png")
    manifest = read_manifest(out)
    assert manifest["files"] == ["figs/a.png", "metrics.json"]
    assert manifest["command"] == "test" and manifest["argv"] == ["a", "b"] and manifest["created"]
    with atomic_directory(out) as tmp:  # its own folder: replaced
        (tmp / "new.json").write_text("{}")
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST_NAME, "new.json"]
    (out / "user.txt").write_text("added by the user")
    ran = []
    with pytest.raises(OutputPathError, match=r"did not write \('user\.txt'\)"):
        with atomic_directory(out) as tmp:
            ran.append(True)
    assert not ran, "refused before the body ran"
    assert (out / "user.txt").read_text() == "added by the user" and no_temporaries(tmp_path)


def test_atomic_directory_refuses_foreign_folders_unless_forced(tmp_path):
    out = user_folder(tmp_path / "mine")
    with pytest.raises(OutputPathError, match="--overwrite"):
        with atomic_directory(out):
            pass
    assert (out / "notes.txt").exists() and (out / "sub" / "data.bin").exists()
    with run_context(overwrite=True):  # what --overwrite does for every command
        with atomic_directory(out) as tmp:
            (tmp / "r.json").write_text("{}")
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST_NAME, "r.json"]
    user_folder(tmp_path / "mine2")
    with atomic_directory(tmp_path / "mine2", force=True) as tmp:
        (tmp / "r.json").write_text("{}")
    assert not (tmp_path / "mine2" / "notes.txt").exists() and no_temporaries(tmp_path)


def test_atomic_directory_never_replaces_a_folder_holding_an_input(tmp_path):
    out = tmp_path / "out"
    with atomic_directory(out) as tmp:
        (tmp / "a.json").write_text("{}")
    log = out / "a.json"  # now an input of the next command
    with run_context(overwrite=True, inputs=[log]):
        with pytest.raises(OutputPathError, match="holds the input"):
            with atomic_directory(out, force=True):
                pass
    assert log.exists()


def test_files_appearing_during_the_run_are_not_deleted(tmp_path):
    out = tmp_path / "out"
    with atomic_directory(out) as tmp:
        (tmp / "a.json").write_text("{}")
    with pytest.raises(OutputPathError, match="late.txt"):
        with atomic_directory(out) as tmp:
            (tmp / "b.json").write_text("{}")
            (out / "late.txt").write_text("written while the command ran")
    assert (out / "late.txt").exists() and (out / "a.json").exists() and no_temporaries(tmp_path)


def test_atomic_directory_dot_is_refused_without_a_traceback_or_temporaries(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(OutputPathError, match="current directory"):
        with atomic_directory("."):
            pass
    assert list(tmp_path.iterdir()) == []


# --- the commands -------------------------------------------------------------------------------

CAMERA_LOG = "t,vx,delta,kappa,e1,e2\n" + "".join(f"{i / 100},30,0.001,0,0.0,0.0\n" for i in range(300))


@pytest.mark.parametrize(
    "argv",
    [
        ["estimate", "{log}", "--out", "{out}"],
        ["discrepancy", "{log}", "--out", "{out}"],
        ["reproduce", "--study", "1", "--out", "{out}"],
        ["reproduce", "--all", "--out", "{out}"],
    ],
    ids=["estimate", "discrepancy", "reproduce", "reproduce-all"],
)
def test_every_command_keeps_a_user_folder(tmp_path, capsys, monkeypatch, argv):
    log = tmp_path / "drive.csv"
    log.write_text(CAMERA_LOG)
    out = user_folder(tmp_path / "mine")
    started = []
    monkeypatch.setattr("tire_learning_env.studies.run_study", lambda *a, **k: started.append(1))
    monkeypatch.setattr("tire_learning_env.report.reproduce_all", lambda *a, **k: started.append(1))
    fill = {"{log}": str(log), "{out}": str(out)}
    assert main([fill.get(a, a) for a in argv]) == 2
    err = capsys.readouterr().err
    assert "refusing to replace" in err and "mine" in err and "--overwrite" in err and "Traceback" not in err
    assert (out / "notes.txt").read_text() == "my notes" and (out / "sub" / "data.bin").exists()
    assert not started and no_temporaries(tmp_path)
    # the log inside the output folder: refused even with --overwrite
    inside = out / "drive.csv"
    inside.write_text(CAMERA_LOG)
    fill["{log}"] = str(inside)
    if "{log}" in argv:
        assert main([fill.get(a, a) for a in argv] + ["--overwrite"]) == 2
        assert "holds the input" in capsys.readouterr().err and inside.exists()


@pytest.mark.parametrize("command", [["estimate", "drive.csv"], ["discrepancy", "drive.csv"], ["reproduce", "--study", "1"]])
def test_out_dot_is_a_clear_error(tmp_path, capsys, monkeypatch, command):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "drive.csv").write_text(CAMERA_LOG)
    assert main(command + ["--out", ".", "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert "current directory" in err and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["drive.csv"]


def test_unwritable_out_fails_before_computing(tmp_path, capsys, monkeypatch):
    blocker = tmp_path / "file.txt"
    blocker.write_text("x")
    started = []
    monkeypatch.setattr("tire_learning_env.studies.run_study", lambda *a, **k: started.append(1))
    assert main(["reproduce", "--study", "1", "--out", str(blocker / "out")]) == 2
    assert "is a file, not a folder" in capsys.readouterr().err and not started


def test_simulate_refuses_to_overwrite_a_file_unless_asked(tmp_path, capsys):
    out = tmp_path / "drive.csv"
    out.write_text("my own data")
    args = ["simulate", "--duration", "1", "--out", str(out)]
    assert main(args) == 2
    assert "--overwrite" in capsys.readouterr().err and out.read_text() == "my own data"
    assert main(args + ["--overwrite"]) == 0
    assert out.read_text().startswith("t,")
    vehicle = tmp_path / "v.json"
    vehicle.write_text(json.dumps({"m": 1500.0, "Iz": 3000.0, "lf": 1.2, "lr": 1.6, "Cf": 80000.0, "Cr": 90000.0}))
    assert main(["simulate", "--duration", "1", "--vehicle", str(vehicle), "--out", str(vehicle), "--overwrite"]) == 2
    assert "is an input" in capsys.readouterr().err and json.loads(vehicle.read_text())["m"] == 1500.0
    assert main(["simulate", "--duration", "1", "--log", str(tmp_path / "b.csv")]) == 0  # --log names the file too


@pytest.mark.slow
def test_reproduce_reruns_into_its_own_folder_and_overwrite_replaces_a_foreign_one(tmp_path, capsys):
    out = tmp_path / "s1"
    assert main(["reproduce", "--study", "1", "--out", str(out), "--no-progress"]) == 0
    manifest = read_manifest(out)
    assert "metrics.json" in manifest["files"] and manifest["command"] == "reproduce"
    assert main(["reproduce", "--study", "1", "--out", str(out), "--no-progress"]) == 0  # its own folder
    mine = user_folder(tmp_path / "mine")
    assert main(["reproduce", "--study", "1", "--out", str(mine), "--overwrite", "--no-progress"]) == 0
    assert (mine / "metrics.json").exists() and not (mine / "notes.txt").exists()


def test_help_shows_defaults_and_common_options(capsys):
    for command in ("simulate", "estimate", "discrepancy", "reproduce"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        text = " ".join(capsys.readouterr().out.split())
        assert "--overwrite" in text and "--no-progress" in text
        if command == "simulate":
            assert "(default: pacejka)" in text and "one CSV FILE" in text
            assert "_positive" not in text
        if command in ("estimate", "discrepancy"):
            assert "--no-unit-checks" in text
