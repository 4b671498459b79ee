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

from ._kernels import (
    CURVATURE_TABLE,
    GUARD_AY,
    NO_LANE_CHANGE,
    LOG_INDEX,
    LOG_TRUE_E1,
    LOG_TRUE_E2_DOT,
    N_LOG,
    STOP_BLOWUP,
    STOP_DONE,
    STOP_HANDOVER,
    advance_ticks,
    guard_steering,
    lane_change_driver_inputs,
    record_tick,
    road_lookup,
)
from .driver import LaneKeepingDriver
from .dynamics import BicyclePlant, PlantEffects, StateIndex
from .params import CameraParams, DriverParams, ParameterError, RoadParams, TireParams, VehicleParams
from .roads import Road, make_road
from .sensors import Camera
from .tires import TireModel, axle_tires

__all__ = [
    "Plant",
    "RoadTable",
    "Simulator",
    "SimulationLog",
    "simulate",
    "advance_ticks_python",
    "log_from_rows",
    "SENSOR_KEYS",
    "TRUTH_KEYS",
]

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
                true_e1=x[:, StateIndex.E1],
                true_e1_dot=x[:, StateIndex.E1_DOT],
                true_e2=x[:, StateIndex.E2],
                true_e2_dot=x[:, StateIndex.E2_DOT],
                true_alpha_f=self.truth["true_slip"][:, 0],
                true_alpha_r=self.truth["true_slip"][:, 1],
                true_Fyf=self.truth["true_force"][:, 0],
                true_Fyr=self.truth["true_force"][:, 1],
                true_vy=x[:, StateIndex.E1_DOT] - s["vx"] * x[:, StateIndex.E2],
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
        self.camera = Camera(camera, self.dt, camera_x=plant.vehicle.camera_x)
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
        vx, ax = self._vx0
        offset = float(steering_offset)
        full = math.nan if steering is None else float(steering)
        if self.speed_profile is None and hasattr(self.plant, "kernel_params"):
            self.table.cover(self.s + (n_ticks + 2) * self.dt * vx + 1.0)
            # flat arguments, each group unpacked in place (advance_ticks, Notes: per-call cost)
            s, _, delta, done, status = advance_ticks(
                n_ticks, self.dt, self.tick_index, self.plant.state, self.s, vx, ax,
                *self.plant.kernel_params(),
                CURVATURE_TABLE, self.table.kappa, self.table.dkappa, self.table.ds, _NO_KNOTS,
                math.inf, 0.0,
                *self.camera.kernel_args(),
                *self.driver.kernel_args(),
                offset, full, self.last_delta,
                *NO_LANE_CHANGE,
                out,
            )  # fmt: skip
            compiled = True
        else:
            compiled = False
            profile = None if self.speed_profile is None else self._profile_speed
            s, _, delta, done, status = advance_ticks_python(
                n_ticks, self.dt, self.tick_index, self.plant, self.s, vx, ax, self.table.lookup, self.camera,
                self.driver, offset, full, self.last_delta, out, speed_profile=profile,
                midpoint_ax_factor=0.0 if profile is not None else 0.125,
            )  # fmt: skip
        if status == STOP_BLOWUP:
            t = (self.tick_index + done) * self.dt
            raise FloatingPointError(
                f"simulation blew up at t={t:.4f} s: state {np.asarray(self.plant.state).tolist()}, delta={delta}"
            )
        self.s, self.last_delta = s, delta
        if compiled:
            # the inputs held at the end of the chunk, as BicyclePlant.step records them (for output())
            k, dk = self.table.lookup(s)
            vx_end = vx + self.dt * ax
            self.plant.hold_inputs(delta, vx_end, ax, vx_end * k, vx_end * vx_end * dk + ax * k)
        self.tick_index += n_ticks
        self.t = self.tick_index * self.dt
        return SimulationLog(*log_from_rows(out, self.plant.vehicle), self.dt, self.plant.vehicle)


_NO_KNOTS = np.zeros(0)  # the running curvature integral a road table does not need
# log_from_rows' columns, looked up once (it runs at every env step): (key, column) of each sensor
# entry, the column ranges of the slip, force and true-state entries
_SENSOR_COLUMNS = tuple((key, LOG_INDEX[key]) for key in SENSOR_KEYS)
_SLIP_COLUMNS = slice(LOG_INDEX["alpha_f"], LOG_INDEX["alpha_r"] + 1)
_FORCE_COLUMNS = slice(LOG_INDEX["Fyf"], LOG_INDEX["Fyr"] + 1)
_TRUE_STATE_COLUMNS = slice(LOG_INDEX["true_e1"], LOG_INDEX["true_e2_dot"] + 1)


def log_from_rows(out: NDArray, vehicle: VehicleParams) -> tuple[dict[str, NDArray], dict[str, NDArray]]:
    """``(sensors, truth)`` of tick-log rows ``out`` (n, N_LOG) (:data:`~._kernels.LOG_COLUMNS`).

    ``true_force_nonlinear`` is ``F_y - 2 C alpha`` with the nominal ``vehicle``'s stiffness.
    """
    sensors = {key: out[:, j].copy() for key, j in _SENSOR_COLUMNS}
    slip = out[:, _SLIP_COLUMNS].copy()
    force = out[:, _FORCE_COLUMNS].copy()
    truth = {
        "true_state": out[:, _TRUE_STATE_COLUMNS].copy(),
        "true_slip": slip,
        "true_force": force,
        "true_force_nonlinear": force - slip * np.array([2.0 * vehicle.Cf, 2.0 * vehicle.Cr]),
        "s": out[:, LOG_INDEX["s"]].copy(),
    }
    return sensors, truth


