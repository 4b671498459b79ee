"""Logger formats (MF4, Parquet, MCAP) read through channel maps into the CSV log's columns."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("asammdf")
pytest.importorskip("pyarrow")
pytest.importorskip("mcap")
pytest.importorskip("rosbags")

from tire_learning_env.formats import (ChannelMap, convert_unit, default_channel_map, load_channel_map,  # noqa: E402
                                       logger_channel_map, save_channel_map, write_logger_log, write_ros2_bag)
from tire_learning_env.io import LogFormatError, read_log, write_log  # noqa: E402

DATA = Path(__file__).resolve().parents[1] / "tire_learning_env" / "data"
FORMATS = ("mf4", "parquet", "mcap")


@pytest.fixture(scope="module")
def columns():
    """6 s of the simulator: 50 rows/s plus every camera frame (20 Hz, paper noise, with dropouts in e1)."""
    from tire_learning_env.params import CameraParams
    from tire_learning_env.simulation import simulate

    log = simulate("study1", 6.0, camera=CameraParams.paper_noise(rate=20.0), physics_rate=1000.0, seed=3)
    cols = log.to_columns()
    keep = np.zeros(len(cols["t"]), dtype=bool)
    keep[::20] = True
    keep |= np.isfinite(cols["e1"])
    return {k: v[keep] for k, v in cols.items()}


def _same(a, b, rtol=1e-12, atol=1e-12):
    for k in a.sensors:
        assert k in b.sensors, k
        x, y = a.sensors[k], b.sensors[k]
        assert np.array_equal(np.isnan(x), np.isnan(y)), f"{k}: NaN rows differ"
        np.testing.assert_allclose(x, y, rtol=rtol, atol=atol, equal_nan=True, err_msg=k)
    assert set(a.sensors) == set(b.sensors)
    assert set(a.truth) == set(b.truth)
    for k in a.truth:
        np.testing.assert_allclose(a.truth[k], b.truth[k], rtol=rtol, atol=atol, err_msg=k)


@pytest.mark.parametrize("fmt", FORMATS)
def test_round_trip_same_columns_as_csv(tmp_path, columns, fmt):
    """simulate -> write the logger file (logger names, km/h, deg, g, ms) -> read with the map == the CSV log."""
    write_log(tmp_path / "drive.csv", columns)
    csv_log = read_log(tmp_path / "drive.csv")
    write_logger_log(tmp_path / f"drive.{fmt}", columns, channel_map=tmp_path / "drive.channels.yaml")
    log = read_log(tmp_path / f"drive.{fmt}")
    assert log.kind == csv_log.kind == "camera"
    # the CSV keeps 10 significant digits; the logger files keep float64 (after unit factors)
    _same(log, csv_log, rtol=1e-9, atol=1e-12)
    notes = " | ".join(log.notes)
    assert "drive.channels.yaml (found beside the log)" in notes
    assert "vx <- " in notes and "[km/h]" in notes and "[g]" in notes
    if fmt == "parquet":
        assert "no resampling" in notes
    else:
        assert "time base" in notes and "e1 (" in notes and "nearest frame" in notes
    # the raw file really holds non-SI values (the map did the conversion)
    if fmt == "parquet":
        import pyarrow.parquet as pq

        raw = pq.read_table(tmp_path / "drive.parquet").column("VehSpd").to_numpy()
        np.testing.assert_allclose(raw, columns["vx"] * 3.6, rtol=1e-12)


def test_examples_shipped_read_alike():
    """The shipped MF4 and Parquet examples (one simulated drive) read into the same log."""
    mf4 = read_log(DATA / "example_drive.mf4")
    pq_log = read_log(DATA / "example_drive.parquet")
    assert mf4.kind == "camera" and mf4.has_truth
    assert 25.0 < mf4.duration < 31.0
    _same(mf4, pq_log, rtol=1e-12)
    for f in ("example_drive.mf4", "example_drive.parquet"):
        assert (DATA / f).stat().st_size < 300_000


def test_examples_shipped_are_the_simulators(tmp_path):
    """The shipped MF4, Parquet and channel map are what ``write_example_logs`` writes from the simulator
    today (so they are the package's own drive, and not stale), and hold that drive's columns in SI."""
    from tire_learning_env.formats import write_example_logs
    from tire_learning_env.params import CameraParams
    from tire_learning_env.simulation import simulate

    write_example_logs(tmp_path)
    assert (tmp_path / "example_drive.channels.yaml").read_text() == (DATA / "example_drive.channels.yaml").read_text()
    fresh = {f: read_log(tmp_path / f) for f in ("example_drive.mf4", "example_drive.parquet")}
    for f, log in fresh.items():
        _same(read_log(DATA / f), log, rtol=0.0, atol=0.0)
    # and the simulator's own columns, before any logger unit: km/h, deg, deg/s, g converted back exactly
    sim = simulate("study1", 30.0, camera=CameraParams.paper_noise(rate=20.0), physics_rate=1000.0, seed=7).to_columns()
    log = fresh["example_drive.mf4"]
    idx = np.searchsorted(sim["t"], log.sensors["t"])
    np.testing.assert_allclose(sim["t"][idx], log.sensors["t"], atol=1e-9)
    for k in ("vx", "delta", "kappa", "e1", "e2", "yaw_rate", "ay"):
        np.testing.assert_allclose(log.sensors[k], sim[k][idx], rtol=1e-12, atol=1e-15, equal_nan=True, err_msg=k)


def test_resampling_to_the_time_base(tmp_path, columns):
    """A channel logged at another rate is interpolated onto the rows, and the notes say so."""
    from asammdf import MDF, Signal

    t = columns["t"]
    fast_t = np.arange(t[0], t[-1] + 1e-9, 0.005)  # yaw rate at 200 Hz
    fast = np.sin(fast_t)
    mdf = MDF(version="4.10")
    mdf.append([Signal(columns[c], t, name=c, unit=u) for c, u in (("vx", "m/s"), ("delta", "rad"), ("kappa", "1/m"),
                                                                    ("ay", "m/s^2"))])  # fmt: skip
    frame = np.isfinite(columns["e1"])
    mdf.append([Signal(columns["e1"][frame], t[frame], name="e1", unit="m"),
                Signal(columns["e2"][frame], t[frame], name="e2", unit="rad")])  # fmt: skip
    mdf.append([Signal(np.degrees(fast), fast_t, name="yaw_rate", unit="deg/s")])
    mdf.save(tmp_path / "r.mf4")
    log = read_log(tmp_path / "r.mf4", check_units=False)  # no map: names as the columns, units from the file
    notes = " | ".join(log.notes)
    assert "no channel map" in notes and "yaw_rate (" in notes and "linear" in notes
    np.testing.assert_allclose(log.sensors["yaw_rate"], np.interp(log.sensors["t"], fast_t, fast), atol=1e-12)
    np.testing.assert_array_equal(np.isfinite(log.sensors["e1"]), frame)


def test_unit_conversions():
    assert convert_unit(np.array([36.0]), "km/h", "vx")[0] == pytest.approx(10.0)
    assert convert_unit(np.array([180.0]), "deg", "delta")[0] == pytest.approx(math.pi)
    assert convert_unit(np.array([90.0]), "deg/s", "yaw_rate")[0] == pytest.approx(math.pi / 2)
    assert convert_unit(np.array([1.0]), "g", "ay")[0] == pytest.approx(9.80665)
    assert convert_unit(np.array([1500.0]), "ms", "t")[0] == pytest.approx(1.5)
    with pytest.raises(LogFormatError, match=r"unknown unit 'furlong/s'.*m/s"):
        convert_unit(np.zeros(1), "furlong/s", "vx")
    with pytest.raises(LogFormatError, match=r"unit 'deg' is a unit of rad, but 'vx' is in m/s"):
        convert_unit(np.zeros(1), "deg", "vx")


def test_channel_map_errors_name_the_problem(tmp_path, columns):
    write_logger_log(tmp_path / "d.mf4", columns)
    good = logger_channel_map(list(columns), "mf4").to_dict()
    bad = json.loads(json.dumps(good))
    bad["columns"]["vx"]["channel"] = "VehicleSpeedMissing"
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    with pytest.raises(LogFormatError, match=r"channel 'VehicleSpeedMissing' \(column 'vx' in channel map .*bad.json\) "
                       r"is not in the file; its channels: .*'VehSpd'"):  # fmt: skip
        read_log(tmp_path / "d.mf4", channel_map=tmp_path / "bad.json")
    bad = json.loads(json.dumps(good))
    bad["columns"]["ay"]["unit"] = "gees"
    (tmp_path / "unit.json").write_text(json.dumps(bad))
    with pytest.raises(LogFormatError, match=r"column 'ay' \(channel 'LatAcc'\): unknown unit 'gees'"):
        load_channel_map(tmp_path / "unit.json")
    (tmp_path / "key.yaml").write_text("columns:\n  vx: {channel: V, units: km/h}\n")
    with pytest.raises(LogFormatError, match=r"column 'vx': unknown key\(s\) \['units'\]"):
        load_channel_map(tmp_path / "key.yaml")
    (tmp_path / "col.yaml").write_text("columns:\n  speed: V\n")
    with pytest.raises(LogFormatError, match=r"'speed' is not a column of the log format"):
        load_channel_map(tmp_path / "col.yaml")
    # a channel map is not needed to be told the file's units were wrong: the CSV checks still run
    wrong = json.loads(json.dumps(good))
    wrong["columns"]["vx"]["unit"] = "m/s"  # the file holds km/h
    with pytest.raises(LogFormatError, match=r"'vx'.*km/h"):
        read_log(tmp_path / "d.mf4", channel_map=ChannelMap.from_dict(wrong, "wrong map"))


@pytest.mark.parametrize("fmt", FORMATS)
def test_unreadable_file_is_one_named_error(tmp_path, fmt):
    p = tmp_path / f"junk.{fmt}"
    p.write_bytes(b"this is not a logger file\x00\x01" * 20)
    with pytest.raises(LogFormatError, match=rf"junk.{fmt}: not a readable {fmt.upper() if fmt != 'parquet' else 'Parquet'} file"):
        read_log(p, channel_map=logger_channel_map(["t", "vx", "delta", "kappa", "e1", "e2"], fmt))


def test_default_channel_map_and_precedence(tmp_path, columns):
    """A batch's default map is used for logs without a map beside them; a map beside the log wins."""
    write_logger_log(tmp_path / "a.parquet", columns)
    save_channel_map(logger_channel_map(list(columns), "parquet"), tmp_path / "fleet_map.json")
    with pytest.raises(LogFormatError, match="no time column|not in the file|required column"):
        read_log(tmp_path / "a.parquet")  # no map anywhere: logger names are not log columns
    with default_channel_map(tmp_path / "fleet_map.json"):
        log = read_log(tmp_path / "a.parquet")
    assert any("the default given to the batch" in n for n in log.notes)
    save_channel_map(logger_channel_map(list(columns), "parquet"), tmp_path / "a.channels.yaml")
    with default_channel_map(tmp_path / "does_not_matter.json"):
        log = read_log(tmp_path / "a.parquet")
    assert any("found beside the log" in n for n in log.notes)


def test_same_estimate_as_csv(tmp_path, columns):
    """The estimator gives the same stiffness on the MF4, Parquet and MCAP files as on the CSV of the same data."""
    from tire_learning_env.observer import ObserverConfig, estimate
    from tire_learning_env.params import VehicleParams

    write_log(tmp_path / "d.csv", columns)
    for fmt in FORMATS:  # each in its own folder: the MCAP map names topics, the MF4 map channels
        (tmp_path / fmt).mkdir()
        write_logger_log(tmp_path / fmt / f"d.{fmt}", columns, channel_map=tmp_path / fmt / "d.channels.yaml")
    cfg = ObserverConfig(sensors="camera", offline=False)
    paths = [tmp_path / "d.csv"] + [tmp_path / fmt / f"d.{fmt}" for fmt in FORMATS]
    k = [estimate(read_log(p).sensors, VehicleParams(), None, config=cfg).cornering_stiffness() for p in paths]
    assert all(np.all(np.isfinite(ki)) for ki in k)
    for ki in k[1:]:
        np.testing.assert_allclose(ki, k[0], rtol=1e-6)


def test_same_estimate_command_as_csv(tmp_path):
    """``tire-learning estimate`` as a user runs it (default settings: the offline fit on) gives the same
    stiffness and 2-sigma band on the shipped MF4 and Parquet examples (docs/fleet.md's command) as on
    the same data written as CSV and as MCAP (ROS 2 bags: same columns, test_ros2_bag_round_trip)."""
    from tire_learning_env.cli import main

    example = read_log(DATA / "example_drive.mf4")
    columns = {**example.sensors, **example.truth}
    write_log(tmp_path / "d.csv", columns)
    logs = {"csv": tmp_path / "d.csv", "mf4": DATA / "example_drive.mf4", "parquet": DATA / "example_drive.parquet"}
    (tmp_path / "mcap").mkdir()
    logs["mcap"] = tmp_path / "mcap" / "d.mcap"
    write_logger_log(logs["mcap"], columns, channel_map=tmp_path / "mcap" / "d.channels.yaml")
    summary = {}
    for name, log in logs.items():
        assert main(["estimate", str(log), "--out", str(tmp_path / f"out_{name}"), "--no-progress"]) == 0, name
        metrics = json.loads((tmp_path / f"out_{name}" / "metrics.json").read_text())
        summary[name] = metrics["summary"]
        if name != "csv":  # read through its channel map, not as a CSV
            assert any("channel map" in n and "found beside the log" in n for n in metrics["log_notes"]), name
    ref = summary["csv"]
    keys = [f"stiffness_{a}_{w}" for a in ("front", "rear") for w in ("N_per_rad", "2sigma_N_per_rad")]
    for k in keys:  # the example is identified: a value and a band on both axles
        assert ref[k] is not None and np.all(np.isfinite(np.ravel(ref[k]).astype(float))), ref
    for name, s in summary.items():
        assert s["verdict"] == ref["verdict"] == "identified" and s["sensors"] == ref["sensors"], name
        for k in keys:
            # the CSV keeps 10 significant digits, the logger files float64: the estimates agree far below that
            np.testing.assert_allclose(np.ravel(s[k]).astype(float), np.ravel(ref[k]).astype(float), rtol=1e-6,
                                       err_msg=f"{name}: {k}")


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_ros2_bag_round_trip(tmp_path, columns, storage):
    """simulate -> ROS 2 bag (TwistStamped, Imu, Float64 topics; CDR) -> read with the map == the CSV log."""
    write_log(tmp_path / "drive.csv", columns)
    csv_log = read_log(tmp_path / "drive.csv")
    write_ros2_bag(tmp_path / "bag", columns, channel_map=tmp_path / "bag.channels.yaml", storage=storage)
    log = read_log(tmp_path / "bag")  # the folder; its map is found beside it
    _same(log, csv_log, rtol=1e-9, atol=1e-12)
    assert any("bag.channels.yaml (found beside the log)" in n for n in log.notes)
    assert any("/imu/data:angular_velocity.z" in n or "e1 (" in n for n in log.notes)
    if storage == "sqlite3":
        db3 = next((tmp_path / "bag").glob("*.db3"))
        _same(read_log(db3, channel_map=tmp_path / "bag.channels.yaml"), csv_log, rtol=1e-9, atol=1e-12)
    else:  # the bag's MCAP file read alone: ROS 2 CDR messages through the MCAP reader
        mcap_file = next((tmp_path / "bag").glob("*.mcap"))
        _same(read_log(mcap_file, channel_map=tmp_path / "bag.channels.yaml"), csv_log, rtol=1e-9, atol=1e-12)


def test_ros2_missing_topic_is_named(tmp_path, columns):
    cmap = write_ros2_bag(tmp_path / "bag", columns).to_dict()
    cmap["columns"]["yaw_rate"]["channel"] = "/imu/dataa:angular_velocity.z"
    with pytest.raises(LogFormatError, match=r"channel '/imu/dataa:angular_velocity.z' \(column 'yaw_rate'.*"
                       r"its channels: .*'/imu/data'"):  # fmt: skip
        read_log(tmp_path / "bag", channel_map=ChannelMap.from_dict(cmap, "edited map"))
