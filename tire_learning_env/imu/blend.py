r"""Never worse than the linear Kalman filter: the observer and the KF weighted by how well each
predicts the IMU (interacting-multiple-model mode probabilities).

Why. The neuro-adaptive observer learns the tire curves, so where its model holds it beats
a filter with fixed linear tires (the Revs log: 0.3 against 0.7 deg of sideslip RMSE). But
from ``(a_y, r)`` alone the sideslip is seen only *through* the tire curves: when the
learned curve or the states are not to be trusted (an ``a_y`` much noisier than the bicycle
model's motion, a sensor offset, a drive with little excitation, a vehicle file that is
wrong), a filter that trusts nothing learned can be the better one. Which one is better
changes along a log, and no reference sensor says so on line.

How. Both estimators run over the log on their own (:class:`~..observer.NeuroAdaptiveObserver`
and :class:`~..baselines.LinearKalmanFilter`). Each hands over, per row, its innovations of
``a_y`` and ``r`` (one-step prediction errors, before the correction). Treat them as the two
modes of an interacting multiple model (Blom and Bar-Shalom 1988) and run its
mode-probability recursion::

    c_j(k)  = sum_i p_ij mu_i(k-1)                      (Markov switching, p_ii = 1 - dt/T_s)
    mu_j(k) = c_j(k) N(nu_j(k); 0, S_j(k)) / sum_l c_l(k) N(nu_l(k); 0, S_l(k))

with ``S_j(k)`` the innovation variance of mode ``j`` per channel, *measured* from its own
past innovations (exponentially weighted over ``time_constant`` seconds, bias-corrected;
Mehra's innovation-based adaptive estimation) rather than taken from the filters' nominal
covariances: those rest on noise and force-error models that are exactly what may be wrong,
and the two filters compute them differently, whereas measured prediction errors put both
on one footing. With a Gaussian likelihood and the variance at its estimate, the log
likelihood ratio of the two modes over a window is ``-n/2 ln(S_obs / S_kf)``: the mode with
the smaller prediction error wins, by the prediction-error (maximum-likelihood) criterion.
A channel enters only on rows where both modes measured it.

The reported estimate is the mixture mean ``x = sum_j mu_j x_j`` (state, slip, force) with
the mixture variance ``sum_j mu_j (P_j + (x_j - x)^2)``. Unlike the full IMM, the filters'
states are not re-initialised from the mixture (no interaction step): each filter stays
exactly what it is on its own, so the mixture is a convex combination of two estimates and
its error is at most the larger of theirs at every instant, and close to the smaller one
wherever the prediction errors tell them apart.

Offline. The reported estimate comes from the refined observer pass, which already used the
whole log; its mode probabilities are the fixed-interval smoothed ones, ``p(mode at k | all
rows)`` (forward-backward recursion of the same Markov chain, ``smooth=True``), with each row's
innovation variances measured on both sides of it. The first rows are then judged with the
evidence that follows them instead of sitting at the prior during the warm-up, which is
exactly when the KF (started at zero with a huge covariance) is at its worst. The causal blend
keeps the forward recursion above.

Causal blend: a third mode. The observer's causal pass learns with one of two laws
(``AdaptationParams.causal_update``): per-measurement recursive least squares (``"rls"``, the IMU
default) or one Gauss-Newton step over all data so far at the end of each 2 s block (``"block"``).
Neither is the better on every car: on the real Ferrari log the per-measurement law's sideslip RMSE
is 0.34 deg against 0.49 for the block law (KF 0.69), on the simulated ``imu_white`` family the block
law's causal blend is no worse than the KF on 15 of 20 logs against 11 of 20 (median 0.027 against
0.037 deg, KF 0.029). So the causal blend runs both and lets the IMU decide: modes ``observer``
(the core's law), ``observer_<other law>`` and ``linear_kf``, the observer modes sharing the prior
(``BlendParams.other_causal_law``). Measured with the recursion above: on the Ferrari log the
per-measurement law gets 0.74 of the weight on average (0.362 deg, against 0.356 with two modes), on
``imu_white`` the block law gets 0.72-0.94.

Limits. Prediction error is evidence about the IMU channels, not about the sideslip itself:
two filters that predict ``a_y`` and ``r`` equally well but disagree on the sideslip get
equal weights (the sideslip error is then at most the average of theirs).

Fallback when the curve is not identified (:func:`file_not_contradicted`, ``BlendParams.unidentified_fallback``).
From ``(a_y, r)`` the yaw response fixes the understeer combination of the two stiffnesses tightly,
their common scale only through the transients; the sideslip follows the rear curve
(``beta = -alpha_r + lr r / vx``), so it moves along the scale while the IMU predictions hardly
change. Where the data leave the scale open, a filter can predict the IMU much better (it has the
understeer right) and still have the worse sideslip: the innovation likelihood then says nothing
about which sideslip to trust. The log tells us so when an axle's stiffness is **not identified**
(two-sigma band wider than ``ObserverConfig.identifiable_rel_2sigma``, the core's verdict) **and**
the vehicle file's stiffness lies inside the learned two-sigma band on **both** axles (the log has
not shown the file wrong). The reported (refined) blend then keeps the prior mode probabilities on
every row instead of the innovation evidence: the mixture of the two, whose RMSE is at most the mean
of theirs (Minkowski), so no worse than the KF's wherever the observer's is not, and at most half the
excess where it is. Neither condition alone suffices: on the Ferrari log neither axle is identified
either (bands +-23 / +-22 %) but the file is 3.5 / 4.3 sigma off, and the learned curve wins (0.41
against 0.69 deg); where the curve is identified the learned one is the better even when the file is
inside its band (``imu_vibration_bias`` scenario 5: file 1.6 / 1.0 sigma off, observer 0.0076 against
the KF's 0.0455 deg; the KF has no sensor-offset states). Measured on ``imu_white`` scenario 2 (race car,
2.2 m/s^2 a_y noise; rear band +-11.3 %, file 0.8 / 1.1 sigma from the learned stiffness):
0.0175 deg -> 0.0137 against the KF's 0.0160.

Causal fallback (:func:`causal_fallback_rows`, ``BlendParams.causal_fallback``). The causal blend
cannot know the verdict of the whole log, but it can know the verdict of the rows so far: the
``"block"`` law closes each 2 s block with a Gauss-Newton step over every block before it, so at each
block end it holds a fit and its weight covariance from past rows only
(:meth:`~..observer.NeuroAdaptiveObserver.causal_stiffness`: the slope at zero and its standard
deviation per tire). Where that verdict is the same fallback (a stiffness not identified, the file
inside the band on both axles), and before the first block closes, the causal blend gives the
linear KF alone: a causal pass whose curve has not yet earned trust, on a log that has not shown the
file wrong, is the file's estimate. (The reported blend keeps the prior mixture instead: its observer
pass used the whole log and is close to the KF where the curve is not identified, so the mixture beats
both; a causal pass still learning is not, and a mixture would carry its error.) When a block's
verdict changes, the evidence recursion resumes from the KF. Measured on ``imu_white`` scenario 2:
the causal blend 0.0315 deg -> 0.0168 (KF 0.0160; 22 of 23 blocks fall back, the last two do not: the
block law's rear band narrows to +-15 % with the file 2.0 sigma off, its own curve 18 % high). The
verdict's band is the larger of the weight covariance's and the batch-means sandwich's over the closed
blocks (:mod:`..observer.block_law`; docs/real_car.md, "Causal sandwich").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, Mapping, Sequence

import numpy as np
from numba import njit
from numpy.typing import NDArray

from ..observer._kernel import CH_AY, CH_R
from ..observer.model import StateIndex
from ..observer.trace import EstimateTrace
from ..params import ParameterError, _Params

__all__ = ["BlendParams", "Blend", "mode_probabilities", "blend_traces", "file_not_contradicted", "causal_fallback_rows",
           "MODES"]  # fmt: skip

#: mode order of :attr:`Blend.mu`
MODES = ("observer", "linear_kf")


@dataclass(frozen=True)
class BlendParams(_Params):
    """Settings of the mode-probability recursion (physical time scales, not fitted to a log).

    Parameters
    ----------
    time_constant : float
        Memory of the measured innovation variances [s] (a few vehicle responses).
    sojourn : float
        Mean time a mode stays the better one [s] (Markov switching: ``p_switch = dt / sojourn``
        per row); bounds how fast the weights can move.
    warmup : float
        No likelihood is used before each mode has this long of innovations [s] (variances
        not yet measured): the modes keep their prior weights.
    prior_observer : float
        Initial probability of the observer mode (shared by the observer modes when there are several).
    other_causal_law : bool
        The causal blend (:func:`~.estimate.estimate_imu`) also weighs the observer's causal pass
        under the other learning law (``AdaptationParams.causal_update``: per-measurement ``"rls"``,
        the IMU default, and the ``"block"`` law): which one predicts the IMU better is the log's
        to say (module docstring).
    unidentified_fallback : bool
        The reported blend keeps the prior mode probabilities when the learned curve is not
        identified and the vehicle file lies inside its two-sigma band on both axles
        (:func:`file_not_contradicted`, module docstring).
    causal_fallback : bool
        The causal blend gives the linear KF alone on the rows where the causal verdict, from the
        ``"block"`` law's fit over the rows so far, is the same fallback: a stiffness not identified
        and the file inside the band on both axles (:func:`causal_fallback_rows`, module docstring).
    """

    time_constant: float = 2.0
    sojourn: float = 5.0
    warmup: float = 1.0
    prior_observer: float = 0.5
    other_causal_law: bool = True
    unidentified_fallback: bool = True
    causal_fallback: bool = True

    _positive: ClassVar[tuple[str, ...]] = ("time_constant", "sojourn")
    _non_negative: ClassVar[tuple[str, ...]] = ("warmup",)

    def __post_init__(self) -> None:
        super().__post_init__()
        if not 0.0 < self.prior_observer < 1.0:
            raise ParameterError(f"BlendParams.prior_observer must be in (0, 1), got {self.prior_observer!r}")


@njit(cache=True)
def _switch(logmu, dt, sojourn):
    """Markov switching over ``dt`` [s] (mixing of the mode probabilities, ``p_switch = dt / sojourn``
    shared among the other modes); log probabilities in and out."""
    M = logmu.shape[0]
    if M < 2 or not dt > 0.0:
        return logmu
    p = min(dt / sojourn, 0.5)
    mu = np.exp(logmu - logmu.max())
    mu /= mu.sum()
    c = (1.0 - p) * mu + p * (1.0 - mu) / (M - 1)
    return np.log(np.maximum(c, 1e-300))


@njit(cache=True)
def _mode_kernel(t, nu, tau, sojourn, warmup, mu0, hold, hold_mu, out_mu, out_var, out_ll):
    """``nu`` (M, n, C) innovations (NaN: none); fills ``out_mu`` (n, M), the predictive
    innovation variances ``out_var`` (M, n, C) used at each row and the rows' log likelihoods
    ``out_ll`` (n, M) (zero where a row is not used). On rows with ``hold[k]`` the probabilities
    are ``hold_mu`` (the variances still learn the row's innovations); the recursion goes on from
    there when the hold ends."""
    M, n, C = nu.shape
    s1 = np.zeros((M, C))  # bias-corrected EW mean of nu^2: sum of weights and weighted sum
    s0 = np.zeros((M, C))
    t_first = np.full((M, C), np.nan)
    logmu = np.log(mu0)
    for k in range(n):
        dt = t[k] - t[k - 1] if k > 0 else 0.0
        logmu = _switch(logmu, dt, sojourn)
        # decay the variance statistics
        a = math.exp(-dt / tau) if dt > 0.0 else 1.0
        for j in range(M):
            for ch in range(C):
                s0[j, ch] *= a
                s1[j, ch] *= a
        ll = np.zeros(M)
        for ch in range(C):
            usable = True
            for j in range(M):
                if not (nu[j, k, ch] == nu[j, k, ch]) or s0[j, ch] <= 0.0:
                    usable = False
                elif not (t[k] - t_first[j, ch] >= warmup):
                    usable = False
            for j in range(M):
                v = s1[j, ch] / s0[j, ch] if s0[j, ch] > 0.0 else np.nan
                out_var[j, k, ch] = v
                if usable:
                    v = max(v, 1e-300)
                    ll[j] += -0.5 * (nu[j, k, ch] ** 2 / v + math.log(2.0 * math.pi * v))
        if hold[k]:  # the held probabilities exactly; the recursion goes on from them
            for j in range(M):
                logmu[j] = math.log(max(hold_mu[j], 1e-300))
                out_ll[k, j] = 0.0
                out_mu[k, j] = hold_mu[j]
        else:
            logmu = logmu + ll
            logmu -= logmu.max()
            mu = np.exp(logmu)
            mu /= mu.sum()
            for j in range(M):
                out_ll[k, j] = ll[j]
                out_mu[k, j] = mu[j]
        # then learn this row's innovations (the variance at row k used only rows < k)
        for j in range(M):
            for ch in range(C):
                x = nu[j, k, ch]
                if x == x:
                    if not (t_first[j, ch] == t_first[j, ch]):
                        t_first[j, ch] = t[k]
                    s0[j, ch] += 1.0
                    s1[j, ch] += x * x


@njit(cache=True)
def _two_sided_loglik(t, nu, tau, warmup, out_var, out_ll):
    """The rows' log likelihoods ``out_ll`` (n, M) with each mode's innovation variance measured from
    the rows on *both* sides of the row (exponentially weighted over ``tau`` each way, the row itself
    left out): for a pass that already used the whole log. A channel enters a row when every mode
    measured it there and the log holds at least ``warmup`` seconds of that channel."""
    M, n, C = nu.shape
    f0 = np.zeros((M, n, C))
    f1 = np.zeros((M, n, C))
    s0 = np.zeros((M, C))
    s1 = np.zeros((M, C))
    for k in range(n):  # forward sums over rows < k
        a = math.exp(-(t[k] - t[k - 1]) / tau) if k > 0 else 1.0
        for j in range(M):
            for ch in range(C):
                s0[j, ch] *= a
                s1[j, ch] *= a
                f0[j, k, ch] = s0[j, ch]
                f1[j, k, ch] = s1[j, ch]
                x = nu[j, k, ch]
                if x == x:
                    s0[j, ch] += 1.0
                    s1[j, ch] += x * x
    span = np.zeros((M, C))
    t_lo = np.full((M, C), np.inf)
    t_hi = np.full((M, C), -np.inf)
    for k in range(n):
        for j in range(M):
            for ch in range(C):
                if nu[j, k, ch] == nu[j, k, ch]:
                    t_lo[j, ch] = min(t_lo[j, ch], t[k])
                    t_hi[j, ch] = max(t_hi[j, ch], t[k])
    for j in range(M):
        for ch in range(C):
            span[j, ch] = t_hi[j, ch] - t_lo[j, ch]
    s0[:] = 0.0
    s1[:] = 0.0
    for k in range(n - 1, -1, -1):  # backward sums over rows > k, and the likelihoods
        a = math.exp(-(t[k + 1] - t[k]) / tau) if k < n - 1 else 1.0
        for j in range(M):
            for ch in range(C):
                s0[j, ch] *= a
                s1[j, ch] *= a
        for ch in range(C):
            usable = True
            for j in range(M):
                if not (nu[j, k, ch] == nu[j, k, ch]) or not (span[j, ch] >= warmup) or f0[j, k, ch] + s0[j, ch] <= 0.0:
                    usable = False
            for j in range(M):
                w0 = f0[j, k, ch] + s0[j, ch]
                v = (f1[j, k, ch] + s1[j, ch]) / w0 if w0 > 0.0 else np.nan
                out_var[j, k, ch] = v
                if usable:
                    v = max(v, 1e-300)
                    out_ll[k, j] += -0.5 * (nu[j, k, ch] ** 2 / v + math.log(2.0 * math.pi * v))
        for j in range(M):
            for ch in range(C):
                x = nu[j, k, ch]
                if x == x:
                    s0[j, ch] += 1.0
                    s1[j, ch] += x * x


@njit(cache=True)
def _filter_given_loglik(t, ll, sojourn, mu0, out_mu):
    """The forward (filtered) mode probabilities from given row log likelihoods ``ll`` (n, M)."""
    n, M = ll.shape
    logmu = np.log(mu0)
    for k in range(n):
        dt = t[k] - t[k - 1] if k > 0 else 0.0
        logmu = _switch(logmu, dt, sojourn)
        logmu = logmu + ll[k]
        logmu -= logmu.max()
        mu = np.exp(logmu)
        mu /= mu.sum()
        for j in range(M):
            out_mu[k, j] = mu[j]


@njit(cache=True)
def _smooth_kernel(t, sojourn, mu_f, ll, out_mu):
    """Fixed-interval smoothing of the mode probabilities (forward-backward recursion of the
    two-state Markov chain): ``mu_f`` (n, M) the forward (filtered) probabilities, ``ll`` (n, M) the
    rows' log likelihoods; fills ``out_mu`` (n, M) with ``p(mode at k | all rows)``."""
    n, M = mu_f.shape
    logb = np.zeros(M)  # log backward message beta_k(j) = p(rows > k | mode j at k), normalised
    for k in range(n - 1, -1, -1):
        lg = np.log(np.maximum(mu_f[k], 1e-300)) + logb
        lg -= lg.max()
        g = np.exp(lg)
        g /= g.sum()
        for j in range(M):
            out_mu[k, j] = g[j]
        if k == 0:
            break
        # message to row k-1: sum_j P(j at k | i at k-1) L_j(k) beta_k(j)
        dt = t[k] - t[k - 1]
        p = min(dt / sojourn, 0.5) if (M > 1 and dt > 0.0) else 0.0
        e = logb + ll[k]
        e_max = e.max()
        w = np.exp(e - e_max)
        tot = w.sum()
        nb = np.empty(M)
        for i in range(M):
            nb[i] = (1.0 - p) * w[i] + p * (tot - w[i]) / max(M - 1, 1)
        logb = np.log(np.maximum(nb, 1e-300))
        logb -= logb.max()


def mode_probabilities(t: NDArray, innovations: list[NDArray], params: BlendParams | None = None,
                       prior: NDArray | None = None, smooth: bool = False, hold: NDArray | None = None,
                       hold_mu: NDArray | None = None) -> tuple[NDArray, NDArray]:  # fmt: skip
    """Mode probabilities from per-row innovations (module docstring): causal, or smoothed over the
    whole log.

    Parameters
    ----------
    t : array (n,)
        Row times [s].
    innovations : list of array (n, C)
        One per mode, the same channels in the same columns (NaN: not measured).
    params : BlendParams, optional
    prior : array (M,), optional
        Initial probabilities (default: ``params.prior_observer`` for mode 0, the rest shared).
    smooth : bool
        ``False``: causal (filtered) probabilities, ``p(mode at k | rows <= k)``. ``True``: the
        fixed-interval smoothed ones, ``p(mode at k | all rows)`` (forward-backward recursion of
        the same Markov chain and likelihoods): for an estimate that already used the whole log.
    hold : array (n,) of bool, optional
        Causal only: rows whose probabilities are set to ``hold_mu`` instead of the evidence (the
        causal fallback, :func:`causal_fallback_rows`); the recursion resumes from them.
    hold_mu : array (M,), optional
        The probabilities on held rows (default: the last mode, the linear KF, alone).

    Returns
    -------
    mu : array (n, M)
        Probability of each mode at each row (after the row's innovations; with ``smooth`` given
        every row). The smoothed ones judge each row with innovation variances measured on both
        sides of it (no warm-up: the first rows are judged with the variances that follow them).
    variance : array (M, n, C)
        Innovation variances each mode was judged with (measured from rows before).
    """
    params = params or BlendParams()
    nu = np.ascontiguousarray(np.stack([np.asarray(v, dtype=float) for v in innovations]))
    M, n, C = nu.shape
    if prior is None:
        prior = np.r_[params.prior_observer, np.full(M - 1, (1.0 - params.prior_observer) / max(M - 1, 1))][:M]
    prior = np.asarray(prior, dtype=float)
    if prior.shape != (M,) or np.any(prior <= 0):
        raise ParameterError(f"prior must hold {M} positive probabilities, got {prior!r}")
    out_mu = np.empty((n, M))
    out_var = np.full((M, n, C), np.nan)
    out_ll = np.zeros((n, M))
    tt = np.ascontiguousarray(t, dtype=float)
    if hold is not None and smooth:
        raise ParameterError("hold applies to the causal probabilities (smooth=False)")
    if not smooth:
        hold_rows = np.zeros(n, dtype=np.bool_) if hold is None else np.ascontiguousarray(hold, dtype=np.bool_)
        if hold_rows.shape != (n,):
            raise ParameterError(f"hold must hold one flag per row ({n}), got shape {hold_rows.shape}")
        h_mu = np.r_[np.zeros(M - 1), 1.0] if hold_mu is None else np.asarray(hold_mu, dtype=float)
        if h_mu.shape != (M,) or np.any(h_mu < 0) or not h_mu.sum() > 0:
            raise ParameterError(f"hold_mu must hold {M} non-negative probabilities, got {hold_mu!r}")
        _mode_kernel(tt, nu, float(params.time_constant), float(params.sojourn), float(params.warmup), prior / prior.sum(),
                     hold_rows, h_mu / h_mu.sum(), out_mu, out_var, out_ll)  # fmt: skip
        return out_mu, out_var
    # smoothed: variances from both sides of each row, the filter, then the backward pass
    _two_sided_loglik(tt, nu, float(params.time_constant), float(params.warmup), out_var, out_ll)
    _filter_given_loglik(tt, out_ll, float(params.sojourn), prior / prior.sum(), out_mu)
    out_s = np.empty((n, M))
    if n:
        _smooth_kernel(tt, float(params.sojourn), out_mu, out_ll, out_s)
    return out_s, out_var


@dataclass
class Blend:
    """The mixture of the observer and the linear KF (:func:`blend_traces`).

    Attributes
    ----------
    t : (n,) [s]
    vy, yaw_rate : (n,) mixture state [m/s], [rad/s]
    beta : (n,) sideslip [rad] ``atan(vy / vx)``
    beta_std : (n,) mixture standard deviation of ``beta`` [rad]
    slip, force : (n, 2) mixture slip angles [rad] and axle forces [N]
    mu : (n, M) probabilities of the ``modes`` (the observer's, then the linear KF last)
    modes : tuple of str
        Mode names (default :data:`MODES`).
    """

    t: NDArray
    vy: NDArray
    yaw_rate: NDArray
    beta: NDArray
    beta_std: NDArray
    slip: NDArray
    force: NDArray
    mu: NDArray
    modes: tuple = MODES

    @property
    def mu_observer(self) -> NDArray:
        """Probability of the observer modes together (every mode but the linear KF)."""
        return 1.0 - self.mu[:, -1] if self.mu.shape[1] > 2 else self.mu[:, 0]

    def summary(self) -> dict:
        """Time shares of the modes (the ``blend`` block of ``metrics.json``)."""
        m = self.mu_observer
        return {
            "modes": list(self.modes),
            "mean_probability_by_mode": {name: float(np.mean(self.mu[:, j])) for j, name in enumerate(self.modes)},
            "mean_probability_observer": float(np.mean(m)),
            "fraction_observer_above_0.5": float(np.mean(m > 0.5)),
            "fraction_observer_above_0.9": float(np.mean(m > 0.9)),
            "fraction_kf_above_0.9": float(np.mean(m < 0.1)),
            "final_probability_observer": float(m[-1]) if len(m) else float("nan"),
        }


def file_not_contradicted(report: Mapping[str, Mapping], nominal: Sequence[float]) -> dict:
    """Whether the learned curve leaves the sideslip to the prior: an axle not identified and the
    vehicle file's stiffness inside the learned two-sigma band on both axles (module docstring).

    Parameters
    ----------
    report : mapping axle -> dict
        ``EstimationResult.stiffness_report()`` (``identified``, ``value_N_per_rad``, ``std_N_per_rad``;
        per tire).
    nominal : (float, float)
        The vehicle file's per-tire stiffness ``(Cf, Cr)`` [N/rad], in the report's axle order.

    Returns
    -------
    dict
        ``fallback`` (bool), ``not_identified`` (axles), ``file_sigma`` (per axle, the file's distance
        from the learned stiffness in its standard deviations; NaN without a band).
    """
    axles = list(report)
    if len(axles) != len(nominal):
        raise ParameterError(f"nominal must hold one stiffness per axle {axles}, got {nominal!r}")
    z = {}
    for a, c in zip(axles, nominal):
        sd = float(report[a]["std_N_per_rad"])
        d = float(c) - float(report[a]["value_N_per_rad"])
        z[a] = d / sd if sd > 0.0 else math.nan  # no band: not inside it
    unident = [a for a in axles if not report[a]["identified"]]
    inside = all(abs(v) <= 2.0 for v in z.values())
    return {"fallback": bool(unident) and inside, "not_identified": unident, "file_sigma": z}


def causal_fallback_rows(t: NDArray, verdicts: Mapping[str, NDArray], nominal: Sequence[float],
                         identifiable_rel_2sigma: float) -> tuple[NDArray, dict]:  # fmt: skip
    """Rows on which the causal blend falls back to the linear KF (module docstring).

    Parameters
    ----------
    t : array (n,)
        Row times [s].
    verdicts : mapping
        The ``"block"`` law's causal stiffness data (:meth:`~..observer.NeuroAdaptiveObserver.causal_stiffness`,
        ``trace.meta["causal_stiffness"]``): ``t`` (nb,) block ends [s], ``value``, ``std`` (nb, 2) per tire [N/rad].
    nominal : (float, float)
        The vehicle file's per-tire stiffness ``(Cf, Cr)`` [N/rad].
    identifiable_rel_2sigma : float
        The core's identifiability threshold (``ObserverConfig.identifiable_rel_2sigma``).

    Returns
    -------
    hold : array (n,) of bool
        Row ``k`` is held when the last block that closed at or before ``t[k]`` left a stiffness not
        identified and the file inside the two-sigma band on both axles (:func:`file_not_contradicted`'s
        rule on the data so far), and on the rows before the first block closes (no curve learned yet).
    info : dict
        ``rows_held_fraction``, ``blocks`` and ``blocks_fallback``.
    """
    t = np.asarray(t, dtype=float)
    tb = np.asarray(verdicts["t"], dtype=float)
    k = np.asarray(verdicts["value"], dtype=float).reshape(-1, 2)
    s = np.asarray(verdicts["std"], dtype=float).reshape(-1, 2)
    c = np.asarray(nominal, dtype=float)
    if len(tb) != len(k) or len(tb) != len(s) or c.shape != (2,):
        raise ParameterError("verdicts need t (nb,), value and std (nb, 2); nominal one stiffness per axle")
    unident = np.any(2.0 * s > identifiable_rel_2sigma * np.abs(k), axis=1)
    inside = np.all((s > 0.0) & (np.abs(c - k) <= 2.0 * s), axis=1)
    fb = unident & inside
    j = np.searchsorted(tb, t, side="right") - 1  # the last block closed at or before each row
    hold = np.where(j >= 0, fb[np.maximum(j, 0)], True) if len(tb) else np.ones(len(t), dtype=bool)
    return hold.astype(bool), {"rows_held_fraction": float(np.mean(hold)) if len(t) else 0.0,
                               "blocks": int(len(tb)), "blocks_fallback": int(np.sum(fb))}  # fmt: skip


def blend_traces(observer: EstimateTrace, kalman: EstimateTrace, params: BlendParams | None = None,
                 smooth: bool = False, alternatives: Sequence[tuple[str, EstimateTrace]] = (),
                 evidence: bool = True, hold: NDArray | None = None) -> Blend:  # fmt: skip
    """Mode probabilities from the IMU innovations of the traces, and the mixture estimate.

    Parameters
    ----------
    observer, kalman : EstimateTrace
        Over the same rows (``innovation`` columns ``CH_AY``, ``CH_R``; ``state`` and ``std`` columns
        ``StateIndex.VY``, ``StateIndex.R``).
    params : BlendParams, optional
    smooth : bool
        Smoothed mode probabilities (:func:`mode_probabilities`): for an observer pass that is
        not causal anyway (the offline refinement); ``False`` keeps the blend causal.
    alternatives : sequence of (name, EstimateTrace)
        Further observer modes over the same rows (the causal blend: the observer under the other
        causal learning law). Modes in order: ``observer``, the alternatives, ``linear_kf``; the
        observer modes share the prior ``params.prior_observer``.
    evidence : bool
        ``False``: no innovation evidence, the prior mode probabilities on every row (the fallback
        of :func:`file_not_contradicted`).
    hold : array (n,) of bool, optional
        Causal blend only: rows on which the linear KF alone is the estimate (the causal fallback,
        :func:`causal_fallback_rows`); the evidence recursion resumes after them.
    """
    params = params or BlendParams()
    traces = [observer, *(tr for _, tr in alternatives), kalman]
    names = ("observer", *(str(n) for n, _ in alternatives), "linear_kf")
    if len(set(names)) != len(names):
        raise ParameterError(f"mode names must differ, got {names}")
    for tr in traces[1:]:
        if len(tr.t) != len(observer.t) or not np.array_equal(tr.t, observer.t):
            raise ParameterError("the observer and Kalman traces must cover the same rows")
    n_obs = len(traces) - 1
    prior = np.r_[np.full(n_obs, params.prior_observer / n_obs), 1.0 - params.prior_observer]
    imu = [CH_AY, CH_R]
    if evidence:
        mu, _ = mode_probabilities(observer.t, [tr.innovation[:, imu] for tr in traces], params, prior=prior, smooth=smooth,
                                   hold=hold)  # fmt: skip
    else:
        mu = np.tile(prior, (len(observer.t), 1))
    vx = np.maximum(observer.vx, 1e-3)
    vy = sum(mu[:, j] * tr.state[:, StateIndex.VY] for j, tr in enumerate(traces))
    yaw_rate = sum(mu[:, j] * tr.state[:, StateIndex.R] for j, tr in enumerate(traces))
    beta = sum(mu[:, j] * tr.beta for j, tr in enumerate(traces))
    var = np.zeros_like(beta)
    for j, tr in enumerate(traces):
        s = tr.std[:, StateIndex.VY] / vx if tr.std.size else np.zeros_like(beta)
        var += mu[:, j] * (s**2 + (tr.beta - beta) ** 2)
    slip = sum(mu[:, j : j + 1] * tr.slip for j, tr in enumerate(traces))
    force = sum(mu[:, j : j + 1] * tr.force for j, tr in enumerate(traces))
    return Blend(observer.t.copy(), vy, yaw_rate, beta, np.sqrt(var), slip, force, mu, names)
