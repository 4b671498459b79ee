"""tire_learning_env: learn a car's tire model while it drives, from the lane camera.

Importing the package registers the Gymnasium ids (see :data:`registration.ENV_IDS`).
"""

from .params import CameraParams, DriverParams, ParameterError, RoadParams, TireParams, VehicleParams
from .dynamics import BicyclePlant, PlantEffects, error_state_matrices, slip_angles
from .tires import LinearTire, PacejkaTire, axle_tires
from .roads import make_road
from .simulation import SimulationLog, Simulator, simulate
from .registration import ENV_IDS, register_envs

__version__ = "0.1.0"

register_envs()

__all__ = [
    "__version__",
    "VehicleParams",
    "TireParams",
    "RoadParams",
    "CameraParams",
    "DriverParams",
    "ParameterError",
    "PlantEffects",
    "BicyclePlant",
    "error_state_matrices",
    "slip_angles",
    "LinearTire",
    "PacejkaTire",
    "axle_tires",
    "make_road",
    "simulate",
    "Simulator",
    "SimulationLog",
    "ENV_IDS",
    "register_envs",
]
