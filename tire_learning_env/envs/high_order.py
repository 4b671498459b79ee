"""The lane-keeping environment on the high-order truth vehicle."""

from __future__ import annotations

from typing import Any, Mapping

from ..high_order.params import HighOrderConfig, MultiBodyParams, bmw_320i
from ..high_order.plant import MultiBodyPlant, equivalent_bicycle
from ..params import CameraParams, DriverParams, RoadParams, VehicleParams, coerce_params
from ..roads import Road, make_road
from .lane_keeping import LaneKeepingEnv

__all__ = ["HighOrderLaneKeepingEnv"]


class HighOrderLaneKeepingEnv(LaneKeepingEnv):
    """:class:`~tire_learning_env.envs.LaneKeepingEnv` whose truth vehicle is the multi-body model.

    ## Description

    Identical to ``LaneKeepingEnv`` (same spaces, reward, termination, ``info`` keys:
    ``true_state``, ``true_slip``, ``true_force``, ``true_force_nonlinear``,
    ``sensor_log``, ``truth_log``) except for the truth vehicle: CommonRoad's 29-state
    multi-body model (:class:`~tire_learning_env.high_order.MultiBodyPlant`, default
    parameter set CommonRoad vehicle 2, a BMW 320i, with its PAC2002 tires, a 0.45 m tire
    relaxation length and a PI speed controller holding the set-point speed). The camera
    sees ``e1``/``e2`` of the sprung-mass CG relative to the road's geometry. Ground truth:
    axle forces are the sum of the two tires' lateral forces in the body frame, axle slips
    are eq. (13) of the body velocities (see ``docs/high_order.md``).

    ## Arguments

    As ``LaneKeepingEnv`` without ``tire``, ``tire_model``, ``tires`` and ``effects`` (the
    tires are part of the multi-body model), plus ``high_order`` (a
    :class:`~tire_learning_env.high_order.MultiBodyParams` or dict) and ``high_order_config``
    (a :class:`~tire_learning_env.high_order.HighOrderConfig` or dict). ``vehicle`` is the
    nominal bicycle the built-in driver and estimators assume (default: the plant's
    equivalent bicycle, :func:`~tire_learning_env.high_order.equivalent_bicycle`, with the
    true per-tire cornering stiffness at static load); its ``vx`` is the speed set-point.

    ## Version History

    * v0: initial release.
    """

    _CONFIG_KEYS = tuple(
        k for k in LaneKeepingEnv._CONFIG_KEYS if k not in ("tire", "tire_model", "tires", "effects")
    ) + ("high_order", "high_order_config")

    def __init__(
        self,
        road: str | Road = "study1",
        high_order: MultiBodyParams | Mapping | None = None,
        high_order_config: HighOrderConfig | Mapping | None = None,
        vehicle: VehicleParams | Mapping | None = None,
        camera: CameraParams | Mapping | None = None,
        driver: DriverParams | Mapping | None = None,
        road_params: RoadParams | Mapping | None = None,
        physics_rate: float = 1000.0,
        policy_rate: float = 20.0,
        action_mode: str = "offset",
        max_steering_offset: float = 0.05,
        departure_threshold: float | None = None,
        initial_state_std: tuple[float, float, float, float] | None = None,
        render_mode: str | None = None,
        config: Mapping[str, Any] | None = None,
    ) -> None:
        args = dict(
            road=road,
            high_order=high_order,
            high_order_config=high_order_config,
            vehicle=vehicle,
            camera=camera,
            driver=driver,
            road_params=road_params,
            physics_rate=physics_rate,
            policy_rate=policy_rate,
            action_mode=action_mode,
            max_steering_offset=max_steering_offset,
            departure_threshold=departure_threshold,
            initial_state_std=initial_state_std,
        )
        args = self._merge_config(args, config)
        self.high_order_params: MultiBodyParams = (
            coerce_params(MultiBodyParams, args.pop("high_order"), "high_order") or bmw_320i()
        )
        self.high_order_config: HighOrderConfig = (
            coerce_params(HighOrderConfig, args.pop("high_order_config"), "high_order_config") or HighOrderConfig()
        )
        rp = self._params("road_params", args["road_params"])
        road_obj = make_road(args["road"], rp)
        if args["vehicle"] is None:
            args["vehicle"] = equivalent_bicycle(self.high_order_params)
        params, cfg = self.high_order_params, self.high_order_config

        def plant_factory(v: VehicleParams) -> MultiBodyPlant:
            return MultiBodyPlant(road_obj, params, cfg, vx=v.vx)

        args["road"] = road_obj
        args["road_params"] = rp
        super().__init__(**args, render_mode=render_mode, plant_factory=plant_factory)
