r"""Speed-scheduled observer gains of the IMU variant: vertex LMIs over a speed polytope.

Observer (predictor form, one step ``dt`` per log row, :mod:`.observer`)::

    x_{k+1} = x_k + dt f(x_k, w_k, delta_k, vx_k) + L_{c(k)} (z_k - h(x_k, w_k, delta_k, vx_k))

with ``z = [a_y, r]``, ``f`` and ``h`` the body-frame model of :mod:`.model` and
``L_c`` the gain of the speed cell ``c(k)`` that contains ``vx_k``.

Error system certified
----------------------
Let ``e = x - x_hat``. With the mean-value theorem, the true axle force minus the
model's at the estimated slip is ``k_i (alpha_i - alpha_hat_i) + d_i``: ``k_i`` is the
slope of the *true* curve between the true and the estimated slip (front including
``cos(delta)``), ``d_i`` the approximation error of the learned curve at the estimate
(weight error, basis residual, Euler discretisation error of the plant) [N]. Since
``alpha - alpha_hat = H e`` does not depend on ``delta``,

    e_{k+1} = (I + dt A(theta) - L_c C(theta)) e_k + (dt E - L_c D) d_k - L_c v_k

with ``A, C, E, D`` of :func:`.model.body_matrices`, ``v`` the IMU noise and
``theta = (k_f, k_r, 1/vx, vx)``. The same sample ``k`` enters the dynamics and the
measurement (predictor form), so the error matrix is *affine* in each component of
``theta`` separately; the measurement's direct dependence on the force (``D d``, the
feedthrough of ``a_y``) is kept, not dropped.

Polytope and why the vertices suffice
-------------------------------------
Speed range ``[v_lo, v_hi]`` split into cells ``[v_a, v_b]`` (geometric spacing). In a
cell, ``theta`` lies in the box ``k_f in [k_f_lo, k_f_hi]``, ``k_r in [k_r_lo, k_r_hi]``,
``1/vx in [1/v_b, 1/v_a]``, ``vx in [v_a, v_b]`` (``1/vx`` and ``vx`` treated as
independent: conservative, sound). A multi-affine matrix function on a box is a convex
combination of its 16 vertex values, and the LMIs below are affine in the closed-loop
matrix and the performance output, so holding at the 16 vertices of every cell they hold
for every speed in the range and every admissible slope.

LMIs (scaled states ``x = S x_s``; inputs in units of ``force_error_scale`` and of the
noise std; ``Y_c = P L_c``; one common ``P`` for all cells)::

    [[rho^2 P,             (P A_v - Y_c C_v)^T,  H_v^T],
     [P A_v - Y_c C_v,      P,                    0   ],   >= 0   at every vertex v of cell c
     [H_v,                  0,                    I   ]]

    [[Z_c,  (P B - Y_c Dn, -Y_c)^T], [., P]] >= 0,   trace Z_c <= t,   minimise t

(``A_v = I + dt A`` at the vertex, ``B = dt E``, ``Dn = D``; ``H_v`` = sideslip error
[mrad] and the scaled states). Guarantees, for *any* speed trajectory in the range
(arbitrarily fast switching between cells: the Lyapunov function ``e^T P e`` is common)
and any slopes in the box:

1. with ``d = 0`` and no noise the state error decays at least at the certified rate
   (``rho = exp(-decay_rate dt)``; the certificate reports the rate actually proven);
2. for white unit-variance force error and noise, the steady mean-square weighted error
   (sideslip in mrad, scaled states) is at most ``t`` (robust H2 / guaranteed cost);
   the state error is input-to-state stable with respect to the force error, hence to
   the weight error.

Not certified: weight convergence (needs persistent excitation, as for the camera
variant), a step other than ``dt`` (the observer steps with the log's actual time
differences; :mod:`.logs` rejects jitter above 25 %, the Revs log is exactly uniform),
speeds outside the range (the nearest cell's gain is used and the rows are
counted), slopes outside the box. In particular both axles at the friction peak
(``k_f = k_r = 0``) make the lateral velocity unobservable from ``(a_y, r)``: no
observer can certify decay there, so the box stops at ``slope_fraction_lo`` of the
nominal stiffness (:class:`InfeasibleLMIError` names the binding vertex otherwise).

Every solution is re-checked with numpy (:func:`certify_schedule`): ``P > 0``, the largest
eigenvalue of ``-LMI`` at every vertex of every cell ``<= tol`` (relative), the decay
rate from the generalised eigenvalues, and an independent dense check on the *physical*
set (``1/vx`` tied to ``vx``) that the Lyapunov decrease holds there too. Results are
cached on disk (same directory and conventions as :mod:`..observer.gains`); a cache hit is
re-certified, never trusted.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray

from ..observer.gains import InfeasibleLMIError, default_cache_dir
from ..params import ParameterError, VehicleParams
from .model import body_matrices

__all__ = [
    "ImuGains",
    "synthesize_imu_gains",
    "certify_schedule",
    "speed_edges",
    "slope_box",
    "STATE_SCALE",
    "InfeasibleLMIError",
]

_VERSION = 1  # bump when the formulation changes (invalidates the cache)
#: scaling of ``[vy [m/s], r [rad/s]]`` inside the solve
STATE_SCALE = np.array([0.1, 0.01])
BETA_SCALE = 1e-3  # [rad]: sideslip error unit of the performance output (mrad)


def speed_edges(speed_range: tuple[float, float], n_cells: int) -> NDArray:
    """Geometric cell edges over ``speed_range`` [m/s] (equal steps in ``ln vx``, so ``1/vx``
    varies by the same ratio in every cell)."""
    lo, hi = (float(v) for v in speed_range)
    if not (0 < lo < hi):
        raise ParameterError(f"speed_range must be 0 < lo < hi [m/s], got {speed_range!r}")
    if int(n_cells) < 1:
        raise ParameterError(f"n_cells must be >= 1, got {n_cells!r}")
    return np.geomspace(lo, hi, int(n_cells) + 1)


def slope_box(
    vehicle: VehicleParams,
    slope_fractions: tuple[float, float] = (0.1, 1.5),
    max_steer: float = 0.3,
) -> NDArray:
    """Effective axle-slope box ``[[k_f_lo, k_f_hi], [k_r_lo, k_r_hi]]`` [N/rad].

    ``k_i in [lo, hi] * 2 C_i`` (nominal axle stiffness); the front lower bound also
    carries ``cos(max_steer)`` (the front force acts through ``cos(delta)``).
    """
    lo, hi = (float(v) for v in slope_fractions)
    if not (0 <= lo < hi):
        raise ParameterError(f"slope_fractions must be 0 <= lo < hi, got {slope_fractions!r}")
    if not (0 <= max_steer < math.pi / 2):
        raise ParameterError(f"max_steer must be in [0, pi/2) rad, got {max_steer!r}")
    c2 = np.array([2.0 * vehicle.Cf, 2.0 * vehicle.Cr])
    box = np.column_stack([lo * c2, hi * c2])
    box[0, 0] *= math.cos(max_steer)
    return box


@dataclass
class ImuGains:
    """Certified speed-scheduled gains ``L_c`` (one per speed cell, common Lyapunov matrix).

    Attributes
    ----------
    L : ndarray, shape (n_cells, 2, 2)
        Gain per cell in SI units: ``x_{k+1} = ... + L_c [a_y - a_y_hat, r - r_hat]``.
    edges : ndarray, shape (n_cells + 1,)
        Speed cell edges [m/s].
    P : ndarray, shape (2, 2)
        Common Lyapunov matrix (scaled coordinates ``x = diag(STATE_SCALE) x_s``).
    dt : float
        Step [s] the gains are designed for.
    slope_box : ndarray (2, 2)
        Certified effective axle slopes [N/rad].
    decay_rate : float
        Certified decay rate of the state error over every cell and slope [1/s].
    cell_decay_rate : ndarray (n_cells,)
        The same per cell.
    nominal_decay_rate : float
        Decay rate at the nominal (linear) slopes, slowest over the speed range [1/s]
        (information: what the observer does in the linear region; sets the settling
        time of the weights).
    cost : float
        ``sqrt(t)``: certified RMS bound of the weighted error for unit white inputs.
    max_vertex_eig : float
        Largest relative eigenvalue of ``-LMI`` over all vertices (certificate: ``<= tol``).
    dense_check : dict
        Independent check on the physical set (``1/vx = 1/vx``) on a grid.
    """

    L: NDArray
    edges: NDArray
    P: NDArray
    dt: float
    slope_box: NDArray
    decay_rate: float
    cell_decay_rate: NDArray
    nominal_decay_rate: float
    cost: float
    max_vertex_eig: float
    certified: bool
    tolerance: float
    solve_s: float
    cache_hit: bool = False
    dense_check: dict = field(default_factory=dict)
    settings: dict = field(default_factory=dict)

    @property
    def n_cells(self) -> int:
        return len(self.edges) - 1

    @property
    def speed_range(self) -> tuple[float, float]:
        return float(self.edges[0]), float(self.edges[-1])

    def cell_index(self, vx: NDArray | float) -> NDArray:
        """Cell of each speed (speeds outside the range use the nearest cell)."""
        idx = np.searchsorted(self.edges, np.asarray(vx, dtype=float), side="right") - 1
        return np.clip(idx, 0, self.n_cells - 1)

    def gain(self, vx: float) -> NDArray:
        """``L`` (2, 2) used at speed ``vx`` [m/s]."""
        return self.L[int(self.cell_index(vx))]

    def summary(self) -> dict:
        """The ``lmi`` block of ``metrics.json``."""
        return {
            "what": "common-Lyapunov vertex LMIs, robust H2, predictor-form IMU observer; holds for any "
            "speed trajectory in speed_range_mps and any effective axle slopes in slope_box_N_per_rad",
            "certified": bool(self.certified),
            "speed_range_mps": list(self.speed_range),
            "n_cells": self.n_cells,
            "cell_edges_mps": self.edges.round(4).tolist(),
            "n_vertices": 16 * self.n_cells,
            "slope_box_N_per_rad": {"front": self.slope_box[0].tolist(), "rear": self.slope_box[1].tolist()},
            "slope_box_fraction_of_nominal": self.settings.get("slope_fractions"),
            "dt_s": self.dt,
            "decay_rate_requested": self.settings.get("decay_rate"),
            "decay_rate_certified": float(self.decay_rate),
            "cell_decay_rate_certified": self.cell_decay_rate.round(4).tolist(),
            "nominal_slope_decay_rate": float(self.nominal_decay_rate),
            "h2_cost": float(self.cost),
            "max_vertex_eig": float(self.max_vertex_eig),
            "tolerance": self.tolerance,
            "dense_check": self.dense_check,
            "noise_std": self.settings.get("noise_std"),
            "force_error_scale_N": self.settings.get("force_error_scale"),
            "solve_s": round(self.solve_s, 4),
            "cache_hit": self.cache_hit,
        }


# -- problem data ----------------------------------------------------------------------------
def _vertex_data(vehicle, dt, box, edges, noise, state_weight):
    """Per cell: list of scaled ``(A_v, C_v, H_v, theta_v)`` at the 16 vertices."""
    S = np.diag(STATE_SCALE)
    Si = np.diag(1.0 / STATE_SCALE)
    Ni = np.diag(1.0 / noise)
    cells = []
    for va, vb in zip(edges[:-1], edges[1:]):
        verts = []
        for kf, kr, s, v in itertools.product(box[0], box[1], (1.0 / vb, 1.0 / va), (va, vb)):
            A, C, _, _ = body_matrices(vehicle, v, kf, kr, inv_vx=s)
            As = Si @ (np.eye(2) + dt * A) @ S
            Cs = Ni @ C @ S
            Hs = _performance(s, state_weight)
            verts.append((As, Cs, Hs, (kf, kr, s, v)))
        cells.append(verts)
    return cells


def _performance(inv_vx: float, state_weight: float) -> NDArray:
    """Sideslip error ``vy_err / vx`` in mrad, and the scaled state errors."""
    return np.vstack([[inv_vx * STATE_SCALE[0] / BETA_SCALE, 0.0], state_weight * np.eye(2)])


def _input_data(vehicle, dt, noise, force_error_scale):
    """Scaled force-error input of the dynamics ``B`` and of the measurement ``Dn``."""
    _, _, E, D = body_matrices(vehicle, 1.0, 0.0, 0.0)
    Si = np.diag(1.0 / STATE_SCALE)
    B = Si @ (dt * E) * force_error_scale
    Dn = np.diag(1.0 / noise) @ D * force_error_scale
    return B, Dn


def _lmis(P, Ys, Zs, cells, B, Dn, rho):
    """``(per_vertex[c][v], per_cell[c])``: matrices that must be >= 0 (numpy or cvxpy)."""
    numeric = isinstance(P, np.ndarray)
    if numeric:
        bmat, hstack = np.block, np.hstack
    else:
        import cvxpy as cp

        bmat, hstack = cp.bmat, cp.hstack
    per_vertex, per_cell = [], []
    for verts, Y, Z in zip(cells, Ys, Zs):
        rows = []
        for As, Cs, Hs, _ in verts:
            PA = P @ As - Y @ Cs
            nh = Hs.shape[0]
            rows.append(
                bmat(
                    [
                        [rho**2 * P, PA.T, Hs.T],
                        [PA, P, np.zeros((2, nh))],
                        [Hs, np.zeros((nh, 2)), np.eye(nh)],
                    ]
                )
            )
        per_vertex.append(rows)
        PB = hstack([P @ B - Y @ Dn, -Y])
        per_cell.append(bmat([[Z, PB.T], [PB, P]]))
    return per_vertex, per_cell


def _worst(M: NDArray) -> float:
    M = 0.5 * (M + M.T)
    return float(np.linalg.eigvalsh(-M).max() / max(1.0, np.abs(M).max()))


def certify_schedule(P, Ls, Zs, cells, B, Dn, rho, dt, tol):
    """Independent numpy check of a solution (scaled coordinates of the solve).

    Returns ``(certified, max_vertex_eig, decay_rate, cell_decay, per_vertex_eig)`` where
    ``per_vertex_eig[c, v]`` is the largest relative eigenvalue of ``-LMI`` (``<= tol``
    required; the cell's H2 block counts for each of its vertices) and the decay rates
    come from ``rho_v^2 = max eig(A_cl^T P A_cl, P)`` over the vertices.
    """
    P = 0.5 * (P + P.T)
    Ys = [P @ L for L in Ls]
    per_vertex, per_cell = _lmis(P, Ys, Zs, cells, B, Dn, rho)
    eig = np.array([[max(_worst(M), _worst(Mc)) for M in rows] for rows, Mc in zip(per_vertex, per_cell)])
    cell_rho = []
    for verts, L in zip(cells, Ls):
        r = 0.0
        for As, Cs, _, _ in verts:
            Acl = As - L @ Cs
            r = max(r, float(np.sqrt(max(sla.eigh(Acl.T @ P @ Acl, P, eigvals_only=True).max(), 0.0))))
        cell_rho.append(r)
    cell_rho = np.array(cell_rho)
    cell_decay = np.where(cell_rho > 0, -np.log(np.maximum(cell_rho, 1e-300)) / dt, np.inf)
    ok = bool(np.linalg.eigvalsh(P).min() > 0 and eig.max() <= tol and cell_rho.max() < 1.0)
    return ok, float(eig.max()), float(cell_decay.min()), cell_decay, eig


def _dense_check(vehicle, dt, box, edges, P, Ls, noise, rho_cert, n=5) -> dict:
    """Lyapunov decrease on the physical set: ``1/vx`` tied to ``vx``, a grid in every cell."""
    S = np.diag(STATE_SCALE)
    Si = np.diag(1.0 / STATE_SCALE)
    Ni = np.diag(1.0 / noise)
    worst = 0.0
    count = 0
    for (va, vb), L in zip(zip(edges[:-1], edges[1:]), Ls):
        for kf, kr, v in itertools.product(np.linspace(*box[0], n), np.linspace(*box[1], n), np.linspace(va, vb, n)):
            A, C, _, _ = body_matrices(vehicle, v, kf, kr)
            Acl = Si @ (np.eye(2) + dt * A) @ S - L @ Ni @ C @ S
            worst = max(worst, float(np.sqrt(max(sla.eigh(Acl.T @ P @ Acl, P, eigvals_only=True).max(), 0.0))))
            count += 1
    return {
        "points": count,
        "max_contraction": worst,
        "certified_contraction": rho_cert,
        "ok": bool(worst <= rho_cert * (1 + 1e-9)),
    }


def _nominal_decay(vehicle, dt, edges, Ls_si) -> float:
    """Slowest closed-loop decay at the nominal slopes over the speed range (spectral radius)."""
    worst = 0.0
    k_f, k_r = 2.0 * vehicle.Cf, 2.0 * vehicle.Cr
    for (va, vb), L in zip(zip(edges[:-1], edges[1:]), Ls_si):
        for v in np.linspace(va, vb, 5):
            A, C, _, _ = body_matrices(vehicle, v, k_f, k_r)
            worst = max(worst, float(np.abs(np.linalg.eigvals(np.eye(2) + dt * A - L @ C)).max()))
    return float(-math.log(worst) / dt) if 0 < worst < 1 else 0.0


def _cache_key(payload: dict) -> str:
    text = json.dumps(payload, sort_keys=True, default=lambda o: np.asarray(o).round(12).tolist())
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def _solve(cells, B, Dn, rho, solver, margin):
    import cvxpy as cp

    P = cp.Variable((2, 2), symmetric=True)
    Ys = [cp.Variable((2, 2)) for _ in cells]
    Zs = [cp.Variable((4, 4), symmetric=True) for _ in cells]
    t = cp.Variable()
    per_vertex, per_cell = _lmis(P, Ys, Zs, cells, B, Dn, rho)
    cons = [P >> margin * np.eye(2)]
    for rows, Mc, Z in zip(per_vertex, per_cell, Zs):
        cons += [0.5 * (M + M.T) >> margin * np.eye(M.shape[0]) for M in rows]
        cons += [0.5 * (Mc + Mc.T) >> margin * np.eye(Mc.shape[0]), cp.trace(Z) <= t]
    prob = cp.Problem(cp.Minimize(t), cons)
    try:
        prob.solve(solver=solver)
    except cp.error.SolverError:
        return "solver_error", None, None, None
    if P.value is None or any(Y.value is None for Y in Ys):
        return prob.status, None, None, None
    return prob.status, P.value, [Y.value for Y in Ys], [np.asarray(Z.value) for Z in Zs]


def _diagnose(cells, B, Dn, rho, solver, edges) -> str:
    """Smallest slack ``s`` with ``LMI + s I >= 0`` everywhere, and the binding vertices."""
    import cvxpy as cp

    P = cp.Variable((2, 2), symmetric=True)
    Ys = [cp.Variable((2, 2)) for _ in cells]
    Zs = [cp.Variable((4, 4), symmetric=True) for _ in cells]
    slack = cp.Variable()
    per_vertex, per_cell = _lmis(P, Ys, Zs, cells, B, Dn, rho)
    cons = [P >> np.eye(2), cp.trace(P) <= 1e6]
    vertex_cons = []
    for rows, Mc, Z in zip(per_vertex, per_cell, Zs):
        for M in rows:
            c = 0.5 * (M + M.T) + slack * np.eye(M.shape[0]) >> 0
            vertex_cons.append(c)
        cons += [0.5 * (Mc + Mc.T) + slack * np.eye(Mc.shape[0]) >> 0, cp.trace(Z) <= 1e8]
    prob = cp.Problem(cp.Minimize(slack), cons + vertex_cons)
    for name in dict.fromkeys((solver, "SCS")):
        try:
            prob.solve(solver=name)
        except cp.error.SolverError:
            continue
        if slack.value is not None:
            break
    if slack.value is None:
        return f"the diagnostic solve failed too (status {prob.status})"
    parts = []
    k = 0
    for c, verts in enumerate(cells):
        for _, _, _, (kf, kr, s, v) in verts:
            dual = vertex_cons[k].dual_value
            k += 1
            if dual is not None and float(np.trace(dual)) > 1e-3:
                parts.append(f"cell {c} [{edges[c]:.1f}, {edges[c + 1]:.1f}] m/s vertex k_f={kf:.4g}, k_r={kr:.4g} N/rad, 1/vx={s:.4g}, vx={v:.4g}")
    return (
        f"the LMIs can at best hold as LMI >= -{float(slack.value):.3g} I (they need >= 0); binding: "
        + ("; ".join(parts[:6]) or "none identified")
        + (f" (+{len(parts) - 6} more)" if len(parts) > 6 else "")
    )


def synthesize_imu_gains(
    vehicle: VehicleParams,
    dt: float = 0.01,
    speed_range: tuple[float, float] = (15.0, 65.0),
    n_cells: int = 10,
    slope_fractions: tuple[float, float] = (0.1, 1.5),
    max_steer: float = 0.3,
    decay_rate: float = 0.1,
    noise_std: tuple[float, float] = (1.0, 0.005),
    force_error_scale: float = 500.0,
    state_weight: float = 1.0,
    solver: str = "CLARABEL",
    tol: float = 1e-7,
    margin: float = 1e-7,
    cache: bool | str | Path = True,
) -> ImuGains:
    """Solve the speed-polytope vertex LMIs of the module docstring and certify the result.

    Parameters
    ----------
    vehicle : VehicleParams
        Nominal vehicle (``m, Iz, lf, lr, Cf, Cr``).
    dt : float
        Observer step [s] (the log's sample period).
    speed_range : (float, float)
        Speeds [m/s] the certificate must cover.
    n_cells : int
        Number of gain cells (geometric in speed).
    slope_fractions : (float, float)
        True axle slope between true and estimated slip, as a fraction of the nominal
        ``2 C``: ``(0.1, 1.5)`` = from 10 % of nominal (near the friction peak) to 150 %.
    max_steer : float
        Largest road-wheel angle [rad] covered (the ``cos(delta)`` of the front force).
    decay_rate : float
        Required decay rate of the state error at the worst vertex [1/s].
    noise_std : (float, float)
        IMU noise std ``(a_y [m/s^2], r [rad/s])`` the gains filter.
    force_error_scale : float
        Force approximation error the gains reject [N].
    state_weight : float
        Weight of the scaled states beside the sideslip error (mrad) in the H2 cost.
    solver : {"CLARABEL", "SCS"}
    tol : float
        Certificate tolerance (relative largest eigenvalue of ``-LMI``).
    margin : float
        Strictness imposed in the solve.
    cache : bool or path
        Disk cache (default directory of :func:`..observer.gains.default_cache_dir`).

    Raises
    ------
    InfeasibleLMIError
        No gain schedule satisfies the LMIs, or the solution fails the numpy certificate.
    """
    if not dt > 0:
        raise ParameterError(f"dt must be > 0, got {dt!r}")
    if not decay_rate >= 0:
        raise ParameterError(f"decay_rate must be >= 0, got {decay_rate!r}")
    noise = np.asarray(noise_std, dtype=float)
    if noise.shape != (2,) or np.any(~(noise > 0)):
        raise ParameterError(f"noise_std must be two positive values (a_y [m/s^2], r [rad/s]), got {noise_std!r}")
    if not force_error_scale > 0:
        raise ParameterError(f"force_error_scale must be > 0, got {force_error_scale!r}")
    edges = speed_edges(speed_range, n_cells)
    box = slope_box(vehicle, slope_fractions, max_steer)
    rho = float(np.exp(-decay_rate * dt))
    cells = _vertex_data(vehicle, dt, box, edges, noise, state_weight)
    B, Dn = _input_data(vehicle, dt, noise, force_error_scale)
    settings = {
        "version": _VERSION,
        "vehicle": vehicle.to_dict(),
        "dt": dt,
        "edges": edges.tolist(),
        "slope_fractions": list(slope_fractions),
        "max_steer": max_steer,
        "slope_box": box.tolist(),
        "decay_rate": decay_rate,
        "noise_std": noise.tolist(),
        "force_error_scale": force_error_scale,
        "state_weight": state_weight,
        "solver": solver,
        "margin": margin,
        "state_scale": STATE_SCALE.tolist(),
    }
    cache_file = None
    if cache:
        root = default_cache_dir() if cache is True else Path(cache)
        cache_file = root / f"imu_{_cache_key(settings)}.json"
        if cache_file.exists():
            try:
                data = json.loads(cache_file.read_text())
                P, Ls, Zs = np.array(data["P"]), [np.array(L) for L in data["Ls"]], [np.array(Z) for Z in data["Zs"]]
                t = float(data["t"])
            except (ValueError, KeyError, TypeError):
                P = None
            if P is not None:
                res = certify_schedule(P, Ls, Zs, cells, B, Dn, rho, dt, tol)
                if res[0]:
                    return _gains(vehicle, dt, box, edges, P, Ls, t, res, noise, 0.0, tol, True, settings)
    t0 = time.perf_counter()
    status, P, Ys, Zs = _solve(cells, B, Dn, rho, solver, margin)
    solve_s = time.perf_counter() - t0
    if P is None or status not in ("optimal", "optimal_inaccurate"):
        why = _diagnose(cells, B, Dn, rho, solver, edges)
        raise InfeasibleLMIError(f"IMU gain LMIs infeasible (solver status {status!r}): {why}")
    P = 0.5 * (P + P.T)
    Ls = [np.linalg.solve(P, Y) for Y in Ys]
    Zs = [Z * (1.0 + 1e-6) + 1e-9 * np.eye(Z.shape[0]) for Z in Zs]  # certify with a hair of slack
    t = float(max(np.trace(Z) for Z in Zs))
    res = certify_schedule(P, Ls, Zs, cells, B, Dn, rho, dt, tol)
    if not res[0]:
        eig = res[4]
        c, v = np.unravel_index(int(np.argmax(eig)), eig.shape)
        kf, kr, s, vx = cells[c][v][3]
        raise InfeasibleLMIError(
            f"solver status {status!r} but the numpy certificate fails: cell {c} vertex k_f={kf:.4g}, "
            f"k_r={kr:.4g} N/rad, 1/vx={s:.4g}, vx={vx:.4g}: largest eigenvalue of -LMI {eig[c, v]:.3g} > tol {tol:g}"
        )
    if cache_file is not None:
        from ..io import atomic_write_json

        atomic_write_json(cache_file, {"P": P, "Ls": Ls, "Zs": Zs, "t": t, "settings": settings})
    return _gains(vehicle, dt, box, edges, P, Ls, t, res, noise, solve_s, tol, False, settings)


def _gains(vehicle, dt, box, edges, P, Ls, t, res, noise, solve_s, tol, hit, settings) -> ImuGains:
    ok, worst, decay, cell_decay, _ = res
    S = np.diag(STATE_SCALE)
    L_si = np.array([S @ L @ np.diag(1.0 / noise) for L in Ls])
    rho_cert = float(np.exp(-decay * dt))
    dense = _dense_check(vehicle, dt, box, edges, P, Ls, noise, rho_cert)
    return ImuGains(
        L=L_si,
        edges=edges,
        P=P,
        dt=dt,
        slope_box=box,
        decay_rate=decay,
        cell_decay_rate=cell_decay,
        nominal_decay_rate=_nominal_decay(vehicle, dt, edges, L_si),
        cost=float(np.sqrt(t)),
        max_vertex_eig=worst,
        certified=ok and dense["ok"],
        tolerance=tol,
        solve_s=solve_s,
        cache_hit=hit,
        dense_check=dense,
        settings=settings,
    )
