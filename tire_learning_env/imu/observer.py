r"""Neuro-adaptive observer, IMU measurement variant: ``[vy, r]`` and tire-force weights together.

Per log row ``k`` (inputs ``delta_k``, ``vx_k``; measurement ``z_k = [a_y, r]``; model of
:mod:`.model`, gains of :mod:`.gains`)::

    innovation   nu   = z_k - h(x_k, w_k)                      h = [(F_yf cos delta + F_yr)/m, r]
    regressor    Psi  = C_k Upsilon_k + D_w,k                  D_w = dh/dw: the a_y feedthrough
    weights      w+   = Proj( w + K nu ),   K = P_w Psi^T (Psi P_w Psi^T + R)^-1    (RLS)
                 x_k += Upsilon_k (w+ - w),   nu <- z_k - h(x_k, w+)
    predict      x_{k+1} = x_k + dt f(x_k, w+) + L_{c(k)} nu
                 Upsilon_{k+1} = (I + dt A_k - L C_k) Upsilon_k + dt G_w,k - L D_w,k

``Upsilon = dx_hat/dw`` is the sensitivity of the state estimate to the weights (Zhang
2002, as in the camera variant); ``A_k, C_k`` the Jacobians at the estimate with the
learned slopes; ``G_w = df/dw`` (Euler step), ``D_w = dh/dw``: lateral acceleration is a
direct function of the learned force, so the weights are learned both from the force
(feedthrough) and from how the force moved the state (through ``Upsilon``). The
regression uses the innovation of *both* channels with ``R = diag(noise_std^2)``.

Rows are processed in order and only past rows are used: the observer is causal (the
estimate at row ``k`` is the prediction from rows ``< k`` plus the weight update of row
``k``). Rows with a missing (NaN) ``a_y`` or ``r`` are prediction-only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from numpy.typing import NDArray

from ..observer._rls import projected_step, rls_gain
from ..observer.basis import SoftClipBasis
from ..params import ParameterError, VehicleParams
from .gains import ImuGains
from .model import V_FLOOR

__all__ = ["ImuObserver", "ImuTrace"]


@dataclass
class ImuTrace:
    """Per-row estimates of the IMU observer.

    Attributes
    ----------
    t : (n,) time [s]
    x : (n, 2) estimated ``[vy [m/s], r [rad/s]]``
    beta : (n,) sideslip ``atan(vy/vx)`` [rad]
    slip : (n, 2) slip angles [rad]
    force_nonlinear : (n, 2) learned nonlinear axle force ``f_hat`` [N]
    force : (n, 2) total axle force ``2 C alpha + f_hat`` [N]
    weights : (n, 2N)
    innovation : (n, 2) ``[a_y, r]`` innovation (NaN on prediction-only rows)
    cell : (n,) speed cell of the gain used
    """

    t: NDArray
    x: NDArray
    beta: NDArray
    slip: NDArray
    force_nonlinear: NDArray
    force: NDArray
    weights: NDArray
    innovation: NDArray
    cell: NDArray
    diverged: bool = False
    diverged_at: float | None = None
    meta: dict = field(default_factory=dict)


@njit(cache=True)
def _eval(x0, x1, w, d, v, lf, lr, c2f, c2r, lo, hi, off, lam, gamma, phi, dphi):
    """Slips, activations ``gamma sigma`` into ``phi`` (2N,), their slopes into ``dphi``,
    nonlinear forces and learned total slopes of both axles at the state ``(x0, x1)``."""
    N = lo.shape[1]
    af = d - (x0 + lf * x1) / v
    ar = -(x0 - lr * x1) / v
    out_f = np.zeros(2)
    out_k = np.zeros(2)
    for i in range(2):
        a = af if i == 0 else ar
        fn = 0.0
        kn = 0.0
        for j in range(N):
            z1 = -lam * (a - lo[i, j])
            z2 = lam * (a - hi[i, j])
            sp1 = max(z1, 0.0) + math.log1p(math.exp(-abs(z1)))
            sp2 = max(z2, 0.0) + math.log1p(math.exp(-abs(z2)))
            sig = a + (sp1 - sp2) / lam - off[i, j]
            # slope: sigmoid(lam (a - lo)) - sigmoid(lam (a - hi))
            s1 = 0.5 * (1.0 + math.tanh(-0.5 * z1))
            s2 = 0.5 * (1.0 + math.tanh(0.5 * z2))
            phi[i * N + j] = gamma[i] * sig
            dphi[i * N + j] = gamma[i] * (s1 - s2)
            fn += phi[i * N + j] * w[i * N + j]
            kn += dphi[i * N + j] * w[i * N + j]
        out_f[i] = fn
        out_k[i] = kn
    return af, ar, out_f[0], out_f[1], c2f + out_k[0], c2r + out_k[1]


@njit(cache=True)
def _imu_kernel(
    t, delta, vx, ay, yr,
    x, w, ups, pw,
    edges, Lc,
    lo, hi, off, lam, gamma, wlo, whi,
    m, Iz, lf, lr, c2f, c2r, v_floor,
    r_ay, r_r, q_rate, p_max, settle_until, adapt,
    beta_bound, dt_last, status,
    out_x, out_slip, out_f, out_w, out_nu, out_cell,
):  # fmt: skip
    """The observer over all rows (see the module docstring). ``status = [diverged, row]``.

    After the last row the state is predicted one more step of ``dt_last``, so consecutive
    calls on consecutive chunks give the same result as one call on all rows.
    """
    n = delta.shape[0]
    nw = w.shape[0]
    N = nw // 2
    nc = Lc.shape[0]
    phi = np.empty(nw)
    dphi = np.empty(nw)
    psi = np.empty((2, nw))
    pk = np.empty((2, nw))
    kg = np.empty((nw, 2))
    dw = np.empty(nw)
    tmp = np.empty((2, nw))
    for k in range(n):
        v = vx[k] if vx[k] > v_floor else v_floor
        h = t[k + 1] - t[k] if k < n - 1 else dt_last
        d = delta[k]
        cd = math.cos(d)
        c = 0
        while c < nc - 1 and v >= edges[c + 1]:
            c += 1
        out_cell[k] = c
        have = (ay[k] == ay[k]) and (yr[k] == yr[k])
        af, ar, ff, fr, kf, kr = _eval(x[0], x[1], w, d, v, lf, lr, c2f, c2r, lo, hi, off, lam, gamma, phi, dphi)
        Ff = c2f * af + ff
        Fr = c2r * ar + fr
        nu0 = 0.0
        nu1 = 0.0
        if have:
            nu0 = ay[k] - (Ff * cd + Fr) / m
            nu1 = yr[k] - x[1]
            if adapt and t[k] >= settle_until:
                c00 = -(kf * cd + kr) / (m * v)
                c01 = -(kf * cd * lf - kr * lr) / (m * v)
                for a in range(nw):  # Psi = C Upsilon + D_w
                    dwa = (cd * phi[a] if a < N else phi[a]) / m
                    psi[0, a] = c00 * ups[0, a] + c01 * ups[1, a] + dwa
                    psi[1, a] = ups[1, a]
                rls_gain(pw, psi, r_ay, r_r, q_rate * h, p_max, kg, pk)
                moved = projected_step(w, kg, nu0, nu1, wlo, whi, dw)
                if moved:  # x += Upsilon dw, then the innovation at the new (x, w)
                    for r_ in range(2):
                        acc = 0.0
                        for a in range(nw):
                            acc += ups[r_, a] * dw[a]
                        x[r_] += acc
                    af, ar, ff, fr, kf, kr = _eval(x[0], x[1], w, d, v, lf, lr, c2f, c2r, lo, hi, off, lam, gamma, phi, dphi)
                    Ff = c2f * af + ff
                    Fr = c2r * ar + fr
                    nu0 = ay[k] - (Ff * cd + Fr) / m
                    nu1 = yr[k] - x[1]
            out_nu[k, 0] = nu0
            out_nu[k, 1] = nu1
        else:
            out_nu[k, 0] = math.nan
            out_nu[k, 1] = math.nan
        out_x[k, 0] = x[0]
        out_x[k, 1] = x[1]
        out_slip[k, 0] = af
        out_slip[k, 1] = ar
        out_f[k, 0] = ff
        out_f[k, 1] = fr
        for a in range(nw):
            out_w[k, a] = w[a]
        if status[0] == 0.0 and not (abs(x[0]) <= beta_bound * v and abs(x[1]) < 10.0):
            status[0] = 1.0
            status[1] = k
        # Jacobians at the estimate (learned slopes), Euler step, gain of the speed cell
        a00 = -(kf * cd + kr) / (m * v)
        a01 = -(kf * cd * lf - kr * lr) / (m * v)
        a10 = -(kf * cd * lf - kr * lr) / (Iz * v)
        a11 = -(kf * cd * lf * lf + kr * lr * lr) / (Iz * v)
        l00 = Lc[c, 0, 0] if have else 0.0
        l01 = Lc[c, 0, 1] if have else 0.0
        l10 = Lc[c, 1, 0] if have else 0.0
        l11 = Lc[c, 1, 1] if have else 0.0
        # Upsilon_{k+1} = (I + h A - L C) Upsilon + h G_w - L D_w   (C = [[a00, a01], [0, 1]])
        m00 = 1.0 + h * a00 - l00 * a00
        m01 = h * (a01 - v) - l00 * a01 - l01
        m10 = h * a10 - l10 * a00
        m11 = 1.0 + h * a11 - l10 * a01 - l11
        for a in range(nw):
            if a < N:
                g0 = cd * phi[a] / m
                g1 = lf * cd * phi[a] / Iz
            else:
                g0 = phi[a] / m
                g1 = -lr * phi[a] / Iz
            dwa = g0  # D_w row of a_y equals G_w row 0 (both (F cos delta + F)/m)
            tmp[0, a] = m00 * ups[0, a] + m01 * ups[1, a] + h * g0 - l00 * dwa
            tmp[1, a] = m10 * ups[0, a] + m11 * ups[1, a] + h * g1 - l10 * dwa
        for a in range(nw):
            ups[0, a] = tmp[0, a]
            ups[1, a] = tmp[1, a]
        vy_dot = (Ff * cd + Fr) / m - v * x[1]
        r_dot = (lf * Ff * cd - lr * Fr) / Iz
        x0 = x[0] + h * vy_dot + l00 * nu0 + l01 * nu1
        x1 = x[1] + h * r_dot + l10 * nu0 + l11 * nu1
        x[0] = x0
        x[1] = x1


class ImuObserver:
    """Neuro-adaptive observer of ``[vy, r]`` and the tire-force weights from an IMU.

    Parameters
    ----------
    vehicle : VehicleParams
        Nominal vehicle (``2 Cf``, ``2 Cr``: the linear part of the axle curves).
    basis : SoftClipBasis
        Activations, scales and weight box (e.g. :func:`.estimate.imu_basis`).
    gains : ImuGains
        Certified speed-scheduled gains.
    noise_std : (float, float)
        ``(a_y [m/s^2], r [rad/s])`` std used in the regression's ``R``.
    initial_std : float
        Prior std of every weight in units of the basis weight range.
    random_walk : float
        Weight random walk [1/sqrt(s)] in units of the weight range (0: stationary tire).
    max_std : float
        Cap of each weight's std in units of the weight range.
    settle_s : float, optional
        Weights are frozen for this long after a reset so the start-up transient of the
        state is not learned as a tire force; default 3 time constants of the nominal
        closed loop (:attr:`.gains.ImuGains.nominal_decay_rate`).
    beta_bound : float
        ``|vy| > beta_bound vx`` (or a non-finite estimate) flags divergence [-].
    initial_weights : array_like, optional
        ``w(0)`` (2N,), e.g. from :func:`..observer.warm_start.least_squares_weights`.
    adapt : bool
        ``False`` freezes the weights (the fixed-curve observer, e.g. the nominal linear
        tire: what the same gains give without learning).
    """

    def __init__(
        self,
        vehicle: VehicleParams,
        basis: SoftClipBasis,
        gains: ImuGains,
        noise_std: tuple[float, float] = (1.0, 0.005),
        initial_std: float = 0.25,
        random_walk: float = 0.0,
        max_std: float = 1.0,
        settle_s: float | None = None,
        beta_bound: float = 0.5,
        initial_weights: NDArray | None = None,
        adapt: bool = True,
    ) -> None:
        if not (initial_std > 0 and max_std > 0 and random_walk >= 0):
            raise ParameterError("initial_std and max_std must be > 0 and random_walk >= 0")
        noise = np.asarray(noise_std, dtype=float)
        if noise.shape != (2,) or np.any(~(noise > 0)):
            raise ParameterError(f"noise_std must be two positive values, got {noise_std!r}")
        self.vehicle = vehicle
        self.basis = basis
        self.gains = gains
        self.noise_std = noise
        self.initial_std = float(initial_std)
        self.random_walk = float(random_walk)
        self.max_std = float(max_std)
        if settle_s is None:
            settle_s = 3.0 / max(gains.nominal_decay_rate, 1e-3)
        self.settle_s = float(settle_s)
        self.beta_bound = float(beta_bound)
        self.adapt = bool(adapt)
        nw = basis.n_weights
        self.initial_weights = np.zeros(nw) if initial_weights is None else np.asarray(initial_weights, float).copy()
        if self.initial_weights.shape != (nw,):
            raise ParameterError(f"initial_weights must have shape ({nw},)")
        self.reset()

    def reset(self, x0: NDArray | None = None, weights: NDArray | None = None) -> None:
        """Start again from ``x0`` (default zero) and ``weights`` (default the initial ones)."""
        nw = self.basis.n_weights
        self.x = np.zeros(2) if x0 is None else np.asarray(x0, dtype=float).reshape(2).copy()
        w0 = self.initial_weights if weights is None else np.asarray(weights, dtype=float)
        self.w = np.clip(w0, self.basis.weight_lower.ravel(), self.basis.weight_upper.ravel()).astype(float)
        self.ups = np.zeros((2, nw))
        self.pw = np.eye(nw) * (self.initial_std * self.basis.weight_range) ** 2
        self._started = False

    @property
    def weights(self) -> NDArray:
        return self.w.copy()

    def run(self, sensors: dict[str, NDArray]) -> ImuTrace:
        """Process rows ``t, delta, vx, ay, yaw_rate`` (continuing from the current state).

        Ground truth is refused: the observer must never see ``true_*`` columns.
        """
        leaked = [k for k in sensors if str(k).startswith("true")]
        if leaked:
            raise ValueError(f"the observer must not see ground truth; got columns {leaked}")
        missing = [k for k in ("t", "delta", "vx", "ay", "yaw_rate") if k not in sensors]
        if missing:
            raise ParameterError(f"IMU observer rows need columns {missing}")
        t = np.ascontiguousarray(sensors["t"], dtype=float)
        cols = [np.ascontiguousarray(sensors[k], dtype=float) for k in ("delta", "vx", "ay", "yaw_rate")]
        n = len(t)
        b = self.basis
        nw = b.n_weights
        out_x, out_slip, out_f = np.empty((n, 2)), np.empty((n, 2)), np.empty((n, 2))
        out_w, out_nu, out_cell = np.empty((n, nw)), np.empty((n, 2)), np.empty(n, dtype=np.int64)
        status = np.zeros(2)
        if n == 0:
            return self._trace(t, cols[1], out_x, out_slip, out_f, out_w, out_nu, out_cell, status)
        if not self._started:
            self._settle_until = float(t[0]) + self.settle_s
            self._started = True
        wr = b.weight_range
        v = self.vehicle
        _imu_kernel(
            t, *cols, self.x, self.w, self.ups, self.pw,
            np.ascontiguousarray(self.gains.edges), np.ascontiguousarray(self.gains.L),
            b.lower, b.upper, b.offset, float(b.sharpness), b.scale,
            np.ascontiguousarray(b.weight_lower.ravel()), np.ascontiguousarray(b.weight_upper.ravel()),
            v.m, v.Iz, v.lf, v.lr, 2.0 * v.Cf, 2.0 * v.Cr, V_FLOOR,
            float(self.noise_std[0] ** 2), float(self.noise_std[1] ** 2),
            (self.random_walk * wr) ** 2, (self.max_std * wr) ** 2, self._settle_until, self.adapt,
            self.beta_bound, float(self.gains.dt), status,
            out_x, out_slip, out_f, out_w, out_nu, out_cell,
        )  # fmt: skip
        return self._trace(t, cols[1], out_x, out_slip, out_f, out_w, out_nu, out_cell, status)

    def _trace(self, t, vx, out_x, out_slip, out_f, out_w, out_nu, out_cell, status) -> ImuTrace:
        lin = out_slip * np.array([2 * self.vehicle.Cf, 2 * self.vehicle.Cr])
        beta = np.arctan2(out_x[:, 0], np.maximum(vx, V_FLOOR)) if len(t) else np.empty(0)
        diverged = bool(status[0])
        return ImuTrace(
            t, out_x, beta, out_slip, out_f, lin + out_f, out_w, out_nu, out_cell,
            diverged, float(t[int(status[1])]) if diverged else None,
        )  # fmt: skip

    # -- learned tire curve (eq. 29) ------------------------------------------------------
    def axle_force(self, alpha: NDArray, axle: str | int, weights: NDArray | None = None) -> NDArray:
        """Learned total axle force ``2 C alpha + gamma sum W sigma(alpha)`` [N] (eq. 29)."""
        i = _axle_index(axle)
        w = self.w if weights is None else np.asarray(weights, dtype=float)
        c2 = 2.0 * (self.vehicle.Cf if i == 0 else self.vehicle.Cr)
        a = np.asarray(alpha, dtype=float)
        return c2 * a + self.basis.nonlinear_force(a, w, i)

    def cornering_stiffness(self, weights: NDArray | None = None) -> tuple[float, float]:
        """Per-tire cornering stiffness: half the slope of the learned axle curve at zero slip [N/rad]."""
        w = self.w if weights is None else np.asarray(weights, dtype=float)
        out = []
        for i, c in enumerate((self.vehicle.Cf, self.vehicle.Cr)):
            out.append((2.0 * c + float(self.basis.nonlinear_slope(0.0, w, i))) / 2.0)
        return out[0], out[1]


def _axle_index(axle) -> int:
    if axle in ("front", 0):
        return 0
    if axle in ("rear", 1):
        return 1
    raise ParameterError(f"axle must be 'front' or 'rear', got {axle!r}")


def compile_kernel(observer: ImuObserver) -> None:
    """Compile (or load from numba's cache) the kernel on a 3-row dummy log; the observer's
    state is untouched."""
    saved = (observer.x.copy(), observer.w.copy(), observer.ups.copy(), observer.pw.copy(), observer._started)
    rows = {"t": np.array([0.0, 0.01, 0.02]), "delta": np.zeros(3), "vx": np.full(3, 20.0), "ay": np.zeros(3),
            "yaw_rate": np.zeros(3)}  # fmt: skip
    observer.run(rows)
    observer.x, observer.w, observer.ups, observer.pw, observer._started = saved
