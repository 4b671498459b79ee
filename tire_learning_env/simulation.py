"""Closed-loop simulation: truth plant + lane camera + lane-keeping driver on a road.

:class:`Simulator` is the one loop every environment and every command shares. Each
physics tick ``t_j`` it

1. lets the camera take/deliver a frame of the true ``e1``, ``e2``,
2. asks the driver for the steering from the latest delivered frame (plus an optional
   steering offset, or a full steering override),
3. integrates the plant over ``[t_j, t_j + dt]``,

and records a row of what a car would know (:attr:`SimulationLog.sensors`) and of ground
truth (for scoring only). Row ``j`` holds everything at ``t_j``: the frame delivered at
``t_j`` (NaN if none), the steering applied from ``t_j``, the truth state at ``t_j``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np
from numpy.typing import NDArray

from ._kernels import GUARD_AY, LOG_COLUMNS, N_LOG, advance_bicycle, guard_steering, road_lookup
from .driver import LaneKeepingDriver
from .dynamics import BicyclePlant, PlantEffects
from .params import CameraParams, DriverParams, ParameterError, RoadParams, TireParams, VehicleParams
from .roads import Road, make_road
from .sensors import Camera
from .tires import TireModel, axle_tires

__all__ = ["Plant", "RoadTable", "Simulator", "SimulationLog", "simulate", "SENSOR_KEYS", "TRUTH_KEYS"]

SENSOR_KEYS = ("t", "delta", "vx", "ax", "kappa", "psi_dot_des", "psi_ddot_des", "e1", "e2", "yaw_rate", "ay")
TRUTH_KEYS = ("true_state", "true_slip", "true_force", "true_force_nonlinear", "s")


class Plant(Protocol):
    """What :class:`Simulator` needs from a truth vehicle (see :class:`~.dynamics.BicyclePlant`)."""

    vehicle: VehicleParams
    state: list

    def reset(self, xi=None) -> None: ...

    def step(self, delta: float, dt: float, psi_dot_des, psi_ddot_des, vx: float, ax: float): ...


class RoadTable:
    """A road sampled every ``ds`` metres for fast scalar lookups in the physics loop.

    Linear interpolation of ``kappa`` and ``dkappa/ds``
    (:func:`~tire_learning_env._kernels.road_lookup`); exact for the piecewise-linear
    roads when knots fall on the grid, second-order accurate otherwise. The table grows
    on demand (:meth:`cover`).
    """

    def __init__(self, road: Road, ds: float = 0.05, length: float = 500.0) -> None:
        self.road = road
        self.ds = float(ds)
        self.kappa = np.zeros(0)
        self.dkappa = np.zeros(0)
        self.cover(length)

    def cover(self, length: float) -> None:
        """Make the table reach at least ``length`` metres (doubling when it grows)."""
        n_old = len(self.kappa)
        if n_old and (n_old - 2) * self.ds >= length:
            return
        n_new = max(int(math.ceil(length / self.ds)) + 2, 2 * n_old)
        s = np.arange(n_old, n_new) * self.ds
        self.kappa = np.ascontiguousarray(np.concatenate([self.kappa, self.road.curvature(s)]))
        self.dkappa = np.ascontiguousarray(np.concatenate([self.dkappa, self.road.curvature_rate(s)]))

    def lookup(self, s: float) -> tuple[float, float]:
        """``(kappa, dkappa/ds)`` at distance ``s`` [m]."""
        self.cover(s + 1.0)
        return road_lookup(s, self.kappa, self.dkappa, self.ds)


@dataclass
class SimulationLog:
    """Per-tick record of a simulation (row ``j`` = instant ``t_j``).

    ``sensors`` holds what a car knows (:data:`SENSOR_KEYS`; ``e1``/``e2`` are NaN on
    ticks without a delivered frame). ``truth`` holds ground truth for scoring
    (:data:`TRUTH_KEYS`); estimators must never read it.
    """

    sensors: dict[str, NDArray]
    truth: dict[str, NDArray]
    dt: float
    vehicle: VehicleParams
    meta: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.sensors["t"])

    @staticmethod
    def concatenate(logs: list["SimulationLog"]) -> "SimulationLog":
        """Join consecutive logs (e.g. the chunks of an episode)."""
        if not logs:
            raise ValueError("nothing to concatenate")
        sensors = {k: np.concatenate([lg.sensors[k] for lg in logs]) for k in logs[0].sensors}
        truth = {k: np.concatenate([lg.truth[k] for lg in logs]) for k in logs[0].truth}
        return SimulationLog(sensors, truth, logs[0].dt, logs[0].vehicle, dict(logs[0].meta))

    def to_columns(self, include_truth: bool = True) -> dict[str, NDArray]:
        """Columns of the shared driving-log format (``LOG_FORMAT.md``)."""
        s = self.sensors
        cols = {k: s[k] for k in ("t", "vx", "delta", "kappa", "e1", "e2", "yaw_rate", "ay", "ax")}
        if include_truth:
            x = self.truth["true_state"]
            cols.update(
                true_e1=x[:, 0],
                true_e1_dot=x[:, 1],
                true_e2=x[:, 2],
                true_e2_dot=x[:, 3],
                true_alpha_f=self.truth["true_slip"][:, 0],
                true_alpha_r=self.truth["true_slip"][:, 1],
                true_Fyf=self.truth["true_force"][:, 0],
                true_Fyr=self.truth["true_force"][:, 1],
                true_vy=x[:, 1] - s["vx"] * x[:, 2],
            )
            cols["true_beta"] = np.arctan2(cols["true_vy"], s["vx"])
        return cols


class Simulator:
    """Truth plant + camera + driver on a road, advanced tick by tick.

    Parameters
    ----------
    plant : Plant
        Truth vehicle (e.g. :class:`~.dynamics.BicyclePlant`).
    road : Road
        Reference path.
    camera : CameraParams
        Camera model.
    driver : DriverParams
        Built-in lane-keeping controller gains.
    driver_vehicle : VehicleParams
        Nominal vehicle the driver's feed-forward assumes (default ``plant.vehicle``).
    physics_dt : float
        Integration step [s].
    speed_profile : callable, optional
        ``t -> (vx [m/s], ax [m/s^2])``; default constant ``plant.vehicle.vx``.
    """

    def __init__(
        self,
        plant: Plant,
        road: Road,
        camera: CameraParams,
        driver: DriverParams,
        driver_vehicle: VehicleParams | None = None,
        physics_dt: float = 1e-3,
        speed_profile: Callable[[float], tuple[float, float]] | None = None,
    ) -> None:
        if not physics_dt > 0:
            raise ParameterError(f"physics_dt must be > 0, got {physics_dt!r}")
        self.plant = plant
        self.road = road
        self.table = RoadTable(road)
        self.dt = float(physics_dt)
        self.camera = Camera(camera, self.dt)
        self.driver = LaneKeepingDriver(driver, driver_vehicle or plant.vehicle)
        self.speed_profile = speed_profile
        self._vx0 = (float(plant.vehicle.vx), 0.0)
        self._speed = self._constant_speed if speed_profile is None else self._profile_speed
        self.reset(np.random.default_rng(0))

    def reset(self, rng: np.random.Generator, xi0=None) -> None:
        """Back to ``t = 0``, ``s = 0`` with initial error state ``xi0`` (default zero)."""
        self.t = 0.0
        self.s = 0.0
        self.tick_index = 0
        self.plant.reset(xi0)
        self.camera.reset(rng)
        self.driver.reset()
        self.last_delta = 0.0

    def speed_at(self, t: float) -> tuple[float, float]:
        """Speed [m/s] and longitudinal acceleration [m/s^2] at time ``t`` [s] (the profile, or constant)."""
        return self._speed(t)

    def _constant_speed(self, t: float) -> tuple[float, float]:
        return self._vx0

    def _profile_speed(self, t: float) -> tuple[float, float]:
        vx, ax = self.speed_profile(t)
        if not vx > 0:
            raise ParameterError(f"speed profile gave vx={vx!r} at t={t:.3f} s; it must stay > 0")
        return float(vx), float(ax)

    def advance(
        self, n_ticks: int, steering_offset: float = 0.0, steering: float | None = None
    ) -> SimulationLog:
        """Run ``n_ticks`` physics ticks.

        Parameters
        ----------
        n_ticks : int
            Number of ticks.
        steering_offset : float
            Added to the driver's steering [rad].
        steering : float, optional
            If given, replaces the driver (full steering) [rad].

        Returns
        -------
        SimulationLog
        """
        out = np.empty((n_ticks, N_LOG))
        self.camera.ensure_noise(n_ticks)
        use_kernel = self.speed_profile is None and hasattr(self.plant, "kernel_params")
        if use_kernel:
            self._advance_compiled(n_ticks, steering_offset, steering, out)
        else:
            self._advance_python(n_ticks, steering_offset, steering, out)
        self.tick_index += n_ticks
        self.t = self.tick_index * self.dt
        return self._log(out)

    def _advance_compiled(self, n_ticks: int, steering_offset: float, steering: float | None, out: NDArray) -> None:
        vx, ax = self._vx0
        self.table.cover(self.s + (n_ticks + 2) * self.dt * vx + 1.0)
        s, delta, done = advance_bicycle(
            n_ticks, self.dt, self.tick_index, self.plant.state, self.s, vx, ax, *self.plant.kernel_params(),
            self.table.kappa, self.table.dkappa, self.table.ds, *self.camera.kernel_args(),
            self.driver.param_vec, self.driver.state, self.driver.guard, float(steering_offset),
            math.nan if steering is None else float(steering), self.last_delta, out,
        )  # fmt: skip
        if done < n_ticks:
            t = (self.tick_index + done) * self.dt
            raise FloatingPointError(
                f"simulation blew up at t={t:.4f} s: state {self.plant.state.tolist()}, delta={delta}"
            )
        self.s, self.last_delta = s, delta
        # the inputs held at the end of the chunk, as BicyclePlant.step records them (for output())
        k, dk = self.table.lookup(s)
        vx_end = vx + self.dt * ax
        self.plant.hold_inputs(delta, vx_end, ax, vx_end * k, vx_end * vx_end * dk + ax * k)

    def _advance_python(self, n_ticks: int, steering_offset: float, steering: float | None, out: NDArray) -> None:
        """The same tick sequence as :func:`._kernels.advance_bicycle`, for any plant."""
        dt, plant, cam, drv = self.dt, self.plant, self.camera, self.driver
        max_steer = drv.params.max_steering
        s, delta = self.s, self.last_delta
        for j in range(n_ticks):
            t = (self.tick_index + j) * dt
            vx, ax = self._speed(t)
            vx_mid, vx_end = vx + 0.5 * dt * ax, vx + dt * ax
            k0, dk0 = self.table.lookup(s)
            k1, dk1 = self.table.lookup(s + 0.5 * dt * vx)
            s_end = s + 0.5 * dt * (vx + vx_end)
            k2, dk2 = self.table.lookup(s_end)
            state = plant.state
            frame = cam.tick(t, state[0], state[2])
            delta_prev = delta
            if steering is None:
                delta = drv.steer(*cam.latest, k0, vx, dt) + steering_offset
            else:
                delta = steering
            delta = guard_steering(min(max(delta, -max_steer), max_steer), delta_prev, drv.guard)
            delta = min(max(delta, -max_steer), max_steer)
            p0, q0 = vx * k0, vx * vx * dk0 + ax * k0
            out[j, 11:15] = state[:4]
            af, ar, Fyf, Fyr, r, ay = plant.step(
                delta,
                dt,
                (p0, vx_mid * k1, vx_end * k2),
                (q0, vx_mid * vx_mid * dk1 + ax * k1, vx_end * vx_end * dk2 + ax * k2),
                vx,
                ax,
            )
            drv.guard[GUARD_AY] = ay
            e1f, e2f = frame if frame is not None else (math.nan, math.nan)
            out[j, :11] = (t, delta, vx, ax, k0, p0, q0, e1f, e2f, r, ay)
            out[j, 15:] = (af, ar, Fyf, Fyr, s)
            s = s_end
        self.s, self.last_delta = s, delta

    def _log(self, out: NDArray) -> SimulationLog:
        col = {name: i for i, name in enumerate(LOG_COLUMNS)}
        veh = self.plant.vehicle
        sensors = {key: out[:, col[key]].copy() for key in SENSOR_KEYS}
        slip = out[:, col["alpha_f"] : col["alpha_r"] + 1].copy()
        force = out[:, col["Fyf"] : col["Fyr"] + 1].copy()
        truth = {
            "true_state": out[:, col["true_e1"] : col["true_e2_dot"] + 1].copy(),
            "true_slip": slip,
            "true_force": force,
            "true_force_nonlinear": force - slip * np.array([2.0 * veh.Cf, 2.0 * veh.Cr]),
            "s": out[:, col["s"]].copy(),
        }
        return SimulationLog(sensors, truth, self.dt, veh)


def simulate(
    road: str | Road = "study1",
    duration: float = 60.0,
    vehicle: VehicleParams | None = None,
    tire_model: str = "pacejka",
    tire: TireParams | None = None,
    tires: tuple[TireModel, TireModel] | None = None,
    camera: CameraParams | None = None,
    driver: DriverParams | None = None,
    effects: PlantEffects | None = None,
    road_params: RoadParams | None = None,
    physics_rate: float = 1000.0,
    seed: int | None = 0,
    speed_profile: Callable[[float], tuple[float, float]] | None = None,
    plant: Plant | None = None,
) -> SimulationLog:
    """Closed-loop run of the low-order truth vehicle (or ``plant``) with the built-in driver.

    Parameters
    ----------
    road : str or Road
        Built-in road name (``study1``, ``straight``, ``lane_change``, ``lane_changes``,
        ``sine``, ``chirp``) or a :class:`~.roads.Road`.
    duration : float
        Simulated time [s].
    vehicle : VehicleParams, optional
        Truth vehicle (default: the paper's sedan).
    tire_model : {"pacejka", "linear"}
        Truth axle tires when ``tires`` is not given.
    tires : tuple of TireModel, optional
        Explicit front/rear truth tires.
    seed : int, optional
        Seed of the camera noise.

    Returns
    -------
    SimulationLog
    """
    vehicle = vehicle or VehicleParams()
    if plant is None:
        front, rear = tires if tires is not None else axle_tires(vehicle, tire_model, tire)
        plant = BicyclePlant(vehicle, front, rear, effects)
    sim = Simulator(
        plant,
        make_road(road, road_params),
        camera or CameraParams(),
        driver or DriverParams(),
        physics_dt=1.0 / physics_rate,
        speed_profile=speed_profile,
    )
    sim.reset(np.random.default_rng(seed))
    n = int(round(duration * physics_rate))
    log = sim.advance(n)
    log.meta.update(road=road if isinstance(road, str) else type(road).__name__, duration=duration, seed=seed)
    return log
