"""Scripted excitation manoeuvres (scripted.py): the catalogue, amplitude tuning, their scores."""

import numpy as np
import pytest

from tire_learning_env.params import ParameterError
from tire_learning_env.scripted import MANOEUVRES, LaneChanges, SineWeave, make_manoeuvre, run_manoeuvre, tune_amplitude
from tire_learning_env.wrappers.excitation import ExcitationConfig


def test_manoeuvres_by_name_and_unknown_parameters():
    assert set(MANOEUVRES) == {"none", "cornering", "lane_changes", "sine_road", "chirp_road", "sine_weave", "chirp_weave"}
    assert make_manoeuvre("sine_weave", frequency=0.4).frequency == 0.4
    with pytest.raises(ParameterError, match="wobble"):
        make_manoeuvre("sine_weave", wobble=1)
    with pytest.raises(ParameterError, match="unknown manoeuvre"):
        make_manoeuvre("donuts")
    for name in MANOEUVRES:
        m = make_manoeuvre(name)
        m.road().curvature(np.linspace(0, 2000, 50))
        assert abs(m.offset(10.0)) <= 0.05


def test_tuning_reaches_but_respects_the_acceleration_limit():
    tuned = tune_amplitude(LaneChanges(), seeds=(10_000,), iterations=7, duration=12.0)
    limit = ExcitationConfig().ay_limit
    assert 0.8 * limit < tuned.max_abs_ay <= 0.95 * limit
    weave = tune_amplitude(SineWeave(frequency=0.4), seeds=(10_000,), iterations=7, duration=12.0)
    assert weave.max_abs_ay <= 0.95 * limit and weave.max_abs_e1 <= 0.95 * ExcitationConfig().lane_margin
    assert weave.max_abs_ay > 0.7 * limit or weave.max_abs_e1 > 0.7 * ExcitationConfig().lane_margin


def test_excitation_beats_lane_keeping_on_a_straight_road():
    """Sanity of the scoring: weaving at the limit learns the curve, plain lane keeping does not."""
    idle = run_manoeuvre(make_manoeuvre("none"), seed=1000, duration=20.0)
    weave = run_manoeuvre(SineWeave(amplitude=0.016, frequency=0.4), seed=1000, duration=20.0)
    assert weave["tire_curve_nrmse_max"] < 0.5 * idle["tire_curve_nrmse_max"]
    assert weave["target_coverage"]["front"] > 0.6 > 0.4 > idle["target_coverage"]["front"]
    assert weave["lane_violation_steps"] == 0 and weave["max_abs_ay"] < 4.0
    assert idle["convergence_time_s"] is None or idle["convergence_time_s"] > weave["convergence_time_s"]