def advance_ticks_python(
    n_ticks: int,
    dt: float,
    tick0: int,
    plant: Plant,
    s0: float,
    vx0: float,
    ax: float,
    curvature: Callable[[float], tuple[float, float]],
    camera: Camera,
    driver: LaneKeepingDriver,
    steering_offset: float,
    steering: float,
    last_delta: float,
    out: NDArray,
    *,
    s_stop: float = math.inf,
    feedforward_curvature: Callable[[float, float], float] | None = None,
    lane_change: tuple[float, float, float] = NO_LANE_CHANGE,
    speed_profile: Callable[[float], tuple[float, float]] | None = None,
    midpoint_ax_factor: float = 0.125,
) -> tuple[float, float, float, int, int]:
    """The tick sequence of :func:`~._kernels.advance_ticks` for any plant (the Python reference loop).

    Parameters
    ----------
    n_ticks, dt, tick0
        Ticks to run, tick [s], index of the first tick.
    plant : Plant
        Any truth vehicle of the :class:`Plant` protocol (``state[:4]`` = error state).
    s0, vx0, ax
        Path coordinate [m], speed [m/s] at the first tick, longitudinal acceleration [m/s^2]
        (``vx`` integrated tick by tick, unless ``speed_profile`` gives both per tick).
    curvature : callable
        ``s -> (kappa [1/m], dkappa/ds [1/m^2])`` of the reference path.
    camera, driver
        :class:`~.sensors.Camera` and :class:`~.driver.LaneKeepingDriver` (their ``tick``,
        ``latest``, ``steer`` and ``guard``).
    steering_offset, steering, last_delta
        As :func:`~._kernels.advance_ticks` (``steering`` NaN: the driver steers).
    out : ndarray (n_ticks, N_LOG)
        Tick log rows, written through :func:`~._kernels.record_tick`.
    s_stop : float
        Stop before a tick that starts at ``s >= s_stop`` [m].
    feedforward_curvature : callable, optional
        ``(s, vx) -> kappa`` the driver feeds forward (default: the curvature at ``s``).
    lane_change : tuple
        ``(offset [m], s_start [m], length [m])`` of a lane-change path (offset 0: none).
    speed_profile : callable, optional
        ``t -> (vx, ax)`` evaluated every tick (the base simulator's speed profiles).
    midpoint_ax_factor : float
        The RK4 midpoint curvature is looked up at ``s + vx dt/2 + factor ax dt^2``: 1/8 is the
        exact midpoint under constant ``ax`` (the compiled loop, the highway ego); the base
        simulator's speed-profile runs use 0 (their logs predate the term; it moves the lookup
        by ``ax dt^2 / 8``, 1.9e-7 m at 1.5 m/s^2 and 1 kHz). With ``ax = 0`` both agree to the bit.

    Returns
    -------
    s, vx, delta, done, status
        As :func:`~._kernels.advance_ticks`; a ``FloatingPointError`` of ``plant.step`` or a
        non-finite state stops the loop with ``STOP_BLOWUP``.
    """
    s, vx, delta = s0, vx0, last_delta
    lc_offset, lc_s0, lc_len = lane_change
    max_steer = driver.params.max_steering
    for j in range(n_ticks):
        if s >= s_stop:
            return s, vx, delta, j, STOP_HANDOVER
        t = (tick0 + j) * dt
        if speed_profile is not None:
            vx, ax = speed_profile(t)
        vx_mid, vx_end = vx + 0.5 * dt * ax, vx + dt * ax
        k0, dk0 = curvature(s)
        k1, dk1 = curvature(s + 0.5 * dt * vx + midpoint_ax_factor * dt * dt * ax)
        s_end = s + 0.5 * dt * (vx + vx_end)
        k2, dk2 = curvature(s_end)
        state = plant.state
        frame = camera.tick(t, state[StateIndex.E1], state[StateIndex.E2], k0)
        delta_prev = delta
        if steering != steering:
            e1m, e2m = camera.latest
            kp = k0 if feedforward_curvature is None else feedforward_curvature(s, vx)
            if lc_offset != 0.0:
                e1m, e2m, kp = lane_change_driver_inputs(s, e1m, e2m, kp, lc_offset, lc_s0, lc_len)
            delta = driver.steer(e1m, e2m, kp, vx, dt) + steering_offset
        else:
            delta = steering
        delta = guard_steering(min(max(delta, -max_steer), max_steer), delta_prev, driver.guard)
        delta = min(max(delta, -max_steer), max_steer)
        p0, q0 = vx * k0, vx * vx * dk0 + ax * k0
        out[j, LOG_TRUE_E1 : LOG_TRUE_E2_DOT + 1] = state[:4]
        try:
            af, ar, Fyf, Fyr, r, ay = plant.step(
                delta,
                dt,
                (p0, vx_mid * k1, vx_end * k2),
                (q0, vx_mid * vx_mid * dk1 + ax * k1, vx_end * vx_end * dk2 + ax * k2),
                vx,
                ax,
            )
        except FloatingPointError:
            return s, vx, delta, j, STOP_BLOWUP
        if not np.all(np.isfinite(np.asarray(plant.state[:4], dtype=float))):
            return s, vx, delta, j, STOP_BLOWUP
        driver.guard[GUARD_AY] = ay
        delivered = frame is not None
        e1f, e2f = frame if delivered else (math.nan, math.nan)
        record_tick(out, j, t, delta, vx, ax, k0, p0, q0, delivered, e1f, e2f, r, ay, af, ar, Fyf, Fyr, s)
        s, vx = s_end, vx_end
    return s, vx, delta, n_ticks, STOP_DONE


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
