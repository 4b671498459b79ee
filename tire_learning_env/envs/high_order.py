"""The lane-keeping environment on the high-order truth vehicle."""

from __future__ import annotations

from typing import Any, Mapping

from ..high_order.params import HighOrderConfig, MultiBodyParams, bmw_320i
from ..high_order.plant import MultiBodyPlant, equivalent_bicycle
from ..params import VehicleParams, coerce_params
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

    As ``LaneKeepingEnv`` (keyword arguments after ``high_order_config``) without ``tire``,
    ``tire_model``, ``tires``, ``effects`` and ``plant_factory`` (the tires are part of the
    multi-body model; ``TypeError``), plus ``high_order`` (a
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

    #: ``LaneKeepingEnv`` arguments of the bicycle's truth tires, refused here.
    _BICYCLE_ONLY = ("tire", "tire_model", "tires", "effects", "plant_factory")

    def __init__(
        self,
        road: str | Road = "study1",
        high_order: MultiBodyParams | Mapping | None = None,
        high_order_config: HighOrderConfig | Mapping | None = None,
        render_mode: str | None = None,
        config: Mapping[str, Any] | None = None,
        **kwargs: Any,
    ) -> None:
        rejected = [k for k in self._BICYCLE_ONLY if k in kwargs]
        if rejected:
            raise TypeError(
                f"{type(self).__name__} got unexpected keyword argument(s) {rejected}: the multi-body model has its own tires"
            )
        args = self._merge_config({"road": road, "high_order": high_order, "high_order_config": high_order_config, **kwargs}, config)
        self.high_order_params: MultiBodyParams = (
            coerce_params(MultiBodyParams, args.pop("high_order"), "high_order") or bmw_320i()
        )
        self.high_order_config: HighOrderConfig = (
            coerce_params(HighOrderConfig, args.pop("high_order_config"), "high_order_config") or HighOrderConfig()
        )
        rp = self._params("road_params", args.get("road_params"))
        road_obj = make_road(args["road"], rp)
        if args.get("vehicle") is None:
            args["vehicle"] = equivalent_bicycle(self.high_order_params)
        params, cfg = self.high_order_params, self.high_order_config

        def plant_factory(v: VehicleParams) -> MultiBodyPlant:
            return MultiBodyPlant(road_obj, params, cfg, vx=v.vx)

        args["road"] = road_obj
        args["road_params"] = rp
        super().__init__(**args, render_mode=render_mode, plant_factory=plant_factory)
