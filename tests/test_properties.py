"""Issue 17, item 7: property-based tests of the log reader and the vehicle file.

Whatever a user hands over, :func:`tire_learning_env.io.read_log` and
:func:`tire_learning_env.io.read_vehicle` either read it correctly or raise their documented
error (:class:`~tire_learning_env.io.LogFormatError`, :class:`~tire_learning_env.params.ParameterError`)
with a message; never another exception.
"""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from tire_learning_env.io import LogFormatError, read_log, read_vehicle  # noqa: E402
from tire_learning_env.params import ParameterError, VehicleParams  # noqa: E402

CLEAN = (LogFormatError, ParameterError)
SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])

CAMERA = ("t", "vx", "delta", "kappa", "e1", "e2")
IMU = ("yaw_rate", "ay", "ax")
TRUTH = ("true_e1", "true_e2", "true_vy", "true_r")

def _read(path, text: str | bytes, **kwargs):
    """``read_log`` on ``text``: the log, or None after a clean error (never another exception)."""
    if isinstance(text, str):
        path.write_text(text, encoding="utf-8")
    else:
        path.write_bytes(text)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # unknown columns, sensor choice: warnings, not errors
        try:
            return read_log(path, **kwargs)
        except CLEAN as exc:
            assert str(exc).strip(), "an error must say what is wrong"
            assert len(str(exc)) < 2000, "errors stay short"
            return None


@st.composite
def camera_tables(draw, extra=(), min_rows=3, max_rows=25):
    """A physically quiet camera log (straight road, on the lane centre) as a dict of columns,
    plus optional IMU / truth columns."""
    n = draw(st.integers(min_rows, max_rows))
    dt = draw(st.sampled_from([0.01, 0.02, 0.05, 0.1]))
    vx = draw(st.floats(5.0, 35.0))
    cols = {
        "t": np.round(np.arange(n) * dt, 6),
        "vx": np.full(n, round(vx, 4)),
        "delta": np.zeros(n),
        "kappa": np.zeros(n),
        "e1": np.zeros(n),
        "e2": np.zeros(n),
    }
    for name in extra:
        cols[name] = np.zeros(n)
    return cols


def _csv(cols: dict, order: list[str], blanks: set[tuple[int, str]] = frozenset()) -> str:
    n = len(next(iter(cols.values())))
    lines = [",".join(order)]
    for i in range(n):
        lines.append(",".join("" if (i, c) in blanks else repr(float(cols[c][i])) for c in order))
    return "\n".join(lines) + "\n"


# --- the log reader ------------------------------------------------------------------------------


@SETTINGS
@given(data=st.data())
def test_any_column_order_reads_back_the_same_values(tmp_path, data):
    extra = data.draw(st.lists(st.sampled_from(IMU + TRUTH), unique=True, max_size=4))
    cols = data.draw(camera_tables(extra=extra))
    n = len(cols["t"])
    for name in cols:  # any values within the reader's structural limits (|delta|, |kappa| <= 1, |e2| <= pi)
        if name not in ("t", "vx"):
            bound = {"delta": 0.5, "kappa": 0.9, "e2": 3.0}.get(name, 1e3)
            values = st.floats(-bound, bound, allow_nan=False)
            cols[name] = np.array(data.draw(st.lists(values, min_size=n, max_size=n)))
    order = data.draw(st.permutations(list(cols)))
    log = _read(tmp_path / "log.csv", _csv(cols, order), check_units=False)
    assert log is not None, "a well-formed log in any column order must be read"
    assert log.kind in ("camera", "imu", "both")
    read = {**log.sensors, **log.truth}
    for name in cols:
        if name in read:
            np.testing.assert_array_equal(read[name], cols[name])
    for name in CAMERA:
        assert name in read


@SETTINGS
@given(data=st.data())
def test_missing_values_give_nan_frames_or_a_clean_error(tmp_path, data):
    cols = data.draw(camera_tables(extra=data.draw(st.lists(st.sampled_from(IMU), unique=True, max_size=3))))
    n = len(cols["t"])
    order = data.draw(st.permutations(list(cols)))
    cells = st.tuples(st.integers(0, n - 1), st.sampled_from(order))
    blanks = set(data.draw(st.lists(cells, max_size=8)))
    log = _read(tmp_path / "log.csv", _csv(cols, order, blanks), check_units=False)
    if log is None:
        return
    read = {**log.sensors, **log.truth}
    for name in read:
        if name in cols:
            expected = cols[name].copy()
            expected[[i for i, c in blanks if c == name]] = np.nan
            np.testing.assert_array_equal(read[name], expected)


@SETTINGS
@given(data=st.data())
def test_unit_scalings_give_a_correct_read_or_a_clean_error(tmp_path, data):
    """km/h speed, degrees, milliseconds, ...: the unit checks either accept or name the column."""
    cols = data.draw(camera_tables(extra=("yaw_rate", "ay"), min_rows=20, max_rows=60))
    n = len(cols["t"])
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    cols["delta"] = 0.02 * np.sin(np.linspace(0.0, 3.0, n))
    cols["e1"] = 0.1 * rng.standard_normal(n)
    cols["e2"] = 0.01 * rng.standard_normal(n)
    scale = {name: data.draw(st.sampled_from([1.0, 1.0, 3.6, 180 / math.pi, 1000.0, 0.001, -1.0])) for name in cols}
    scaled = {name: v * scale[name] for name, v in cols.items()}
    log = _read(tmp_path / "log.csv", _csv(scaled, list(scaled)))
    if log is not None:
        read = {**log.sensors, **log.truth}
        for name in read:
            np.testing.assert_array_equal(read[name], scaled[name])


