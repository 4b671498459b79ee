r"""The neuro-adaptive observer: states and neural tire-force weights estimated together.

Model (SPEC §1-2): ``xi_dot = A xi + B1 delta + B2 psi_dot_des + B3 psi_ddot_des + F f``,
``f_i = gamma_i sum_j W_ij sigma_ij(alpha_i)`` (eq. 9, 14), ``z = C xi`` (camera).

Discretisation: the model is integrated exactly over each physics tick ``dt`` with the
inputs and the estimated force held (zero-order hold, :func:`.gains.discretize`), so
the observer is stable at any rate; corrections happen only when a camera frame arrives
(NaN rows are prediction-only), with the certified frame gain ``L`` of
:func:`.gains.synthesize_gains`.

Adaptation (the repaired eq. 15): with ``Upsilon = d xi_hat / d w`` the sensitivity of the
state estimate to the weights (Zhang 2002),

    predict:  xi-  = Ad xi + Bd u + Fd Gamma Phi(alpha_hat) w,     Upsilon- = Ad Upsilon + Fd Gamma Phi
    frame:    nu = z - C xi-,   Psi = C Upsilon-
              w+ = Proj( w + K nu ),    K = P_w Psi^T (Psi P_w Psi^T + R)^-1   (recursive least squares)
              xi+ = xi- + L nu + (I - L C) Upsilon- (w+ - w),   Upsilon+ = (I - L C) Upsilon-

so ``K`` is the paper's weight gain made time-varying (a constant ``K`` cannot be
certified, SPEC §3). With ``e = xi - xi_hat = Upsilon w_tilde + eta`` the part ``eta``
obeys the certified error dynamics of :mod:`.gains` and the weights follow a linear
regression on the innovation. ``adaptation="gradient"`` replaces RLS by a normalised
gradient step ``K = mu Psi^T R^-1 / (1 + tr(Psi^T R^-1 Psi))``.

Optional latency compensation: a frame that shows the state ``latency`` seconds ago is
compared with the prediction stored for that instant, and the correction is propagated
to the present through ``Ad^m`` (exact for the linear part).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from numpy.typing import NDArray

from ..params import CameraParams, ParameterError, VehicleParams
from ._rls import projected_step, rls_gain
from .basis import SoftClipBasis
from .gains import ObserverGains, discretize

__all__ = ["NeuroAdaptiveObserver", "ObserverTrace", "AdaptationParams"]


@dataclass(frozen=True)
class AdaptationParams:
    """Weight-adaptation settings (standard deviations in units of the basis weight range).

    Parameters
    ----------
    law : {"rls", "gradient"}
        Recursive least squares (default) or normalised gradient.
    initial_std : float
        Prior std of every weight, ``P_w(0) = (initial_std * r)^2 I`` with ``r`` the
        basis' :attr:`~.basis.SoftClipBasis.weight_range`.
    random_walk : float
        Weight random walk [1/sqrt(s)] (``P_w += (random_walk r)^2 T I`` per frame): keeps
        learning alive and lets the curve follow slow changes (wear, pressure).
    max_std : float
        Upper bound of each weight's std (``P_w`` stays bounded without excitation).
    measurement_std : tuple of float, optional
        ``(e1 [m], e2 [rad])`` std used in ``R``; default the camera's noise (floored
        at 1 mm and 1 mrad, which also absorbs unmodelled dynamics).
    step : float
        Normalised-gradient step ``mu`` (``law="gradient"``), in (0, 2).
    settle_time_constants : float
        Weights are frozen after a reset until the initial state error has decayed by
        ``exp(-settle_time_constants)`` at the certified rate (3: to 5 %), so the start-up
        transient is not learned as a tire force.
    prior_length, prior_symmetry : float
        Smooth-curve prior: the initial covariance is ``(initial_std r)^2`` times
        :meth:`~.basis.SoftClipBasis.prior_correlation` (neighbouring slip segments and
        mirror segments learn together); 0 makes the weights independent.
    """

    law: str = "rls"
    initial_std: float = 0.25
    random_walk: float = 0.0
    max_std: float = 1.0
    measurement_std: tuple[float, float] | None = None
    step: float = 0.2
    settle_time_constants: float = 3.0
    prior_length: float = 1.0
    prior_symmetry: float = 0.0

    def __post_init__(self) -> None:
        if self.law not in ("rls", "gradient"):
            raise ParameterError(f"AdaptationParams.law must be 'rls' or 'gradient', got {self.law!r}")
        for name in ("initial_std", "max_std"):
            if not getattr(self, name) > 0:
                raise ParameterError(f"AdaptationParams.{name} must be > 0")
        if not self.random_walk >= 0:
            raise ParameterError("AdaptationParams.random_walk must be >= 0")
        if not 0 < self.step < 2:
            raise ParameterError("AdaptationParams.step must be in (0, 2)")
        if not self.settle_time_constants >= 0:
            raise ParameterError("AdaptationParams.settle_time_constants must be >= 0")


@dataclass
class ObserverTrace:
    """Per-tick estimates (row ``j`` = posterior at ``t_j``).

    Attributes
    ----------
    t : (n,) time [s]
    xi : (n, 4) estimated ``[e1, e1_dot, e2, e2_dot]``
    slip : (n, 2) estimated slip angles [rad]
    force_nonlinear : (n, 2) estimated nonlinear axle force ``f_hat`` [N]
    force : (n, 2) estimated total axle force ``2 C alpha_hat + f_hat`` [N]
    weights : (n, 2N) weights
    innovation : (n, 2) camera innovation ``z - C xi-`` (NaN without frame)
    """

    t: NDArray
    xi: NDArray
    slip: NDArray
    force_nonlinear: NDArray
    force: NDArray
    weights: NDArray
    innovation: NDArray
    diverged: bool = False
    diverged_at: float | None = None
    meta: dict = field(default_factory=dict)

    @staticmethod
    def concatenate(traces: list["ObserverTrace"]) -> "ObserverTrace":
        keys = ("t", "xi", "slip", "force_nonlinear", "force", "weights", "innovation")
        out = {k: np.concatenate([getattr(tr, k) for tr in traces]) for k in keys}
        div = [tr for tr in traces if tr.diverged]
        return ObserverTrace(**out, diverged=bool(div), diverged_at=div[0].diverged_at if div else None)


# -- compiled core ------------------------------------------------------------------------
@njit(cache=True)
def _activations(a, lo, hi, off, lam, out):
    """Soft clips (eq. 30) of one slip ``a`` minus their offsets into ``out`` (N,), numerically stable."""
    for j in range(lo.shape[0]):
        x1 = -lam * (a - lo[j])
        x2 = lam * (a - hi[j])
        sp1 = max(x1, 0.0) + math.log1p(math.exp(-abs(x1)))
        sp2 = max(x2, 0.0) + math.log1p(math.exp(-abs(x2)))
        out[j] = a + (sp1 - sp2) / lam - off[j]


@njit(cache=True)
def _forces(x, w, delta, pdd, vx, lf, lr, lo, hi, off, lam, gamma, sig, phi):
    """Slip (eq. 13), ``Gamma Phi`` into ``phi`` (nw,) and ``f_hat`` (eq. 14) at state ``x``."""
    N = lo.shape[1]
    af = delta - (x[1] - vx * x[2] + lf * x[3] + lf * pdd) / vx
    ar = -(x[1] - vx * x[2] - lr * x[3] - lr * pdd) / vx
    _activations(af, lo[0], hi[0], off[0], lam, sig)
    ff = 0.0
    for a in range(N):
        phi[a] = gamma[0] * sig[a]
        ff += phi[a] * w[a]
    _activations(ar, lo[1], hi[1], off[1], lam, sig)
    fr = 0.0
    for a in range(N):
        phi[N + a] = gamma[1] * sig[a]
        fr += phi[N + a] * w[N + a]
    return af, ar, ff, fr


@njit(cache=True)
def _predict(x, ups, ff, fr, phi, u0, u1, u2, Ad, Bd, Fd, tmp):
    """One exact-ZOH tick: ``x = Ad x + Bd u + Fd f``, ``Upsilon = Ad Upsilon + Fd Gamma Phi``."""
    nw = ups.shape[1]
    N = nw // 2
    xn0 = np.empty(4)
    for r in range(4):
        acc = Bd[r, 0] * u0 + Bd[r, 1] * u1 + Bd[r, 2] * u2 + Fd[r, 0] * ff + Fd[r, 1] * fr
        for c in range(4):
            acc += Ad[r, c] * x[c]
        xn0[r] = acc
    for r in range(4):
        x[r] = xn0[r]
    for c in range(nw):
        for r in range(4):
            acc = 0.0
            for k in range(4):
                acc += Ad[r, k] * ups[k, c]
            tmp[r, c] = acc
    for c in range(N):
        for r in range(4):
            ups[r, c] = tmp[r, c] + Fd[r, 0] * phi[c]
            ups[r, N + c] = tmp[r, N + c] + Fd[r, 1] * phi[N + c]


@njit(cache=True)
def _correct(x, w, ups, pw, nu1, nu2, L, law, r_term, q_dt, p_max, mu, wlo, whi, kg, pk, psi, dw):
    """Frame correction: weights by RLS/gradient with projection, then state and sensitivity."""
    nw = w.shape[0]
    for a in range(nw):  # Psi = C Upsilon (rows e1 and e2)
        psi[0, a] = ups[0, a]
        psi[1, a] = ups[2, a]
    if law == 0:  # recursive least squares, r_term = diag(R)
        rls_gain(pw, psi, r_term[0], r_term[1], q_dt, p_max, kg, pk)
    elif law == -1:  # adaptation frozen (settling after a reset)
        for a in range(nw):
            kg[a, 0] = 0.0
            kg[a, 1] = 0.0
    else:  # normalised gradient, r_term = diag(R^-1)
        norm = 1.0
        for a in range(nw):
            norm += psi[0, a] * psi[0, a] * r_term[0] + psi[1, a] * psi[1, a] * r_term[1]
        for a in range(nw):
            kg[a, 0] = mu * psi[0, a] * r_term[0] / norm
            kg[a, 1] = mu * psi[1, a] * r_term[1] / norm
    projected_step(w, kg, nu1, nu2, wlo, whi, dw)
    ud0 = 0.0
    ud2 = 0.0
    for r in range(4):  # xi += L nu + (I - L C) Upsilon dw
        acc = 0.0
        for a in range(nw):
            acc += ups[r, a] * dw[a]
        if r == 0:
            ud0 = acc
        elif r == 2:
            ud2 = acc
        x[r] += acc
    for r in range(4):
        x[r] += L[r, 0] * (nu1 - ud0) + L[r, 1] * (nu2 - ud2)
    for c in range(nw):  # Upsilon = (I - L C) Upsilon
        u0 = ups[0, c]
        u2 = ups[2, c]
        for r in range(4):
            ups[r, c] -= L[r, 0] * u0 + L[r, 1] * u2


@njit(cache=True)
def _observer_kernel(
    delta, pdd, pddd, z1, z2, predict_last,
    x, w, ups, pw,
    Ad, Bd, Fd, L,
    lo, hi, off, lam, gamma, wlo, whi, lf, lr, vx,
    law, r_term, q_dt, p_max, mu,
    lat_m, hist_x, hist_ups, hist_u, hist_i,
    div_bound, div_state, settle,
    out_x, out_slip, out_f, out_w, out_nu,
):  # fmt: skip
    """Rows in order: [store prior] -> correct with the row's frame -> record -> predict.

    ``settle = [ticks since reset, ticks to wait]``: before that the weights stay frozen
    (state-only correction).
    """
    n = delta.shape[0]
    nw = w.shape[0]
    N = nw // 2
    sig = np.empty(N)
    phi = np.empty(nw)
    kg = np.empty((nw, 2))
    pk = np.empty((2, nw))
    psi = np.empty((2, nw))
    dw = np.empty(nw)
    tmp = np.empty((4, nw))
    hlen = hist_x.shape[0]
    for j in range(n):
        if lat_m > 0:  # remember the prior and the inputs of this tick
            h = hist_i[0] % hlen
            for r in range(4):
                hist_x[h, r] = x[r]
                for c in range(nw):
                    hist_ups[h, r, c] = ups[r, c]
            hist_u[h, 0] = delta[j]
            hist_u[h, 1] = pdd[j]
            hist_u[h, 2] = pddd[j]
            hist_i[0] += 1
        if z1[j] == z1[j] and z2[j] == z2[j]:
            back = lat_m if lat_m < hist_i[0] else hist_i[0] - 1
            if lat_m > 0 and back > 0:
                # the frame shows t_j - latency: restore the prior stored then, correct there,
                # and predict forward again with the stored inputs (out-of-sequence update)
                k0 = hist_i[0] - 1 - back
                hk = k0 % hlen
                for r in range(4):
                    x[r] = hist_x[hk, r]
                    for c in range(nw):
                        ups[r, c] = hist_ups[hk, r, c]
            nu1 = z1[j] - x[0]
            nu2 = z2[j] - x[2]
            out_nu[j, 0] = nu1
            out_nu[j, 1] = nu2
            if abs(nu1) > div_bound[0] or abs(nu2) > div_bound[1]:
                div_state[0] += 1.0
                if div_state[0] >= 5.0 and div_state[1] == 0.0:
                    div_state[1] = 1.0
                    div_state[2] = j
            else:
                div_state[0] = 0.0
            _correct(x, w, ups, pw, nu1, nu2, L, law if settle[0] >= settle[1] else -1, r_term, q_dt, p_max, mu, wlo, whi, kg, pk, psi, dw)
            if lat_m > 0 and back > 0:
                k0 = hist_i[0] - 1 - back
                for i in range(k0, hist_i[0] - 1):
                    hi_ = i % hlen
                    u0, u1, u2 = hist_u[hi_, 0], hist_u[hi_, 1], hist_u[hi_, 2]
                    af, ar, ff, fr = _forces(x, w, u0, u1, vx, lf, lr, lo, hi, off, lam, gamma, sig, phi)
                    _predict(x, ups, ff, fr, phi, u0, u1, u2, Ad, Bd, Fd, tmp)
                    hn = (i + 1) % hlen
                    for r in range(4):
                        hist_x[hn, r] = x[r]
                        for c in range(nw):
                            hist_ups[hn, r, c] = ups[r, c]
        else:
            out_nu[j, 0] = math.nan
            out_nu[j, 1] = math.nan
        af, ar, ff, fr = _forces(x, w, delta[j], pdd[j], vx, lf, lr, lo, hi, off, lam, gamma, sig, phi)
        for r in range(4):
            out_x[j, r] = x[r]
        out_slip[j, 0] = af
        out_slip[j, 1] = ar
        out_f[j, 0] = ff
        out_f[j, 1] = fr
        for a in range(nw):
            out_w[j, a] = w[a]
        if j < n - 1 or predict_last:
            _predict(x, ups, ff, fr, phi, delta[j], pdd[j], pddd[j], Ad, Bd, Fd, tmp)
            settle[0] += 1


class NeuroAdaptiveObserver:
    """Neuro-adaptive observer of the lateral error states and the tire-force weights.

    Parameters
    ----------
    vehicle : VehicleParams
        Nominal vehicle (its ``Cf``, ``Cr`` give the linear part ``2 C alpha``).
    basis : SoftClipBasis
        Activations, scales ``gamma`` and ``W_max``.
    gains : ObserverGains
        Certified frame gain (:func:`.gains.synthesize_gains`).
    physics_dt : float
        Prediction step [s] (the rows of the data).
    adaptation : AdaptationParams, optional
        Weight-adaptation law and its settings.
    camera : CameraParams, optional
        Sets the default measurement noise in ``R`` and the latency.
    latency_compensation : bool
        Compensate ``camera.latency`` (delayed-frame correction).
    divergence_bound : tuple of float
        Innovation ``(e1 [m], e2 [rad])`` beyond which, on 5 consecutive frames, the
        estimate is flagged as diverged (:attr:`diverged`); it is not silently continued.
    initial_weights : array_like, optional
        ``w(0)`` (2N,), e.g. from :func:`.warm_start.least_squares_weights`.

    Notes
    -----
    The vocabulary follows filterpy: :meth:`predict` advances one tick with the known
    inputs, :meth:`update` corrects with a frame; :meth:`run` processes whole arrays of
    rows (correct-then-predict per row) in compiled code.
    """

    def __init__(
        self,
        vehicle: VehicleParams,
        basis: SoftClipBasis,
        gains: ObserverGains,
        physics_dt: float = 1e-3,
        adaptation: AdaptationParams | None = None,
        camera: CameraParams | None = None,
        latency_compensation: bool = False,
        divergence_bound: tuple[float, float] = (1.0, 0.2),
        initial_weights: NDArray | None = None,
    ) -> None:
        if not physics_dt > 0:
            raise ParameterError(f"physics_dt must be > 0, got {physics_dt!r}")
        self.vehicle = vehicle
        self.basis = basis
        self.gains = gains
        self.dt = float(physics_dt)
        self.adaptation = adaptation or AdaptationParams()
        self.camera = camera or CameraParams()
        self.divergence_bound = np.asarray(divergence_bound, dtype=float)
        self._disc_cache: dict[float, tuple] = {}
        std = self.adaptation.measurement_std
        if std is None:
            std = tuple(max(a, b) for a, b in zip(self.camera.noise_std, (1e-3, 1e-3)))
        self.measurement_std = np.asarray(std, dtype=float)
        lat = self.camera.latency if latency_compensation else 0.0
        self.latency_ticks = int(round(lat / self.dt))
        self.initial_weights = (
            np.zeros(basis.n_weights) if initial_weights is None else np.asarray(initial_weights, dtype=float).copy()
        )
        if self.initial_weights.shape != (basis.n_weights,):
            raise ParameterError(f"initial_weights must have shape ({basis.n_weights},)")
        self.reset()

    # -- state ---------------------------------------------------------------------------
    def reset(self, xi0: NDArray | None = None, weights: NDArray | None = None) -> None:
        """Start again from ``xi0`` (default zero, as in the paper) and ``weights``."""
        nw = self.basis.n_weights
        self.x = np.zeros(4) if xi0 is None else np.asarray(xi0, dtype=float).reshape(4).copy()
        w0 = self.initial_weights if weights is None else np.asarray(weights, dtype=float)
        self.w = np.clip(w0, self.basis.weight_lower.ravel(), self.basis.weight_upper.ravel()).astype(float)
        self.ups = np.zeros((4, nw))
        a = self.adaptation
        corr = self.basis.prior_correlation(a.prior_length, a.prior_symmetry)
        self.pw = np.ascontiguousarray(corr * (a.initial_std * self.basis.weight_range) ** 2)
        hlen = max(self.latency_ticks + 2, 2)
        self.hist_x = np.zeros((hlen, 4))
        self.hist_ups = np.zeros((hlen, 4, nw))
        self.hist_u = np.zeros((hlen, 3))
        self.hist_i = np.zeros(1, dtype=np.int64)
        self.div_state = np.zeros(3)
        settle_s = self.adaptation.settle_time_constants / max(self.gains.decay_rate, 1e-6)
        self.settle = np.array([0, int(round(settle_s / self.dt))], dtype=np.int64)
        self.t = 0.0

    @property
    def diverged(self) -> bool:
        """Whether the innovation exceeded the divergence bound on 5 consecutive frames."""
        return bool(self.div_state[1])

    @property
    def weights(self) -> NDArray:
        return self.w.copy()

    # -- model ---------------------------------------------------------------------------
    def _discretization(self, vx: float):
        key = round(float(vx), 2)
        hit = self._disc_cache.get(key)
        if hit is None:
            d = discretize(self.vehicle, self.dt, key)
            hit = (np.ascontiguousarray(d.Ad), np.ascontiguousarray(d.Bd), np.ascontiguousarray(d.Fd))
            self._disc_cache[key] = hit
        return hit

    def _kernel_constants(self, vx: float) -> tuple:
        b, a = self.basis, self.adaptation
        r = self.measurement_std**2
        r_term = r if a.law == "rls" else 1.0 / r  # RLS uses R, the gradient R^-1
        return (
            *self._discretization(vx), np.ascontiguousarray(self.gains.L),
            b.lower, b.upper, b.offset, float(b.sharpness), b.scale,
            np.ascontiguousarray(b.weight_lower.ravel()), np.ascontiguousarray(b.weight_upper.ravel()),
            self.vehicle.lf, self.vehicle.lr, float(vx),
            0 if a.law == "rls" else 1, np.ascontiguousarray(r_term),
            (a.random_walk * self.basis.weight_range) ** 2 * self.gains.frame_period,
            (a.max_std * self.basis.weight_range) ** 2, a.step,
            self.latency_ticks, self.hist_x, self.hist_ups, self.hist_u, self.hist_i,
            self.divergence_bound, self.div_state, self.settle,
        )  # fmt: skip

    def run(self, sensors: dict[str, NDArray], predict_last: bool = True) -> ObserverTrace:
        """Process rows of sensor data (correct with the row's frame, then predict one tick).

        Parameters
        ----------
        sensors : dict of str -> ndarray
            Equal-length arrays ``t, delta, vx, psi_dot_des, psi_ddot_des, e1, e2``
            (``e1``/``e2`` NaN where no frame arrived), e.g. ``SimulationLog.sensors``,
            an env's ``info["sensor_log"]`` or :func:`sensors_from_log`. Ground truth is
            not accepted.

        Returns
        -------
        ObserverTrace
        """
        leaked = [k for k in sensors if k.startswith("true")]
        if leaked:
            raise ValueError(f"the observer must not see ground truth; got columns {leaked}")
        t = np.asarray(sensors["t"], dtype=float)
        n = len(t)
        vx_all = np.asarray(sensors["vx"], dtype=float)
        cols = [np.ascontiguousarray(sensors[k], dtype=float) for k in ("delta", "psi_dot_des", "psi_ddot_des", "e1", "e2")]
        nw = self.basis.n_weights
        out_x, out_slip, out_f = np.empty((n, 4)), np.empty((n, 2)), np.empty((n, 2))
        out_w, out_nu = np.empty((n, nw)), np.empty((n, 2))
        # segments of (nearly) constant speed share one discretisation
        start = 0
        while start < n:
            v0 = round(float(vx_all[start]), 2)
            stop = start + 1
            if np.all(np.abs(vx_all[start:] - v0) < 0.005):
                stop = n
            else:
                while stop < n and abs(vx_all[stop] - v0) < 0.005:
                    stop += 1
            sl = slice(start, stop)
            _observer_kernel(
                *(c[sl] for c in cols), bool(predict_last or stop < n), self.x, self.w, self.ups, self.pw,
                *self._kernel_constants(v0),
                out_x[sl], out_slip[sl], out_f[sl], out_w[sl], out_nu[sl],
            )  # fmt: skip
            start = stop
        if n:
            self.t = float(t[-1]) + (self.dt if predict_last else 0.0)
        lin = out_slip * np.array([2 * self.vehicle.Cf, 2 * self.vehicle.Cr])
        diverged_at = float(t[int(self.div_state[2])]) if self.diverged and n else None
        return ObserverTrace(t, out_x, out_slip, out_f, lin + out_f, out_w, out_nu, self.diverged, diverged_at)

    def predict(self, delta: float, psi_dot_des: float, psi_ddot_des: float, vx: float | None = None) -> None:
        """Advance one tick ``dt`` with the known inputs held (no frame)."""
        self.run(self._row(delta, psi_dot_des, psi_ddot_des, vx, math.nan, math.nan))

    def update(self, z: tuple[float, float], delta: float, psi_dot_des: float, vx: float | None = None) -> None:
        """Correct the current estimate with the frame ``z = (e1 [m], e2 [rad])`` (no time advance).

        ``delta`` and ``psi_dot_des`` are the current inputs (for the slip estimate).
        """
        self.run(self._row(delta, psi_dot_des, 0.0, vx, z[0], z[1]), predict_last=False)

    def _row(self, delta, pdd, pddd, vx, e1, e2) -> dict:
        vx = self.vehicle.vx if vx is None else vx
        return {
            "t": np.array([self.t]),
            "delta": np.array([delta]),
            "vx": np.array([vx]),
            "psi_dot_des": np.array([pdd]),
            "psi_ddot_des": np.array([pddd]),
            "e1": np.array([e1]),
            "e2": np.array([e2]),
        }

    def estimate_now(self, delta: float, psi_dot_des: float, vx: float | None = None) -> dict[str, NDArray]:
        """The current (predicted) estimate with the inputs held: state, slip, forces.

        After :meth:`run` the observer has predicted to the instant after the last row;
        this evaluates slip (eq. 13) and force (eq. 14, 29) there, the same instant as an
        env's end-of-step ground truth.
        """
        vx = self.vehicle.vx if vx is None else vx
        v = self.vehicle
        x = self.x
        af = delta - (x[1] - vx * x[2] + v.lf * x[3] + v.lf * psi_dot_des) / vx
        ar = -(x[1] - vx * x[2] - v.lr * x[3] - v.lr * psi_dot_des) / vx
        slip = np.array([af, ar])
        fnl = np.array([float(self.basis.nonlinear_force(slip[i], self.w, i)) for i in (0, 1)])
        return {
            "state": x.copy(),
            "slip": slip,
            "force_nonlinear": fnl,
            "force": fnl + slip * np.array([2 * v.Cf, 2 * v.Cr]),
            "weights": self.w.copy(),
            "diverged": self.diverged,
        }

    # -- learned tire curve (eq. 29) -------------------------------------------------------
    def axle_force(self, alpha: NDArray, axle: str, weights: NDArray | None = None) -> NDArray:
        """Learned total axle force ``2 C alpha + gamma sum W sigma(alpha)`` [N] (eq. 29)."""
        i = _axle_index(axle)
        w = self.w if weights is None else weights
        c2 = 2 * (self.vehicle.Cf if i == 0 else self.vehicle.Cr)
        a = np.asarray(alpha, dtype=float)
        return c2 * a + self.basis.nonlinear_force(a, w, i)

    def cornering_stiffness(self, weights: NDArray | None = None) -> tuple[float, float]:
        """Per-tire cornering stiffness: half the slope of the learned axle curve at zero slip [N/rad]."""
        w = self.w if weights is None else weights
        out = []
        for i, c in enumerate((self.vehicle.Cf, self.vehicle.Cr)):
            slope = 2 * c + float(self.basis.nonlinear_slope(0.0, w, i))
            out.append(slope / 2.0)
        return out[0], out[1]


def _axle_index(axle: str) -> int:
    if axle in ("front", 0):
        return 0
    if axle in ("rear", 1):
        return 1
    raise ParameterError(f"axle must be 'front' or 'rear', got {axle!r}")
