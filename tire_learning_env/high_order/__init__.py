"""High-order truth vehicle: CommonRoad's multi-body model (the paper's CarSim role).

The paper validated its observer on CarSim, a high-order model whose internals the observer
never sees. Here that role is played by the multi-body model of ``commonroad-vehicle-models``
(29 states: sprung mass with roll, pitch and heave, front/rear unsprung masses with roll and
compliant lateral joints, four wheel spins, PAC2002 combined-slip tires), ported to numba
(:mod:`._mb_kernels`, tested against CommonRoad's own ``vehicle_dynamics_mb``) and extended
with a tire relaxation length, a steering servo option and a PI speed controller.

- :mod:`.params`: :class:`MultiBodyParams` (CommonRoad's fields, strict validation),
  :class:`HighOrderConfig` (relaxation, steering, speed control), :func:`bmw_320i`.
- :mod:`.plant`: :class:`MultiBodyPlant` (the plant interface of
  :class:`~tire_learning_env.simulation.Simulator`), ground-truth conventions,
  :func:`true_cornering_stiffness`, :func:`equivalent_bicycle`.
- :mod:`.simulate`: :func:`simulate_high_order` (closed loop with the built-in driver and
  camera), :func:`steady_state_cornering`, :func:`effective_cornering_stiffness`,
  :func:`steady_state_axle_curves` (the scoring references for a bicycle-model estimator).
- The lane-keeping env on this plant is :class:`tire_learning_env.envs.high_order.HighOrderLaneKeepingEnv`
  (``TireLearning-HighOrderCornering-v0``, ``TireLearning-HighOrderLaneChange-v0``).

The mapping (parameter set, units, what "axle force" means, relaxation) is documented in
``docs/high_order.md``.
"""

from .params import COMMONROAD_TIRE, COMMONROAD_VEHICLE2, HighOrderConfig, LongitudinalLimits, MultiBodyParams, Pac2002Tire, SteeringLimits, bmw_320i
from .plant import MultiBodyPlant, equivalent_bicycle, static_wheel_loads, tire_lateral_force, true_cornering_stiffness
from .simulate import effective_cornering_stiffness, simulate_high_order, steady_state_axle_curves, steady_state_cornering

__all__ = [
    "MultiBodyParams",
    "Pac2002Tire",
    "SteeringLimits",
    "LongitudinalLimits",
    "HighOrderConfig",
    "COMMONROAD_VEHICLE2",
    "COMMONROAD_TIRE",
    "bmw_320i",
    "MultiBodyPlant",
    "equivalent_bicycle",
    "static_wheel_loads",
    "tire_lateral_force",
    "true_cornering_stiffness",
    "simulate_high_order",
    "steady_state_cornering",
    "effective_cornering_stiffness",
    "steady_state_axle_curves",
]

