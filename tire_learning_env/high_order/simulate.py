"""Closed-loop runs of the high-order plant and its quasi-steady (effective) axle stiffness.

Why two stiffness figures: :func:`~.plant.true_cornering_stiffness` is the *tire's* slope at
zero slip at static load (what the issue asks to score against). A bicycle-model observer,
however, sees the *axle* force against the bicycle slip of eq. (13), and in the multi-body
model that relation also contains the camber thrust of the rolling body (CommonRoad's
``p_hy3``, ``p_vy3`` with roll camber ``gamma = roll + D z_s``) and the suspension
compliances. Vehicle dynamicists call the resulting slope the *effective axle cornering
stiffness* (Bundorf's cornering compliance). :func:`effective_cornering_stiffness` measures
it from steady-state circles: it is what a bicycle model fitted to this vehicle recovers.
"""

from __future__ import annotations

import numpy as np

from ..params import CameraParams
from ..roads import PiecewiseCurvatureRoad, Road, make_road
from ..simulation import SimulationLog, simulate
from .params import HighOrderConfig, MultiBodyParams
from .plant import MultiBodyPlant, register_closed_loop_references

__all__ = ["simulate_high_order", "steady_state_cornering", "effective_cornering_stiffness", "steady_state_axle_curves"]


def simulate_high_order(road: str | Road = "lane_changes", duration: float = 60.0, **kwargs) -> SimulationLog:
    """Closed-loop run of the high-order plant with the built-in driver and camera.

    Keyword arguments ``params``, ``config``, ``record`` go to :class:`~.plant.MultiBodyPlant`;
    the rest (``camera``, ``driver``, ``road_params``, ``physics_rate``, ``seed``,
    ``speed_profile``) to :func:`tire_learning_env.simulation.simulate`.

    Returns
    -------
    SimulationLog
        ``log.vehicle`` is the equivalent bicycle; ``log.meta["plant"]`` the plant (for
        :meth:`~.plant.MultiBodyPlant.history` with ``record=True``).
    """
    plant_kw = {k: kwargs.pop(k) for k in ("params", "config", "record") if k in kwargs}
    road_obj = make_road(road, kwargs.get("road_params"))
    plant = MultiBodyPlant(road_obj, **plant_kw)
    log = simulate(road_obj, duration, vehicle=plant.vehicle, plant=plant, **kwargs)
    log.meta.update(road=road if isinstance(road, str) else type(road).__name__, plant=plant)
    return log


def steady_state_cornering(
    radius: float,
    params: MultiBodyParams | None = None,
    config: HighOrderConfig | None = None,
    duration: float = 6.0,
    average: float = 1.0,
) -> dict[str, float]:
    """Drive a circle of ``radius`` [m] (positive: left) at the set-point speed until steady.

    The built-in driver follows a constant-curvature road from ``s = 0``; the last
    ``average`` seconds are averaged.

    Returns
    -------
    dict
        ``alpha_f``, ``alpha_r`` [rad], ``Fyf``, ``Fyr`` [N], ``ay`` [m/s^2], ``vx``
        [m/s] (actual), ``yaw_rate`` [rad/s], ``e1`` [m].
    """
    kappa = 1.0 / radius
    road = PiecewiseCurvatureRoad((0.0, 1e6), (kappa, kappa))
    log = simulate_high_order(road, duration, params=params, config=config, record=True, camera=CameraParams())
    n = int(round(average / log.dt))
    hist = log.meta["plant"].history()
    return {
        "alpha_f": float(np.mean(log.truth["true_slip"][-n:, 0])),
        "alpha_r": float(np.mean(log.truth["true_slip"][-n:, 1])),
        "Fyf": float(np.mean(log.truth["true_force"][-n:, 0])),
        "Fyr": float(np.mean(log.truth["true_force"][-n:, 1])),
        "ay": float(np.mean(log.sensors["ay"][-n:])),
        "vx": float(np.mean(hist["vx"][-n:])),
        "yaw_rate": float(np.mean(log.sensors["yaw_rate"][-n:])),
        "e1": float(np.mean(log.truth["true_state"][-n:, 0])),
    }


def effective_cornering_stiffness(
    params: MultiBodyParams | None = None, config: HighOrderConfig | None = None, radius: float = 4000.0
) -> tuple[float, float]:
    """Effective per-tire cornering stiffness front/rear [N/rad] seen by a bicycle model.

    Half the slope of the steady-state axle force against the axle slip of eq. (13)
    between left and right circles of ``radius`` (default 4000 m: ``a_y`` about 0.22
    m/s^2 at 30 m/s, well inside the linear range).
    """
    left = steady_state_cornering(radius, params, config)
    right = steady_state_cornering(-radius, params, config)
    cf = 0.5 * (left["Fyf"] - right["Fyf"]) / (left["alpha_f"] - right["alpha_f"])
    cr = 0.5 * (left["Fyr"] - right["Fyr"]) / (left["alpha_r"] - right["alpha_r"])
    return cf, cr


def steady_state_axle_curves(
    params: MultiBodyParams | None = None,
    config: HighOrderConfig | None = None,
    ay_max: float = 4.0,
    count: int = 8,
    vx: float = 30.0,
) -> dict[str, np.ndarray]:
    """The effective (quasi-steady) axle curves: axle force vs eq. (13) slip on steady circles.

    ``count`` left and ``count`` right circles with lateral accelerations spread evenly up
    to ``ay_max`` [m/s^2] at the set-point speed ``vx`` [m/s], plus the straight-line
    origin. This is the characteristic a bicycle model fitted to the multi-body vehicle
    should learn (tire curve plus roll-camber thrust and compliance effects); scoring a
    learned curve against it, by interpolation in ``alpha``, avoids the scatter of
    per-sample truth (relaxation lag, steering jitter with a noisy camera).

    Returns
    -------
    dict
        ``ay`` [m/s^2], ``alpha_f``, ``alpha_r`` [rad], ``Fyf``, ``Fyr`` [N], sorted by ``ay``.
    """
    ays = np.linspace(ay_max / count, ay_max, count)
    rows = [dict(alpha_f=0.0, alpha_r=0.0, Fyf=0.0, Fyr=0.0, ay=0.0)]
    for ay in ays:
        for sign in (1.0, -1.0):
            rows.append(steady_state_cornering(sign * vx * vx / ay, params, config))
    rows.sort(key=lambda r: r["ay"])
    return {k: np.array([r[k] for r in rows]) for k in ("ay", "alpha_f", "alpha_r", "Fyf", "Fyr")}


register_closed_loop_references(effective_cornering_stiffness, steady_state_axle_curves)
