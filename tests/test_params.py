import json

import pytest

from tire_learning_env.io import read_vehicle
from tire_learning_env.params import CameraParams, DriverParams, ParameterError, TireParams, VehicleParams


def test_defaults_are_the_papers_sedan():
    v = VehicleParams()
    assert (v.m, v.Iz, v.lf, v.lr, v.vx, v.Cf, v.Cr) == (1529.95, 4607.47, 1.13906, 1.63716, 30.0, 102466.1678, 102466.1678)


@pytest.mark.parametrize(
    "kwargs, field",
    [({"m": -1.0}, "m"), ({"vx": 0.0}, "vx"), ({"Iz": float("nan")}, "Iz"), ({"Cf": 0}, "Cf")],
)
def test_invalid_vehicle_values_name_the_field(kwargs, field):
    with pytest.raises(ParameterError, match=rf"VehicleParams\.{field}"):
        VehicleParams(**kwargs)


def test_unknown_key_from_dict_is_named():
    with pytest.raises(ParameterError, match="mass_kg"):
        VehicleParams.from_dict({"mass_kg": 1500.0})


def test_vehicle_json_round_trip_and_unknown_key(tmp_path):
    path = tmp_path / "v.json"
    path.write_text(json.dumps({"m": 982.0, "Iz": 1605.0, "lf": 1.33, "lr": 1.07, "Cf": 35000.0, "Cr": 60000.0}))
    v = read_vehicle(path)
    assert v.m == 982.0 and v.Cr == 60000.0
    path.write_text(json.dumps({"m": 982.0, "wheels": 4}))
    with pytest.raises(ParameterError, match="wheels"):
        read_vehicle(path)
    path.write_text("{not json")
    with pytest.raises(ParameterError, match="not valid JSON"):
        read_vehicle(path)


def test_other_params_validate():
    with pytest.raises(ParameterError, match="TireParams.mu"):
        TireParams(mu=-0.1)
    with pytest.raises(ParameterError, match="CameraParams.rate"):
        CameraParams(rate=0.0)
    with pytest.raises(ParameterError, match="CameraParams.noise"):
        CameraParams(noise="pink")
    with pytest.raises(ParameterError, match="DriverParams.gain"):
        DriverParams(gain=-1)
    with pytest.raises(ParameterError, match="bogus"):
        VehicleParams().replace(bogus=1.0)


REVS = {"m": 982.0, "Iz": 1605.0, "lf": 1.33, "lr": 1.07, "Cf": 35000.0, "Cr": 60000.0}


@pytest.mark.parametrize("missing", [["Cr"], ["m", "Iz", "lf", "lr", "Cf", "Cr"]], ids=["no-Cr", "empty"])
def test_vehicle_file_missing_keys_is_an_error_not_the_sedan(tmp_path, missing):
    path = tmp_path / "v.json"
    path.write_text(json.dumps({k: v for k, v in REVS.items() if k not in missing}))
    with pytest.raises(ParameterError, match=r"required key\(s\) \[.*'Cr'\] missing") as exc:
        read_vehicle(path)
    assert "v.json" in str(exc.value)
    for key in missing:
        assert repr(key) in str(exc.value)


@pytest.mark.parametrize("value", [True, "heavy", None, [1500], {"kg": 1500}])
def test_vehicle_values_must_be_numbers_naming_the_key(tmp_path, value):
    path = tmp_path / "v.json"
    path.write_text(json.dumps(REVS | {"m": value}))
    with pytest.raises(ParameterError, match=r"VehicleParams\.m must be a number"):
        read_vehicle(path)
    with pytest.raises(ParameterError, match=r"VehicleParams\.m must be a number"):
        VehicleParams.from_dict({"m": value})


@pytest.mark.parametrize(
    "change, message",
    [
        ({"Cf": 1e12}, r"Cf = 1000000000000.0 N/rad per tire is implausible .* expected 1-100"),
        ({"Cr": 60.0}, r"Cr = 60.0 N/rad per tire is implausible"),
        ({"m": 0.0}, r"VehicleParams\.m must be > 0"),
        ({"m": -5.0}, r"VehicleParams\.m must be > 0"),
        ({"m": 982000.0}, r"VehicleParams\.m = 982000.0 kg is implausible \(expected 1-60000 kg\)"),
        ({"Iz": 1.6e9}, r"VehicleParams\.Iz = .* is implausible .*Iz / \(m lf lr\)"),
        ({"lf": 133.0}, r"VehicleParams\.lf = 133.0 m is implausible"),
        ({"vx": float("inf")}, r"VehicleParams\.vx must be finite"),
    ],
)
def test_implausible_vehicle_files_are_rejected_with_the_range(tmp_path, change, message):
    path = tmp_path / "v.json"
    path.write_text(json.dumps(REVS | change).replace("Infinity", "1e999"))
    with pytest.raises(ParameterError, match=message):
        read_vehicle(path)


def test_plausible_vehicles_pass():
    VehicleParams().check_plausible()
    VehicleParams(**REVS).check_plausible()
    # a 1/10-scale model car
    VehicleParams(m=3.5, Iz=0.05, lf=0.16, lr=0.17, Cf=4.0 * 3.5 * 9.81 / 4, Cr=4.5 * 3.5 * 9.81 / 4, vx=3.0,
                  width=0.3, track=0.25, h_cg=0.05).check_plausible()


def test_vehicle_file_other_problems(tmp_path):
    path = tmp_path / "v.json"
    path.write_text("[1, 2]")
    with pytest.raises(ParameterError, match="expected a JSON object"):
        read_vehicle(path)
    path.write_bytes(b"\x1f\x8b\x08\x00\xff\xfe")
    with pytest.raises(ParameterError, match="cannot read vehicle file|not valid JSON"):
        read_vehicle(path)
    with pytest.raises(ParameterError, match="cannot read vehicle file"):
        read_vehicle(tmp_path / "missing.json")


def test_camera_values_must_be_numbers_naming_the_key():
    with pytest.raises(ParameterError, match=r"CameraParams\.rate must be a number, got '20'"):
        CameraParams.from_dict({"rate": "20"})
    with pytest.raises(ParameterError, match=r"CameraParams\.latency must be a number, got True"):
        CameraParams(latency=True)
    with pytest.raises(ParameterError, match=r"CameraParams\.noise must be a string"):
        CameraParams(noise=1)
    assert CameraParams(rate=20).rate == 20  # an int is a number
