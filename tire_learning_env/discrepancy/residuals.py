"""The residual of a model on a log: :class:`ResidualModel`.

A thin shell around the compiled :func:`._model.window_residuals`: it holds the log's
arrays (:class:`.data.ModelData`), the nominal vehicle and tire, and evaluates the
weighted multiple-shooting residual for any effect-parameter vector ``theta``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .._kernels import TIRE_LINEAR
from ..dynamics import vehicle_vector
from ..params import VehicleParams
from ..tires import TireModel
from ._body_model import body_window_residuals, simulate_body_rows
from ._model import N_OUT, N_THETA, THETA_NOMINAL, TH_LATENCY, TH_STEER_DELAY, simulate_rows, window_residuals
from .config import DiscrepancyConfig
from .data import ModelData

__all__ = ["ResidualModel", "Evaluation"]

#: finite-difference steps of the initial state (e1 [m], e1_dot [m/s], e2 [rad], e2_dot [rad/s])
_FD = np.array([1e-3, 1e-3, 1e-4, 1e-4])
#: largest Gauss-Newton change of a window's initial state (same units)
_MAX_STEP = np.array([2.0, 2.0, 0.2, 0.5])
#: a window state is converged when no Gauss-Newton step component exceeds these
_TOL = np.array([1e-7, 1e-7, 1e-8, 1e-8])
#: the same for the body-frame state of IMU logs (vy [m/s], r [rad/s])
_FD_BODY = np.array([1e-3, 1e-4])
_MAX_STEP_BODY = np.array([2.0, 0.5])
_TOL_BODY = np.array([1e-7, 1e-8])


@dataclass
class Evaluation:
    """One evaluation of the residual.

    Attributes
    ----------
    theta : ndarray, shape (N_THETA,)
    resid : ndarray, shape (M,)
        Weighted residual ``(y - y_model) / sigma``.
    x0 : ndarray, shape (W, S)
        Fitted initial state of each window (S = 4 error states for a camera log, 2 body
        states ``[vy, r]`` for an IMU log).
    jac : ndarray, shape (M, S)
        Weighted sensitivity of the predictions to the initial state.
    """

    theta: NDArray
    resid: NDArray
    x0: NDArray
    jac: NDArray

    @property
    def chi2(self) -> float:
        return float(self.resid @ self.resid)


def _tire_arrays(tire: TireModel) -> tuple[NDArray, NDArray]:
    """Kernel vector and table of a tire; nonlinear curves are tabulated every 1e-4 rad.

    A table costs a few flops per call where the Magic Formula costs three transcendental
    functions; its interpolation error is below 0.01 N for the paper's tires.
    """
    vec, table = tire.kernel_vector()
    if vec[0] != TIRE_LINEAR:
        vec, table = TireModel.kernel_vector(tire)
    return np.ascontiguousarray(vec, dtype=float), np.ascontiguousarray(table, dtype=float)


class ResidualModel:
    """Residual of the augmented bicycle model on one log.

    A camera log is compared with the error-coordinate model (:mod:`._model`), an IMU-only
    log (``data.kind == "imu"``) with the body-frame model (:mod:`._body_model`); both take
    the same ``theta``.

    Parameters
    ----------
    data : ModelData
        Arrays from :func:`.data.prepare`.
    vehicle : VehicleParams
        Nominal vehicle.
    front_tire, rear_tire : TireModel
        Nominal axle tires (linear, Pacejka, or any model, tabulated).
    config : DiscrepancyConfig
    """

    def __init__(
        self,
        data: ModelData,
        vehicle: VehicleParams,
        front_tire: TireModel,
        rear_tire: TireModel,
        config: DiscrepancyConfig,
    ) -> None:
        self.data = data
        self.vehicle = vehicle
        self.front_tire = front_tire
        self.rear_tire = rear_tire
        self.config = config
        self.veh = vehicle_vector(vehicle)
        self.tf, self.tabf = _tire_arrays(front_tire)
        self.tr, self.tabr = _tire_arrays(rear_tire)
        self.n_evaluations = 0
        #: errors-in-variables model of the steering between rows (:mod:`.noise`); None = white noise only
        self.input_noise = None
        self.kind = data.kind
        self.n_state = 2 if data.kind == "imu" else 4
        if self.kind == "imu" and data.ay_guess is not None:
            # lateral velocity guess: steady-state rear slip of the nominal tire, alpha_r = m a_y lf / (L C_r,axle)
            js = data.win_sim
            v = np.maximum(data.vx[js], 1.0)
            r = data.x0_guess[:, 1]
            c_r = max(rear_tire.cornering_stiffness, 1.0)
            alpha_r = vehicle.m * data.ay_guess * vehicle.lf / (vehicle.wheelbase * c_r)
            guess = data.x0_guess.copy()
            guess[:, 0] = np.clip(vehicle.lr * r - v * alpha_r, -0.3 * v, 0.3 * v)
            data.x0_guess = guess
    def evaluate(
        self,
        theta: NDArray | None = None,
        jac: NDArray | None = None,
        x0_guess: NDArray | None = None,
        converge: bool = False,
    ) -> Evaluation:
        """Weighted residual, fitted window states and their sensitivities at ``theta``.

        Parameters
        ----------
        theta : ndarray, shape (N_THETA,), optional
            Effect parameters (default: the nominal model).
        jac : ndarray, shape (M, 4), optional
            Initial-state sensitivities to reuse (from a reference point of a fit): the
            window states are then fitted by ``config.gn_iterations`` fixed-Jacobian
            Gauss-Newton steps (two simulations per window for one step).
        x0_guess : ndarray, shape (W, 4), optional
            Starting guesses of the window states (default: the data's local fits).
        converge : bool
            Fit the window states to convergence (fresh Jacobian every step). Every
            comparison between models uses converged residuals, so that ``chi2`` is a
            function of ``theta`` alone.
        """
        d = self.data
        th = np.array(THETA_NOMINAL if theta is None else theta, dtype=float)
        if th.shape != (N_THETA,):
            raise ValueError(f"theta must have shape ({N_THETA},), got {th.shape}")
        if th[TH_LATENCY] > self.config.preroll + 1e-12:
            raise ValueError(f"latency {th[TH_LATENCY]} s exceeds the pre-roll {self.config.preroll} s")
        if abs(th[TH_STEER_DELAY]) > 1.0:
            raise ValueError(f"steering delay {th[TH_STEER_DELAY]} s: at most 1 s either way")
        m = d.n_measurements
        ns = self.n_state
        resid = np.empty(m)
        x0 = np.empty((d.n_windows, ns))
        whiten = self.input_noise is not None and self.input_noise.active
        if converge or (whiten and jac is not None):
            # a whitened sensitivity cannot drive the unwhitened fixed-Jacobian iteration: converge instead
            mode, n_iter, jac = 2, (12 if self.kind == "imu" else 8), np.empty((m, ns))
        elif jac is not None:
            mode, n_iter, jac = 1, int(self.config.gn_iterations), np.array(jac, dtype=float)
        else:
            mode, n_iter, jac = 0, int(self.config.gn_iterations), np.empty((m, ns))
        guess = d.x0_guess if x0_guess is None else np.ascontiguousarray(x0_guess, dtype=float)
        if self.kind == "imu":
            body_window_residuals(
                th, guess, d.win_sim, d.win_end, d.meas_ptr, d.meas_row, d.meas_chan, d.meas_val, d.meas_w,
                d.t, d.delta, d.dslope, d.vx, d.ax, self.veh, self.tf, self.tr, self.tabf, self.tabr,
                float(self.config.step), _FD_BODY, _MAX_STEP_BODY, _TOL_BODY, n_iter, resid, x0, jac, mode,
            )  # fmt: skip
        else:
            window_residuals(
                th, guess, d.win_sim, d.win_end, d.meas_ptr, d.meas_row, d.meas_chan, d.meas_val, d.meas_w,
                d.t, d.delta, d.dslope, d.vx, d.pdd, self.veh, self.tf, self.tr, self.tabf, self.tabr,
                float(self.config.step), _FD, _MAX_STEP, _TOL, n_iter, resid, x0, jac, mode,
            )  # fmt: skip
        self.n_evaluations += 1
        if whiten:
            resid, jac, x0 = self.input_noise.whiten(d, resid, jac, x0)
        return Evaluation(th, resid, x0, jac)

    def converged(self, theta: NDArray | None = None, x0_guess: NDArray | None = None) -> Evaluation:
        """:meth:`evaluate` with converged window states, from ``x0_guess`` (or the data's guesses)."""
        return self.evaluate(theta, x0_guess=x0_guess, converge=True)

    def best_of(self, theta: NDArray | None, guesses: list[NDArray | None]) -> Evaluation:
        """Converged evaluation from several starting states, the best one *per window*.

        A nonlinear tire (saturating, or a learned curve) can give a window's initial-state fit
        more than one local minimum; taking the best of several starts per window keeps
        ``chi2`` a function of ``theta`` rather than of where the iteration started.
        ``None`` in ``guesses`` means the data's own guesses.
        """
        evs = [self.converged(theta, g) for g in guesses]
        if len(evs) == 1:
            return evs[0]
        d = self.data
        wid = d.window_of_measurement()
        per = np.array([np.bincount(wid, e.resid**2, minlength=d.n_windows) for e in evs])
        pick = np.argmin(per, axis=0)
        resid = np.empty_like(evs[0].resid)
        jac = np.empty_like(evs[0].jac)
        x0 = np.empty_like(evs[0].x0)
        for w in range(d.n_windows):
            a, b = d.meas_ptr[w], d.meas_ptr[w + 1]
            e = evs[pick[w]]
            resid[a:b] = e.resid[a:b]
            jac[a:b] = e.jac[a:b]
            x0[w] = e.x0[w]
        return Evaluation(evs[0].theta, resid, x0, jac)

    def nominal_start(self) -> Evaluation:
        """Converged nominal evaluation from the data's guesses and, for an IMU log, two more
        lateral-velocity starts (+/- 0.5 m/s), best per window (:meth:`best_of`)."""
        if self.kind != "imu":
            return self.converged()
        g = self.data.x0_guess
        shift = np.zeros_like(g)
        shift[:, 0] = 0.5
        best = self.best_of(None, [g, g + shift, g - shift])
        return self.best_of(None, [best.x0])
    def residuals(self, theta: NDArray) -> NDArray:
        """Weighted residual vector only (the function scipy fits)."""
        return self.evaluate(theta).resid

    def trajectories(self, evaluation: Evaluation) -> NDArray:
        """Per-row model outputs (``_model.OUT_*`` columns; for an IMU log ``_body_model.OUT_*``)
        over every window's measured rows. Rows outside the windows are NaN. Shape (N, N_OUT).
        """
        d = self.data
        out = np.full((len(d.t), N_OUT), np.nan)
        for w in range(d.n_windows):
            j0, j1 = int(d.win_sim[w]), int(d.win_end[w])
            traj = np.empty((j1 - j0 + 1, N_OUT))
            if self.kind == "imu":
                simulate_body_rows(
                    evaluation.x0[w], j0, j1, d.t, d.delta, d.dslope, d.vx, d.ax, self.veh, self.tf, self.tr,
                    self.tabf, self.tabr, evaluation.theta, float(self.config.step), traj,
                )  # fmt: skip
            else:
                simulate_rows(
                    evaluation.x0[w], j0, j1, d.t, d.delta, d.dslope, d.vx, d.pdd, self.veh, self.tf, self.tr,
                    self.tabf, self.tabr, evaluation.theta, float(self.config.step), traj,
                )  # fmt: skip
            k = int(d.win_meas[w]) - j0
            out[d.win_meas[w] : j1 + 1] = traj[k:]
        return out