@st.composite
def malformed_logs(draw):
    cols = draw(camera_tables())
    order = draw(st.permutations(list(cols)))
    lines = _csv(cols, order).splitlines()
    junk = st.sampled_from(["abc", "1,5", "nan", "inf", "", '"x"', "1e400", "--", "0x10", " ", "1;2", "\x00", "é"])
    for _ in range(draw(st.integers(1, 5))):
        i = draw(st.integers(0, len(lines) - 1))
        cells = lines[i].split(",")
        action = draw(st.sampled_from(["drop", "add", "replace", "delete_row", "duplicate_row", "separator"]))
        if action == "drop" and len(cells) > 1:
            cells.pop(draw(st.integers(0, len(cells) - 1)))
        elif action == "add":
            cells.append(draw(junk))
        elif action == "replace":
            cells[draw(st.integers(0, len(cells) - 1))] = draw(junk)
        elif action == "delete_row" and len(lines) > 1:
            lines.pop(i)
            continue
        elif action == "duplicate_row":
            lines.insert(i, lines[i])
        elif action == "separator":
            lines[i] = draw(st.sampled_from([";", "\t", " ", "|"])).join(cells)
            continue
        lines[i] = ",".join(cells)
    return "\n".join(lines) + draw(st.sampled_from(["\n", "", "\r\n", "\n\n"]))


@SETTINGS
@given(data=st.data(), text=malformed_logs())
def test_malformed_rows_give_a_clean_error_or_a_read(tmp_path, data, text):
    log = _read(tmp_path / "log.csv", text, check_units=data.draw(st.booleans()))
    if log is not None:
        assert len(log.sensors["t"]) >= 2


@SETTINGS
@given(raw=st.one_of(
    st.binary(max_size=400),
    st.text(max_size=400),
    st.builds(lambda head, body: head + body, st.sampled_from([b"\xef\xbb\xbf", b"\x1f\x8b", b"PK\x03\x04", b""]),
              st.binary(max_size=200)),
    st.builds(lambda body: "t,vx,delta,kappa,e1,e2\n" + body, st.text(max_size=300)),
))
def test_random_bytes_give_a_clean_error_or_a_read(tmp_path, raw):
    _read(tmp_path / "log.csv", raw)


# --- the vehicle file ----------------------------------------------------------------------------

FIELDS = [f for f in VehicleParams().to_dict()]
json_values = st.one_of(
    st.none(), st.booleans(), st.integers(-10**6, 10**6), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8), st.lists(st.integers(), max_size=3), st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)


def _read_vehicle(path, text: str):
    path.write_text(text, encoding="utf-8")
    try:
        return read_vehicle(path)
    except ParameterError as exc:
        assert str(exc).strip() and str(path) in str(exc), "the error names the file"
        return None


@SETTINGS
@given(doc=st.dictionaries(st.one_of(st.sampled_from(FIELDS), st.text(max_size=6)), json_values, max_size=12))
def test_random_vehicle_dicts_give_a_clean_error_or_exactly_the_given_values(tmp_path, doc):
    vehicle = _read_vehicle(tmp_path / "v.json", json.dumps(doc))
    if vehicle is not None:
        got = vehicle.to_dict()
        for key, value in doc.items():
            assert not isinstance(value, bool)
            assert got[key] == value


@st.composite
def plausible_vehicles(draw):
    m = draw(st.floats(500.0, 5000.0))
    lf, lr = draw(st.floats(0.8, 2.0)), draw(st.floats(0.8, 2.0))
    iz = m * lf * lr * draw(st.floats(0.5, 2.0))
    g = 9.81
    load_f, load_r = m * g * lr / (lf + lr) / 2, m * g * lf / (lf + lr) / 2
    doc = {"m": m, "Iz": iz, "lf": lf, "lr": lr,
           "Cf": load_f * draw(st.floats(5.0, 50.0)), "Cr": load_r * draw(st.floats(5.0, 50.0))}
    if draw(st.booleans()):
        doc["vx"] = draw(st.floats(1.0, 60.0))
    return doc


@SETTINGS
@given(doc=plausible_vehicles(), drop=st.sampled_from([None, "m", "Iz", "lf", "lr", "Cf", "Cr"]),
       spoil=st.sampled_from([None, True, "heavy", None, float("nan"), -1.0, [1]]))
def test_plausible_vehicles_read_exactly_and_any_spoiled_key_is_named(tmp_path, doc, drop, spoil):
    vehicle = _read_vehicle(tmp_path / "v.json", json.dumps(doc))
    assert vehicle is not None, f"a plausible vehicle must be read: {doc}"
    assert all(vehicle.to_dict()[k] == v for k, v in doc.items())
    if drop is None:
        return
    bad = dict(doc)
    if spoil is None:
        del bad[drop]
    else:
        bad[drop] = spoil
    path = tmp_path / "v.json"
    path.write_text(json.dumps(bad), encoding="utf-8")
    with pytest.raises(ParameterError, match=drop):
        read_vehicle(path)


@SETTINGS
@given(text=st.one_of(st.text(max_size=200), st.builds(json.dumps, json_values)))
def test_any_vehicle_text_gives_a_clean_error_or_a_vehicle(tmp_path, text):
    _read_vehicle(tmp_path / "v.json", text)
