"""Scenarios (``tire_learning_env.scenarios``): hidden-effect names mapped onto the truth plant, camera and
wrappers, the effect plant, the speed profiles and the identification road."""

from __future__ import annotations

import numpy as np
import pytest

from tire_learning_env.params import ParameterError, VehicleParams
from tire_learning_env.scenarios import EffectPlant, IdentificationRoad, parse_hidden_effects, speed_profile
from tire_learning_env.tires import axle_tires


def test_hidden_effect_names_map_onto_the_truth_model():
    h = parse_hidden_effects({"tire_relaxation": 0.4, "camera_latency": 0.05, "cornering_stiffness_scale": 0.9,
                              "crosswind": 200.0, "bank_angle": 0.01})  # fmt: skip
    assert h.plant.relaxation_length == 0.4 and h.plant.bank_angle == 0.01 and h.plant.crosswind_force == 200.0
    assert h.plant.cornering_stiffness_scale_front == h.plant.cornering_stiffness_scale_rear == 0.9
    assert h.camera == {"latency": 0.05}
    with pytest.raises(ParameterError, match="unknown effect 'gremlins'"):
        parse_hidden_effects({"gremlins": 1.0})
    v = VehicleParams()
    plant = parse_hidden_effects({"speed_dependent_stiffness": 1e-4}).make_plant(v, *axle_tires(v))
    assert isinstance(plant, EffectPlant)
    assert plant.true_cornering_stiffness()[0] == pytest.approx(v.Cf * (1 - 1e-4 * v.vx**2), rel=1e-5)


def test_speed_profile_and_identification_road():
    prof = speed_profile("sine", 30.0)
    v, a = prof(10.0)
    assert v == pytest.approx(30.0 * 1.25) and abs(a) < 1e-9
    with pytest.raises(ParameterError, match="unknown speed profile"):
        speed_profile("warp", 30.0)
    road = IdentificationRoad()
    s = np.linspace(0, 3600, 7201)
    k = road.curvature(s)
    assert np.max(k) > 1 / 260 and np.min(k) < -1 / 260  # curves both ways
    np.testing.assert_allclose(road.curvature(s[:3600] + 1800.0), k[:3600], atol=1e-12)  # periodic
