"""Hidden-effect truth data: moved to :mod:`tire_learning_env.scenarios` (below the analysis layer).

Kept so that code written against ``tire_learning_env.discrepancy.truth`` (the notebooks, user
scripts) keeps working; new code imports from :mod:`tire_learning_env.scenarios`.
"""

from ..scenarios import (  # noqa: F401
    HIDDEN_EFFECTS,
    SCENARIO_ROADS,
    SPEED_PROFILES,
    CurvesRoad,
    EffectPlant,
    HiddenEffects,
    IdentificationRoad,
    parse_hidden_effects,
    simulate_hidden,
    speed_profile,
    steering_nonlinearity_gain,
)

#: the test roads under their former name
DISCREPANCY_ROADS = SCENARIO_ROADS

__all__ = [
    "simulate_hidden",
    "IdentificationRoad",
    "CurvesRoad",
    "DISCREPANCY_ROADS",
    "HIDDEN_EFFECTS",
    "HiddenEffects",
    "parse_hidden_effects",
    "EffectPlant",
    "SPEED_PROFILES",
    "speed_profile",
    "steering_nonlinearity_gain",
]
