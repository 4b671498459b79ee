"""Hidden-effect truth data: moved to :mod:`tire_learning_env.scenarios` (below the analysis layer).

Kept so that code written against ``tire_learning_env.discrepancy.truth`` (the notebooks, user
scripts) keeps working; new code imports from :mod:`tire_learning_env.scenarios`.
"""

from .. import scenarios as _scenarios
from ..scenarios import *  # noqa: F401,F403  (the public names of the scenarios module)
from ..scenarios import SCENARIO_ROADS, steering_nonlinearity_gain  # noqa: F401

#: the test roads under their former name
DISCREPANCY_ROADS = SCENARIO_ROADS

__all__ = [*_scenarios.__all__, "DISCREPANCY_ROADS", "steering_nonlinearity_gain"]
