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
