r"""The neuro-adaptive observer: states and neural tire-force weights estimated together.

One estimator for every sensor set: the measurement model (:mod:`.model`: lane camera
``[e1, e2]``, IMU ``[a_y, r]``, or both) only decides which channels are read and which
certified gains correct the state (:mod:`.gains`). Model, adaptation law, latency handling,
health flag and uncertainty are the same (:mod:`._kernel`, which documents the equations).

Adaptation (the repaired eq. 15): with ``Upsilon = d x_hat / d w`` the sensitivity of the
state estimate to the weights (Q. Zhang, IEEE TAC 47(3), 2002) and ``Psi = H Upsilon + D_w``
the regressor of a measurement,

    w+ = Proj( w + K nu ),   K = P_w Psi^T (Psi P_w Psi^T + H Sigma H^T + R)^-1     (RLS)
    x+ = x + Upsilon (w+ - w) + L nu,    Upsilon+ = Upsilon - L Psi

so ``K`` is the paper's weight gain made time-varying (a constant ``K`` cannot be certified,
SPEC §3), and ``P_w`` is the weights' covariance: the curve's uncertainty band.

The vocabulary follows filterpy and is the same for every estimator of the package
(this observer, :class:`~tire_learning_env.baselines.JointUKF`,
:class:`~tire_learning_env.baselines.LinearKalmanFilter`): :meth:`reset`,
:meth:`predict` (the car moves), :meth:`update` (a sensor speaks), :meth:`run` (whole
arrays of rows in compiled code).
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..params import ParameterError, VehicleParams
from . import _kernel as K
from .basis import SoftClipBasis
from .block_law import BlockLaw
from .gains import ObserverGains
from .model import MeasurementModel, StateIndex
from .rows import CHANNELS, _KernelRows, sensor_rows
from .settings import AdaptationParams, HealthParams
from .trace import HEALTH_NAMES, EstimateTrace

# names this module imported before its split (still importable from here)
from ..params import _Params  # noqa: F401
from .model import check_sensor_columns  # noqa: F401

__all__ = ["NeuroAdaptiveObserver", "AdaptationParams", "HealthParams", "sensor_rows", "CHANNELS", "N_BIAS_PARAMS"]

#: sensor offsets appended to the weights when the IMU is read: a_y [m/s^2], yaw rate [rad/s]
N_BIAS_PARAMS = 2


class NeuroAdaptiveObserver(BlockLaw):
    """Neuro-adaptive estimator of the states and the tire-force weights, for any sensor set.

    Parameters
    ----------
    vehicle : VehicleParams
        Nominal vehicle (its ``Cf``, ``Cr`` give the linear part ``2 C alpha`` of the curves).
    basis : SoftClipBasis
        Activations, scales ``gamma`` and the weight box.
    gains : ObserverGains
        Certified gains (:func:`.gains.synthesize_gains`); its ``model`` is the sensor set.
    noise_std : array (4,)
        Measurement noise std of ``e1`` [m], ``e2`` [rad], ``a_y`` [m/s^2], ``r`` [rad/s]
        (e.g. estimated from the log, :mod:`.calibration`).
    latency : float
        Camera latency [s]: a frame shows the state that long before it is delivered.
    force_error : float
        Std of the force error the model makes [N] (basis residual, unmodelled dynamics),
        white over ``force_error_period``: the process noise of ``Sigma``.
    force_error_period : float
        [s].
    adaptation : AdaptationParams, optional
    health : HealthParams, optional
    initial_weights : array, optional
        ``w(0)`` (tire weights, then the sensor offsets if any).
    physics_dt : float
        Prediction step after the last row of a :meth:`run` and the default of :meth:`predict` [s].
    h_max : float
        Largest integration sub-step [s].
    sample_period : float, optional
        Nominal period of the measurements [s] (health window and gap limit); default the
        gains' frame period.
    pinned_slip : float
        The nominal stiffness is trusted up to this slip [rad]: the prior of the segments
        inside it is 1000 times tighter (the curve is pinned there). 0: learned everywhere.
    """

    def __init__(
        self,
        vehicle: VehicleParams,
        basis: SoftClipBasis,
        gains: ObserverGains,
        noise_std: ArrayLike,
        latency: float = 0.0,
        force_error: float = 100.0,
        force_error_period: float = 0.05,
        adaptation: AdaptationParams | None = None,
        health: HealthParams | None = None,
        initial_weights: ArrayLike | None = None,
        physics_dt: float = 1e-3,
        h_max: float = 0.01,
        sample_period: float | None = None,
        pinned_slip: float = 0.0,
    ) -> None:
        if not physics_dt > 0:
            raise ParameterError(f"physics_dt must be > 0, got {physics_dt!r}")
        if not latency >= 0:
            raise ParameterError(f"latency must be >= 0 s, got {latency!r}")
        noise = np.asarray(noise_std, dtype=float).reshape(4)
        if not np.all(noise > 0):
            raise ParameterError(f"noise_std must be 4 positive values (e1, e2, a_y, r), got {noise_std!r}")
        self.vehicle = vehicle
        self.basis = basis
        self.gains = gains
        self.model: MeasurementModel = gains.model
        self.noise_std = noise
        self.latency = float(latency)
        self.force_error = float(force_error)
        self._configured_force_error = self.force_error  # what reset() returns to (the block law adapts it)
        self.force_error_period = float(force_error_period)
        self.adaptation = adaptation or AdaptationParams()
        self.health_params = health or HealthParams()
        self.dt = float(physics_dt)
        self.h_max = float(h_max)
        self.sample_period = float(sample_period or gains.frame_period)
        self.pinned_slip = float(pinned_slip)
        #: how the steering behaves between rows: ``"hold"`` (zero-order hold: a simulator's
        #: steering, constant over its step) or ``"ramp"`` (first-order hold: a sampled continuous
        #: steering wheel); :func:`~.estimator.estimate` chooses from the log
        self.steering_hold = "hold"
        #: a step between rows longer than this [s] is a pause of the log (a segment boundary): nothing is
        #: predicted across it; the state restarts after it as at the start of a log (zero, its prior
        #: covariance, health settling for ``settle_s``), the weights and their covariance carry over.
        #: :func:`~.estimator.estimate` sets it from :func:`tire_learning_env.io.row_gaps` when the log has a
        #: pause; ``inf``: no boundary (on-line use)
        self.segment_gap_s = math.inf
        self.n_bias = N_BIAS_PARAMS if (self.model.uses_imu and self.adaptation.sensor_offsets) else 0
        nw = basis.n_weights + self.n_bias
        w0 = np.zeros(nw) if initial_weights is None else np.asarray(initial_weights, dtype=float).reshape(-1)
        if w0.shape != (nw,):
            raise ParameterError(f"initial_weights must have shape ({nw},) (tire weights, then {self.n_bias} sensor offsets)")
        self.initial_weights = w0.copy()
        self._bounds = K.bound_table(basis.lower, basis.upper)
        self._model_tuple = self._make_model()
        self._gain_tuple = K.Gains(np.ascontiguousarray(gains.edges), np.ascontiguousarray(gains.L_cam),
                                   np.ascontiguousarray(gains.L_imu))  # fmt: skip
        self.reset()

    # -- construction helpers ---------------------------------------------------------------------
    def set_force_error(self, force_error: float) -> None:
        """Change the process-noise force error std [N] (keeps the state)."""
        if not force_error > 0:
            raise ParameterError(f"force_error must be > 0 N, got {force_error!r}")
        self.force_error = float(force_error)
        self._configured_force_error = self.force_error
        self._model_tuple = self._make_model()

    def set_vehicle(self, vehicle: VehicleParams) -> None:
        """Predict with another vehicle (the same gains: for a refit, not a new design; keeps the state)."""
        if not isinstance(vehicle, VehicleParams):
            raise ParameterError(f"vehicle must be a VehicleParams, got {type(vehicle).__name__}")
        self.vehicle = vehicle
        self._model_tuple = self._make_model()

    def _adapt_force_error(self, force_error: float) -> None:
        """The block law's own process-noise level (until the next :meth:`reset`)."""
        self.force_error = float(force_error)
        self._model_tuple = self._make_model()

    @property
    def n_weights(self) -> int:
        return self.basis.n_weights + self.n_bias

    def _weight_box(self) -> tuple[NDArray, NDArray]:
        """Lower and upper bounds of the weights (fresh copies: callers may keep or change them).

        Built once per basis and bias count (the causal pass' block law asks at every 2 s block:
        900 times on a 30 min log, 0.16 s of rebuilding)."""
        b = self.basis
        key = (id(b), self.n_bias)
        box = self.__dict__.get("_weight_box_cache")
        if box is None or box[0] != key or box[1] is not b:
            lo = np.r_[b.weight_lower.ravel(), np.full(self.n_bias, -np.inf)]
            hi = np.r_[b.weight_upper.ravel(), np.full(self.n_bias, np.inf)]
            box = self._weight_box_cache = (key, b, lo, hi)
        return box[2].copy(), box[3].copy()

    def _make_model(self) -> K.Model:
        v, b = self.vehicle, self.basis
        wlo, whi = self._weight_box()
        q = self.force_error**2 * self.force_error_period
        return K.Model(
            np.array([v.m, v.Iz, v.lf, v.lr, 2.0 * v.Cf, 2.0 * v.Cr, v.camera_x]), np.ascontiguousarray(b.lower),
            np.ascontiguousarray(b.upper), np.ascontiguousarray(b.offset), float(b.sharpness), np.ascontiguousarray(b.scale),
            int(self.n_bias), np.ascontiguousarray(wlo), np.ascontiguousarray(whi), int(self.model.nx), np.array([q, q]),
            float(self.h_max), *self._bounds,
        )  # fmt: skip

    def prior_covariance(self, offline: bool = False) -> NDArray:
        """``P_w(0)``: smooth-curve prior of the tire weights, independent sensor offsets
        (``offline``: the offline fit's prior, else the causal pass'; :class:`AdaptationParams`)."""
        a, b = self.adaptation, self.basis
        length = a.prior_length if (offline or a.online_prior_length is None) else a.online_prior_length
        tire = b.slope_prior(math.radians(length), a.prior_symmetry) * (a.initial_std * b.weight_range) ** 2
        if self.pinned_slip > 0:
            inner = ((np.maximum(np.abs(b.lower), np.abs(b.upper)) <= self.pinned_slip + 1e-12) & (b.lower != b.upper)).ravel()
            scale = np.where(inner, 1e-3, 1.0)
            tire = tire * np.outer(scale, scale)
        if not self.n_bias:
            return tire
        return sla_block_diag(tire, np.diag([a.ay_offset_std**2, a.yaw_rate_offset_std**2]))

    def initial_state_covariance(self) -> NDArray:
        """Prior covariance of the state (the zero initial state of the paper)."""
        std = np.array([0.5, 0.05, 0.5, 0.02])[: self.model.nx]
        return np.diag(std**2)

    @property
    def settle_s(self) -> float:
        return self.adaptation.settle_time_constants / max(self.gains.decay_rate, 0.05)

    def _settings(self, mode: int, t0: float, adapt: bool = True, store_scores: bool = False,
                  accumulate_from: float = -np.inf, gate: float = np.inf, compute_std: bool = True,
                  store_weights: bool = True, kalman: bool = False, record: bool = True,
                  shift_frames: bool = False) -> K.Settings:  # fmt: skip
        hp, a = self.health_params, self.adaptation
        wr = self.basis.weight_range
        return K.Settings(
            np.ascontiguousarray(self.noise_std**2), bool(self.model.uses_camera), bool(self.model.uses_imu),
            float(self.latency), int(mode), bool(adapt), float((a.random_walk * wr) ** 2),
            float((a.max_std * wr) ** 2), float(t0 + self.settle_s),
            float(max(hp.gap_frames * self.sample_period, hp.min_gap_s)), float(hp.nis_factor), float(hp.rollback_s),
            float(gate), float(accumulate_from), np.zeros(self.model.nx), self.initial_state_covariance(), float(self.dt),
            bool(store_weights), bool(store_scores), bool(compute_std), bool(kalman), bool(record), bool(shift_frames),
            bool(self.steering_hold == "ramp"),
        )  # fmt: skip

    # -- state ------------------------------------------------------------------------------------
    def reset(self, state: ArrayLike | None = None, weights: ArrayLike | None = None) -> "NeuroAdaptiveObserver":
        """Start again from ``state`` (default zero, as in the paper) and ``weights`` (default
        the initial ones), with the prior weight covariance."""
        nx, nw = self.model.nx, self.n_weights
        if self.force_error != self._configured_force_error:
            self._adapt_force_error(self._configured_force_error)
        x = np.zeros(nx) if state is None else np.asarray(state, dtype=float).reshape(nx).copy()
        w = self.initial_weights if weights is None else np.asarray(weights, dtype=float).reshape(nw)
        lo, hi = self._weight_box()
        W = max(int(round(self.health_params.window_s / self.sample_period)), int(self.health_params.min_updates))
        hlen = int(math.ceil(self.latency / max(self.dt, 1e-4))) + 3 if self.latency > 0 else 1
        hs = np.zeros(K.N_HS)
        hs[K.HS_CODE] = K.HEALTH_SETTLING
        hs[K.HS_PREV_T] = np.nan  # no previous row: the first interval holds its curvature
        self._state = K.State(
            x, np.clip(w, lo, hi).astype(float), np.zeros((nx, nw)), self.initial_state_covariance(),
            np.ascontiguousarray(self.prior_covariance()), hs, np.zeros((min(W, 4000), 2)), np.zeros(8), np.zeros((8, nw)),
            np.zeros((8, nw, nw)), np.zeros(hlen), np.zeros((hlen, nx)), np.zeros((hlen, nx, nw)), np.zeros((hlen, nx, nx)),
            np.zeros((hlen, 8)), np.zeros(2, dtype=np.int64),
        )  # fmt: skip
        self._t0: float | None = None
        self._block: dict | None = None  # the "block" law's running fit (see _run_blocks)
        self.t = 0.0
        return self

    @property
    def state(self) -> NDArray:
        """Current state estimate ``[vy, r(, e1, e2)]``."""
        return self._state.x.copy()

    @property
    def weights(self) -> NDArray:
        return self._state.w.copy()

    @property
    def pw(self) -> NDArray:
        """Current weight covariance ``P_w``."""
        return self._state.pw

    @property
    def health(self) -> str:
        """Current health flag (:data:`~.trace.HEALTH_NAMES`)."""
        return HEALTH_NAMES[int(self._state.hs[K.HS_CODE])]

    @property
    def trips(self) -> int:
        """How often the health flag tripped since the last reset."""
        return int(self._state.hs[K.HS_TRIPS])

    # -- verbs ------------------------------------------------------------------------------------
    def run(self, sensors: Mapping[str, ArrayLike], predict_last: bool = True, *, mode: str = "causal",
            adapt: bool = True, accumulator: K.Accumulator | None = None, accumulate_from: float = -np.inf,
            gate: float = np.inf, store_scores: bool = False, compute_std: bool = True,
            store_weights: bool = True, kalman: bool = False, record: bool = True,
            shift_frames: bool = False) -> EstimateTrace | None:  # fmt: skip
        """Process rows of sensor data, continuing from the current state.

        Parameters
        ----------
        sensors : mapping of str -> array
            Equal-length columns ``t, delta, vx`` (``ax`` optional), ``kappa`` (or
            ``psi_dot_des``), ``e1, e2`` for the camera and ``ay, yaw_rate`` for the IMU (NaN
            where no sample arrived): an env's ``info["sensor_log"]``, a
            :class:`~tire_learning_env.simulation.SimulationLog`'s ``sensors`` or a log's.
            Ground truth is refused.
        predict_last : bool
            Predict one ``physics_dt`` past the last row (so that the next call continues
            exactly).
        mode : {"causal", "fixed"}
            ``fixed`` holds the weights and accumulates the prediction-error fit into
            ``accumulator`` (:mod:`.offline`).
        record : bool
            Store the per-row outputs; ``False`` only updates the state and the accumulator
            (and returns ``None``): the passes of the offline fit.
        shift_frames : bool
            Fixed mode without ``record``, camera only: apply delayed frames at their instant
            in one forward sweep (the same fit as rewinding and replaying, faster).

        Returns
        -------
        EstimateTrace or None
        """
        if mode != "fixed" and adapt and record and accumulator is None and self.adaptation.causal_update == "block":
            return self._run_blocks(sensors, predict_last, compute_std=compute_std, store_weights=store_weights)
        rows = sensors if isinstance(sensors, _KernelRows) else sensor_rows(sensors, self.model)
        n = len(rows["t"])
        nx, nw = self.model.nx, self.n_weights
        if n and self._t0 is None:
            self._t0 = float(rows["t"][0])
        m = K.MODE_FIXED if mode == "fixed" else K.MODE_CAUSAL
        if not record:
            store_scores = compute_std = store_weights = False
        kw = dict(adapt=adapt, store_scores=store_scores, gate=gate, compute_std=compute_std,
                  store_weights=store_weights, kalman=kalman, record=record, shift_frames=shift_frames)  # fmt: skip
        S = self._settings(m, self._t0 or 0.0, accumulate_from=accumulate_from, **kw)
        nr = n if record else 0
        acc = accumulator if accumulator is not None else K.Accumulator(np.zeros((nw, nw)), np.zeros(nw), np.zeros(4), np.empty((0, 2)))
        out = K.Outputs(
            np.empty((nr, nx)), np.empty((nr, 2)), np.empty((nr, 2)), np.empty((nr, 2)),
            np.empty((nr if store_weights else 0, nw)), np.empty((nr if compute_std else 0, nx)), np.empty((nr, 4)),
            # the scores in single precision: they only feed the sandwich variance (55 MB in double on 180k rows)
            np.empty(nr), np.empty(nr, dtype=np.int8), np.zeros((nr if store_scores else 0, nw), dtype=np.float32),
        )  # fmt: skip
        if n:
            wk = K.make_work(nx, nw, self._bounds[0].shape[1])
            t = rows["t"]
            for a, b, restart in self._segments(t):
                S_ab = S
                if restart:  # after a pause: the state as at a log's start, settling again (segment_gap_s)
                    self._restart_segment()
                    t_seg = float(t[a])
                    S_ab = self._settings(m, t_seg, accumulate_from=max(accumulate_from, t_seg + self.settle_s), **kw)
                if a == 0 and b == n:
                    out_ab, acc_ab = out, acc
                else:  # the rows' slices: the kernel indexes its outputs, scores and innovations by row
                    out_ab = K.Outputs(*(v[a:b] for v in out))
                    acc_ab = acc._replace(innov=acc.innov[a:b]) if acc.innov.shape[0] else acc
                K.run_rows(t[a:b], rows["delta"][a:b], rows["vx"][a:b], rows["ax"][a:b], rows["kappa"][a:b],
                           rows["z"][a:b], rows["e1_release"][a:b], self._model_tuple, self._gain_tuple, S_ab, self._state, acc_ab, out_ab, wk,
                           bool(predict_last) if b == n else False)  # nothing predicted across a pause
            self.t = float(rows["t"][-1]) + (self.dt if predict_last else 0.0)
        if not record:
            return None
        lin = out.slip * np.array([2.0 * self.vehicle.Cf, 2.0 * self.vehicle.Cr])
        trace = EstimateTrace(
            rows["t"], out.x, out.slip, out.force, out.force - lin, out.w, out.std, out.health, out.nu, out.nis,
            rows["vx"], rows["kappa"], self.model.state_names, {"sensors": self.model.name},
        )  # fmt: skip
        if store_scores:
            trace.meta["scores"] = out.score
        return trace

    # -- pauses in a log (segment_gap_s) --------------------------------------------------------
    def _segments(self, t: NDArray) -> list[tuple[int, int, bool]]:
        """``(first, end, restart)`` row ranges of ``t`` between pauses longer than ``segment_gap_s``;
        ``restart``: the state restarts before the range (also the first one, when the previous call's
        last row lies a pause before it)."""
        n = len(t)
        if not math.isfinite(self.segment_gap_s):
            return [(0, n, False)]
        cuts = (np.flatnonzero(np.diff(t) > self.segment_gap_s) + 1).tolist()
        prev = float(self._state.hs[K.HS_PREV_T])
        first = bool(prev == prev and float(t[0]) - prev > self.segment_gap_s)
        return [(a, b, first or a > 0) for a, b in zip([0] + cuts, cuts + [n])]

    def _restart_segment(self) -> None:
        """The state after a pause of the log: as :meth:`reset` leaves it (zero state, its prior
        covariance, no sensitivity to the weights, health settling, no previous row, no delayed
        frames), with the weights, their covariance, the checkpoints and the trip count kept."""
        st = self._state
        st.x[:] = 0.0
        st.ups[:] = 0.0
        st.sig[:] = self.initial_state_covariance()
        trips = st.hs[K.HS_TRIPS]
        ck = st.hs[[K.HS_N_CKPT, K.HS_CKPT_HEAD]].copy()
        st.hs[:] = 0.0
        st.hs[K.HS_CODE] = K.HEALTH_SETTLING
        st.hs[K.HS_PREV_T] = np.nan
        st.hs[K.HS_TRIPS] = trips
        st.hs[[K.HS_N_CKPT, K.HS_CKPT_HEAD]] = ck
        st.hist_meta[:] = 0

    def predict(self, dt: float | None = None, delta: float = 0.0, vx: float | None = None, kappa: float = 0.0,
                ax: float = 0.0, kappa_rate: float = 0.0, steering_rate: float = 0.0) -> "NeuroAdaptiveObserver":  # fmt: skip
        """Advance ``dt`` [s] (default ``physics_dt``): the steering [rad] ramping with
        ``steering_rate`` [rad/s] (0: held), the speed [m/s] with the longitudinal acceleration
        ``ax`` [m/s^2], the path curvature [1/m] with ``kappa_rate`` [1/(m s)] (:meth:`run` uses
        the backward difference of its rows for the curvature, and the ramp to the next row for
        the steering when :attr:`steering_hold` is ``"ramp"``)."""
        dt = self.dt if dt is None else float(dt)
        vx = self.vehicle.vx if vx is None else float(vx)
        S = self._settings(K.MODE_CAUSAL, self._t0 or self.t)
        wk = K.make_work(self.model.nx, self.n_weights, self._bounds[0].shape[1])
        K.predict(self._state, dt, float(delta), float(steering_rate), vx, float(ax), float(kappa), float(kappa_rate),
                  self._model_tuple, S, wk)  # fmt: skip
        self.t += dt
        return self

    def update(self, z: ArrayLike | Mapping[str, float], delta: float = 0.0, vx: float | None = None) -> "NeuroAdaptiveObserver":
        """Correct with a measurement now: ``z`` = ``[e1, e2, a_y, r]`` (NaN: not measured) or a
        mapping of those channel names (``yaw_rate`` for ``r``); ``delta`` [rad], ``vx`` [m/s]
        are the current inputs. The weights adapt as in :meth:`run`."""
        vx = self.vehicle.vx if vx is None else float(vx)
        if isinstance(z, Mapping):
            zz = np.array([float(z.get(c, np.nan)) for c in CHANNELS])
        else:
            zz = np.asarray(z, dtype=float).reshape(-1)
            if zz.size == 2 and self.model.uses_camera and not self.model.uses_imu:
                zz = np.r_[zz, np.nan, np.nan]
            if zz.size != 4:
                raise ParameterError(f"z must hold 4 channels (e1, e2, a_y, r) or be a mapping, got {zz.size} values")
        cols = {"t": np.array([self.t]), "delta": np.array([float(delta)]), "vx": np.array([vx]), "kappa": np.zeros(1),
                "e1": zz[:1], "e2": zz[1:2], "ay": zz[2:3], "yaw_rate": zz[3:4]}  # fmt: skip
        self.run(cols, predict_last=False)
        return self

    def estimate_now(self, delta: float, psi_dot_des: float, vx: float | None = None) -> dict[str, NDArray]:
        """The current (predicted) estimate with the inputs held: state, slip, forces, std, health."""
        vx = self.vehicle.vx if vx is None else float(vx)
        x = self._state.x
        v = self.vehicle
        slip = np.array(K.slip_angles(float(x[StateIndex.VY]), float(x[StateIndex.R]), float(delta), vx, v.lf, v.lr))  # eq. (13)
        w = self._state.w
        fnl = np.array([float(self.basis.nonlinear_force(slip[i], w[: self.basis.n_weights], i)) for i in (0, 1)])
        if self.model.uses_camera:
            kappa = psi_dot_des / max(vx, 1e-3)
            from .model import to_error_state

            state = to_error_state(x, vx, kappa)
        else:
            state = x.copy()
        pw = self._state.pw
        ups = self._state.ups
        std = np.sqrt(np.maximum(np.diag(self._state.sig + ups @ pw @ ups.T), 0.0))
        return {
            "state": state,
            "slip": slip,
            "force_nonlinear": fnl,
            "force": fnl + slip * np.array([2 * v.Cf, 2 * v.Cr]),
            "weights": w.copy(),
            "std": std,
            "health": self.health,
        }

    # -- learned tire curve (eq. 29) --------------------------------------------------------------
    def axle_force(self, alpha: ArrayLike, axle: str | int, weights: ArrayLike | None = None) -> NDArray:
        """Learned total axle force ``2 C alpha + gamma sum W sigma(alpha)`` [N] (eq. 29)."""
        i = axle_index(axle)
        w = self._state.w if weights is None else np.asarray(weights, dtype=float)
        c2 = 2.0 * (self.vehicle.Cf if i == 0 else self.vehicle.Cr)
        a = np.asarray(alpha, dtype=float)
        return c2 * a + self.basis.nonlinear_force(a, w[: self.basis.n_weights], i)

    def cornering_stiffness(self, weights: ArrayLike | None = None) -> tuple[float, float]:
        """Per-tire cornering stiffness: half the slope of the learned axle curve at zero slip [N/rad]."""
        w = self._state.w if weights is None else np.asarray(weights, dtype=float)
        out = []
        for i, c in enumerate((self.vehicle.Cf, self.vehicle.Cr)):
            out.append((2.0 * c + float(self.basis.nonlinear_slope(0.0, w[: self.basis.n_weights], i))) / 2.0)
        return out[0], out[1]


def axle_index(axle) -> int:
    """0 for ``"front"``/0, 1 for ``"rear"``/1."""
    if axle in ("front", 0):
        return 0
    if axle in ("rear", 1):
        return 1
    raise ParameterError(f"axle must be 'front' or 'rear', got {axle!r}")


def sla_block_diag(*blocks: NDArray) -> NDArray:
    import scipy.linalg as sla

    return sla.block_diag(*blocks)
