r"""Certified correction gains from vertex LMIs (cvxpy), re-checked with numpy: one pipeline
for every measurement model.

Why not the paper's Theorem 1
-----------------------------
SPEC §3 proves that LMI (24) holds at no decay rate ``alpha >= 0``: the tire force enters
two integrators away from the camera outputs (``C F = 0``) and at any frozen activation
vector only 2 of the ``2N`` weight directions reach the state, so no quadratic Lyapunov
function decreases along the weight error with a constant adaptation gain ``K``. We
certify a different, provable property and learn the weights with a sensitivity-based
recursive least-squares law (:mod:`._kernel`), whose gain is computed on line.

What is certified
-----------------
A *group* of measurement channels (camera ``[e1, e2]`` or IMU ``[a_y, r]``) corrects the state
every ``T`` seconds with a gain ``L_c`` chosen by the speed cell ``c``. Freeze, over one
period, the speed ``vx`` and the total axle slopes ``k_i`` between the true and the estimated
slip (the linear part ``2 C_i`` plus the slope of the learned part, in the box the basis'
weight bounds allow: the paper's H1/H2 and ``W_max`` construction). Then the posterior
state error obeys

    e_{k+1} = (I - L C)(A e_k + B d_k + W u_k) - L D d'_{k+1} - L v_{k+1}

with ``A = exp(A_c T)`` and ``B`` the exact zero-order-hold maps of the linearised model
(:func:`.model.linear_matrices`), ``d``, ``d'`` axle force errors of the model (weight error
and basis residual) [N], ``v`` the measurement noise, ``C``, ``D`` the group's output
matrices (``D`` is the ``a_y`` feedthrough of the force), and ``W u`` the noise that other
sensors inject while the state is predicted (fused estimation: the IMU corrections made
between two camera frames with the already certified IMU gain). With ``Y_c = P L_c``, the
robust-H2 LMIs (scaled states and inputs; one common ``P``)

    [[rho^2 P - Hs^T Hs,   (P A - Y C A)^T],           [[Z_c,   (P Bw)^T],
     [P A - Y C A,          P             ]] >= 0,       [P Bw,   P      ]] >= 0,
    P Bw = [P B - Y C B,  P W - Y C W,  -Y D,  -Y],    trace Z_c <= t,    minimise t

are imposed at the vertices of every cell: the four corners of the slope box at the lower,
middle and upper speed of the cell. ``A`` and ``C`` depend on the slopes and the speed
through ``exp`` and ``1/vx``, so the vertices do not bound the interior exactly: every
solution is therefore re-checked with numpy at the vertices (positive ``P``, largest
eigenvalue of ``-LMI`` at most ``tol``) *and* on a dense grid of slopes and speeds in every
cell (contraction of ``e^T P e``). When both hold,

1. with exact weights and no noise the state error decays at least at the certified rate
   (``-ln(rho)/T``, ``rho`` the worst contraction over vertices and grid), for any speed
   trajectory in the range (common ``P``: arbitrary switching between cells);
2. the state error is input-to-state stable with respect to the force error and the noise,
   and for white unit-variance normalised inputs its weighted mean square (slip errors in
   mrad and the scaled states) is at most ``t`` at the vertices.

Not certified: the convergence of the weights (it needs persistent excitation; the
studies and the benchmark show it), a period other than ``T`` (dropped frames make the
prediction longer; the health flag watches that), slopes and speeds outside the box, and
the interleaving of groups beyond what the fused design contains.

Fused estimation designs the IMU group first (2 body states), then the camera group on
all 4 states with the IMU corrections inside the prediction over a frame. Results are
cached on disk keyed by every input; a cache hit is re-certified, never trusted; a
corrupt cache file is ignored and rewritten.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray

from ..params import ParameterError, VehicleParams, _Params
from .certificate import GroupCertificate, ObserverGains
from .model import MeasurementModel, linear_matrices, measurement_model, slip_jacobian

__all__ = [
    "InfeasibleLMIError",
    "GainDesign",
    "ObserverGains",
    "GroupCertificate",
    "synthesize_gains",
    "speed_cells",
    "default_cache_dir",
    "STATE_SCALE",
]

_VERSION = 5  # bump when the formulation changes (invalidates the cache)
#: scaling of ``[vy [m/s], r [rad/s], e1 [m], e2 [rad]]`` inside the solve
STATE_SCALE = np.array([0.05, 0.01, 0.05, 0.005])
SLIP_SCALE = 1e-3  # [rad]: slip-error unit of the performance output (mrad)
#: interior margins of the LMI solve, tried in turn until the numpy certificate holds
_SOLVE_MARGINS = (1e-7, 1e-5, 1e-4)


class InfeasibleLMIError(RuntimeError):
    """The gain LMIs have no solution (or the solver's answer fails the numpy certificate)."""


def default_cache_dir() -> Path:
    """``$TIRE_LEARNING_CACHE`` or ``~/.cache/tire_learning_env``, sub-folder ``gains``."""
    return Path(os.environ.get("TIRE_LEARNING_CACHE", Path.home() / ".cache" / "tire_learning_env")) / "gains"


@dataclass(frozen=True)
class GainDesign(_Params):
    """Design settings of the certified gains (physical defaults, not fitted to any log).

    Parameters
    ----------
    camera_decay_rate, imu_decay_rate : float
        Required certified decay rate of the state error [1/s] with camera / IMU corrections.
    camera_force_error, imu_force_error : float
        Force error the gains reject, as a fraction of the mean static axle load [-]
        (a lane camera sees gentle driving: 1.3 %; an IMU design also covers hard driving
        near the limit: 10 %).
    state_weight : float
        Weight of the scaled states beside the slip errors (mrad) in the H2 cost.
    cell_ratio : float
        Speed cells are geometric with this ratio of upper to lower edge.
    speed_margin : float
        The certified speed range is the log's widened by this fraction on both sides.
    max_steer : float
        Largest road-wheel angle covered [rad] (the front force acts through ``cos(delta)``).
    solver : {"CLARABEL", "SCS"}
    tol : float
        Certificate tolerance (relative largest eigenvalue of ``-LMI``).
    """

    camera_decay_rate: float = 0.5
    imu_decay_rate: float = 0.1
    camera_force_error: float = 0.013
    imu_force_error: float = 0.1
    state_weight: float = 1.0
    cell_ratio: float = 1.3
    speed_margin: float = 0.1
    max_steer: float = 0.3
    solver: str = "CLARABEL"
    tol: float = 1e-7

    _positive: ClassVar[tuple[str, ...]] = ("camera_force_error", "imu_force_error", "tol")
    _non_negative: ClassVar[tuple[str, ...]] = ("camera_decay_rate", "imu_decay_rate", "state_weight", "speed_margin", "max_steer")

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.cell_ratio > 1.0:
            raise ParameterError(f"GainDesign.cell_ratio must be > 1, got {self.cell_ratio!r}")
        if self.solver not in ("CLARABEL", "SCS"):
            raise ParameterError(f"GainDesign.solver must be 'CLARABEL' or 'SCS', got {self.solver!r}")


def speed_cells(speed_range: tuple[float, float], ratio: float) -> NDArray:
    """Geometric cell edges over ``speed_range`` [m/s] with at most ``ratio`` per cell."""
    lo, hi = (float(v) for v in speed_range)
    if not (0 < lo < hi):
        raise ParameterError(f"speed range must be 0 < lo < hi [m/s], got {speed_range!r}")
    n = max(1, int(math.ceil(math.log(hi / lo) / math.log(ratio) - 1e-9)))
    return np.geomspace(lo, hi, n + 1)


# -- vertex data ------------------------------------------------------------------------------
def _zoh(A: NDArray, F: NDArray, T: float) -> tuple[NDArray, NDArray]:
    n, m = F.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A
    M[:n, n:] = F
    E = sla.expm(M * T)
    return E[:n, :n], E[:n, n:]


@dataclass
class _Vertex:
    A: NDArray  # prediction over the period
    B: NDArray  # force-error input held over the period (SI, N)
    W: NDArray  # other sensors' noise injected during the prediction (columns: unit white inputs)
    C: NDArray  # group output
    D: NDArray  # force-error feedthrough of the group output
    Hs: NDArray  # performance output (scaled)
    theta: tuple


def _imu_step(vehicle, model_nx, k_f, k_r, v, h):
    """One IMU-period prediction and output at frozen slopes (nx rows)."""
    A, F = linear_matrices(vehicle, v, k_f, k_r, model_nx)
    Ad, Fd = _zoh(A, F, h)
    C, D = measurement_model("both" if model_nx == 4 else "imu").imu_output(vehicle, v, k_f, k_r)
    return Ad, Fd, C, D


def _vertices(vehicle, model: MeasurementModel, group: str, T: float, imu_T: float | None, v: float,
              box: NDArray, noise: NDArray, L_imu_cell: NDArray | None, state_weight: float) -> list[_Vertex]:  # fmt: skip
    """The vertex maps of a group design at speed ``v``: four slope corners."""
    nx = 2 if group == "imu" else model.nx  # the IMU group acts on the body states only
    S = STATE_SCALE[:nx]
    Hslip = slip_jacobian(vehicle, v, nx)
    Hs = np.vstack([Hslip * S / SLIP_SCALE, state_weight * np.eye(nx)])
    out = []
    for k_f, k_r in itertools.product(box[0], box[1]):
        A, F = linear_matrices(vehicle, v, k_f, k_r, nx)
        W = np.zeros((nx, 0))
        if group == "imu":
            Ad, Bd = _zoh(A, F, T)
            C, D = measurement_model("imu").imu_output(vehicle, v, k_f, k_r)
        elif model.uses_imu:  # fused: camera frames, IMU corrections in between
            m_steps = max(1, int(round(T / imu_T)))
            h = T / m_steps
            Ah, Fh, Ci, Di = _imu_step(vehicle, nx, k_f, k_r, v, h)
            Li = np.zeros((nx, 2))
            Li[:2] = L_imu_cell
            Ad = np.eye(nx)
            Bd = np.zeros((nx, 2))
            cov = np.zeros((nx, nx))
            for _ in range(m_steps):
                M = np.eye(nx) - Li @ Ci
                Ad = M @ Ah @ Ad
                Bd = M @ (Ah @ Bd + Fh) - Li @ Di
                cov = M @ Ah @ cov @ Ah.T @ M.T + Li @ np.diag(noise[2:] ** 2) @ Li.T
            lam, vec = np.linalg.eigh(0.5 * (cov + cov.T))
            W = vec * np.sqrt(np.maximum(lam, 0.0))  # W W^T = cov
            C = model.camera_output(vehicle.camera_x)
            D = np.zeros((2, 2))
        else:
            Ad, Bd = _zoh(A, F, T)
            C = model.camera_output(vehicle.camera_x)
            D = np.zeros((2, 2))
        out.append(_Vertex(Ad, Bd, W, C, D, Hs, (k_f, k_r, v)))
    return out


def _scaled(vx: _Vertex, S, noise_group, fes):
    Si = np.diag(1.0 / S)
    Sm = np.diag(S)
    Ni = np.diag(1.0 / noise_group)
    A = Si @ vx.A @ Sm
    B = Si @ vx.B * fes
    W = Si @ vx.W
    C = Ni @ vx.C @ Sm
    D = Ni @ vx.D * fes
    return A, B, W, C, D, vx.Hs


def _lmis(P, Ys, Zs, cells, rho):
    """``(per_vertex[c][v] pairs)``: the two matrices per vertex that must be >= 0 (numpy or cvxpy)."""
    numeric = isinstance(P, np.ndarray)
    if numeric:
        bmat, hstack = np.block, np.hstack
    else:
        import cvxpy as cp

        bmat, hstack = cp.bmat, cp.hstack
    out = []
    for verts, Y, Z in zip(cells, Ys, Zs):
        rows = []
        for A, B, W, C, D, Hs in verts:
            PA = P @ A - Y @ C @ A
            parts = [P @ B - Y @ C @ B]
            if W.shape[1]:
                parts.append(P @ W - Y @ C @ W)
            if np.any(D):
                parts.append(-(Y @ D))
            parts.append(-Y)
            PBw = hstack(parts)
            M1 = bmat([[rho**2 * P - Hs.T @ Hs, PA.T], [PA, P]])
            M2 = bmat([[Z, PBw.T], [PBw, P]])
            rows.append((M1, M2))
        out.append(rows)
    return out


def _n_inputs(verts) -> int:
    A, B, W, C, D, Hs = verts[0]
    return B.shape[1] + W.shape[1] + (D.shape[1] if np.any(D) else 0) + C.shape[0]


def _worst(M: NDArray) -> float:
    M = 0.5 * (M + M.T)
    return float(np.linalg.eigvalsh(-M).max() / max(1.0, np.abs(M).max()))


def _contraction(A, C, Ls, P) -> float:
    Acl = A - Ls @ C @ A
    return float(np.sqrt(max(sla.eigh(Acl.T @ P @ Acl, P, eigvals_only=True).max(), 0.0)))


def _certify(P, Ls, Zs, cells, rho, tol):
    """Numpy check at the vertices: ``(ok, max_vertex_eig, worst_contraction, per_vertex_eig)``."""
    P = 0.5 * (P + P.T)
    Ys = [P @ L for L in Ls]
    mats = _lmis(P, Ys, Zs, cells, rho)
    eig = np.array([[max(_worst(M1), _worst(M2)) for M1, M2 in rows] for rows in mats])
    worst_rho = max(_contraction(A, C, L, P) for verts, L in zip(cells, Ls) for A, B, W, C, D, Hs in verts)
    ok = bool(np.linalg.eigvalsh(P).min() > 0 and eig.max() <= tol and worst_rho < 1.0)
    return ok, float(eig.max()), worst_rho, eig


def _solve(cells, rho, solver, margin, nx):
    import cvxpy as cp

    P = cp.Variable((nx, nx), symmetric=True)
    Ys = [cp.Variable((nx, 2)) for _ in cells]
    Zs = [cp.Variable((_n_inputs(v), _n_inputs(v)), symmetric=True) for v in cells]
    t = cp.Variable()
    mats = _lmis(P, Ys, Zs, cells, rho)
    cons = [P >> margin * np.eye(nx)]
    for rows, Z in zip(mats, Zs):
        for M1, M2 in rows:
            cons += [0.5 * (M1 + M1.T) >> margin * np.eye(M1.shape[0]), 0.5 * (M2 + M2.T) >> margin * np.eye(M2.shape[0])]
        cons.append(cp.trace(Z) <= t)
    prob = cp.Problem(cp.Minimize(t), cons)
    try:
        prob.solve(solver=solver)
    except cp.error.SolverError:
        return "solver_error", None, None, None
    if P.value is None or any(Y.value is None for Y in Ys):
        return prob.status, None, None, None
    return prob.status, P.value, [Y.value for Y in Ys], [np.asarray(Z.value) for Z in Zs]


def _diagnose(cells, thetas, rho, solver, nx, edges) -> str:
    """Smallest slack ``s`` with ``LMI + s I >= 0`` everywhere, and the binding vertices."""
    import cvxpy as cp

    P = cp.Variable((nx, nx), symmetric=True)
    Ys = [cp.Variable((nx, 2)) for _ in cells]
    Zs = [cp.Variable((_n_inputs(v), _n_inputs(v)), symmetric=True) for v in cells]
    slack = cp.Variable()
    mats = _lmis(P, Ys, Zs, cells, rho)
    cons = [P >> np.eye(nx), cp.trace(P) <= 1e6]
    vcons = []
    for rows, Z in zip(mats, Zs):
        for M1, M2 in rows:
            vcons.append(0.5 * (M1 + M1.T) + slack * np.eye(M1.shape[0]) >> 0)
            cons.append(0.5 * (M2 + M2.T) + slack * np.eye(M2.shape[0]) >> 0)
        cons.append(cp.trace(Z) <= 1e8)
    prob = cp.Problem(cp.Minimize(slack), cons + vcons)
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
    flat = [th for ths in thetas for th in ths]
    for c, th in zip(vcons, flat):
        dual = c.dual_value
        if dual is not None and float(np.trace(dual)) > 1e-3:
            parts.append(f"k_f={th[0]:.4g}, k_r={th[1]:.4g} N/rad at vx={th[2]:.3g} m/s")
    return (
        f"speed cells {np.round(edges, 2).tolist()} m/s: the LMIs can at best hold as LMI >= -{float(slack.value):.3g} I "
        "(they need >= 0); binding: " + ("; ".join(parts[:6]) or "none identified")
        + (f" (+{len(parts) - 6} more)" if len(parts) > 6 else "")
    )


def _dense_contraction(vehicle, model, group, T, imu_T, edges, box, noise, L_imu_si, Ls_scaled, P, state_weight, n=4):
    """Worst contraction of ``e^T P e`` on a dense grid of slopes and speeds (exact frozen maps)."""
    worst, count = 0.0, 0
    nxg = 2 if group == "imu" else model.nx
    S = STATE_SCALE[:nxg]
    noise_g = noise[:2] if group == "camera" else noise[2:]
    for c, (va, vb) in enumerate(zip(edges[:-1], edges[1:])):
        for v in np.geomspace(va, vb, n):
            for kf in np.linspace(*box[0], n):
                for kr in np.linspace(*box[1], n):
                    sub = np.array([[kf], [kr]])  # one corner (a box [kf, kf] x [kr, kr] made the same map four times)
                    vx = _vertices(vehicle, model, group, T, imu_T, v, sub, noise,
                                   None if L_imu_si is None else L_imu_si[c], state_weight)[0]  # fmt: skip
                    A, B, W, C, D, Hs = _scaled(vx, S, noise_g, 1.0)
                    worst = max(worst, _contraction(A, C, Ls_scaled[c], P))
                    count += 1
    return worst, count


def _design_group(vehicle, model, group, T, imu_T, edges, box, noise, fes, decay, design, L_imu_si, cache_root, settings):
    """Solve, certify (vertices + dense grid) and return ``(L_si (n_cells, nx_g, 2), certificate, hit)``."""
    nxg = 2 if group == "imu" else model.nx
    S = STATE_SCALE[:nxg]
    noise_g = noise[:2] if group == "camera" else noise[2:]
    rho = float(math.exp(-decay * T))
    cells, thetas = [], []
    for c, (va, vb) in enumerate(zip(edges[:-1], edges[1:])):
        verts, ths = [], []
        for v in (va, math.sqrt(va * vb), vb):
            for vx in _vertices(vehicle, model, group, T, imu_T, v, box, noise,
                                None if L_imu_si is None else L_imu_si[c], design.state_weight):  # fmt: skip
                verts.append(_scaled(vx, S, noise_g, fes))
                ths.append(vx.theta)
        cells.append(verts)
        thetas.append(ths)
    key = dict(settings, group=group, version=_VERSION)
    cache_file = None
    hit = False
    P = Ls = Zs = None
    solve_s = 0.0
    if cache_root is not None:
        text = json.dumps(key, sort_keys=True, default=lambda o: np.asarray(o).round(12).tolist())
        cache_file = Path(cache_root) / f"gains_{hashlib.sha256(text.encode()).hexdigest()[:24]}.json"
        if cache_file.exists():
            try:
                data = json.loads(cache_file.read_text())
                P = np.array(data["P"], dtype=float)
                Ls = [np.array(L, dtype=float) for L in data["Ls"]]
                Zs = [np.array(Z, dtype=float) for Z in data["Zs"]]
                if P.shape != (nxg, nxg) or len(Ls) != len(cells):
                    raise ValueError("shape mismatch")
                hit = _certify(P, Ls, Zs, cells, rho, design.tol)[0]
            except (OSError, ValueError, KeyError, TypeError):
                hit = False  # a corrupt or stale cache file: solve again and overwrite it
    if not hit:
        t0 = time.perf_counter()
        # an "optimal_inaccurate" answer can miss the numpy certificate by a hair near a
        # (barely) unobservable vertex (e.g. IMU-only, both axles near saturation, 200 Hz):
        # solve again with more interior slack before giving up
        for attempt, margin in enumerate(_SOLVE_MARGINS):
            status, P1, Ys, Z1 = _solve(cells, rho, design.solver, margin, nxg)
            if P1 is None or status not in ("optimal", "optimal_inaccurate"):
                if attempt == 0:
                    why = _diagnose(cells, thetas, rho, design.solver, nxg, edges)
                    raise InfeasibleLMIError(f"{group} gain LMIs infeasible (solver status {status!r}) for decay "
                                             f"{decay} 1/s over periods of {T:.4g} s: {why}")  # fmt: skip
                break  # more slack is infeasible: keep the previous answer (it fails below, named)
            P = 0.5 * (P1 + P1.T)
            Ls = [np.linalg.solve(P, Y) for Y in Ys]
            Zs = [Z * (1.0 + 1e-6) + 1e-9 * np.eye(Z.shape[0]) for Z in Z1]
            if _certify(P, Ls, Zs, cells, rho, design.tol)[0]:
                break
        solve_s = time.perf_counter() - t0
    ok, worst_eig, worst_rho, eig = _certify(P, Ls, Zs, cells, rho, design.tol)
    if not ok:
        c, v = np.unravel_index(int(np.argmax(eig)), eig.shape)
        th = thetas[c][v]
        raise InfeasibleLMIError(
            f"{group} gains: the numpy certificate fails at k_f={th[0]:.4g}, k_r={th[1]:.4g} N/rad, vx={th[2]:.3g} "
            f"m/s: largest eigenvalue of -LMI {eig[c, v]:.3g} > tol {design.tol:g} (worst contraction {worst_rho:.6f})"
        )
    if cache_file is not None and not hit:
        from ..io import atomic_write_json

        atomic_write_json(cache_file, {"P": P, "Ls": Ls, "Zs": Zs, "settings": key})
    dense_rho, points = _dense_contraction(vehicle, model, group, T, imu_T, edges, box, noise, L_imu_si, Ls, P,
                                           design.state_weight)  # fmt: skip
    rho_all = max(worst_rho, dense_rho)
    cert = GroupCertificate(
        group=group, period=T, P=P, decay_rate=float(-math.log(rho_all) / T) if rho_all < 1 else 0.0,
        vertex_decay_rate=float(-math.log(worst_rho) / T), cost=float(np.sqrt(max(np.trace(Z) for Z in Zs))),
        max_vertex_eig=worst_eig, dense_points=points, dense_contraction=dense_rho, certified=bool(ok and dense_rho < 1.0),
        n_vertices=sum(len(v) for v in cells), solve_s=solve_s,
    )  # fmt: skip
    L_si = np.array([np.diag(S) @ L @ np.diag(1.0 / noise_g) for L in Ls])
    return L_si, cert, hit


def synthesize_gains(
    vehicle: VehicleParams,
    model: str | MeasurementModel,
    frame_period: float,
    noise_std: NDArray,
    speed_range: tuple[float, float],
    slope_box: NDArray,
    design: GainDesign | None = None,
    imu_period: float | None = None,
    cache: bool | str | Path = True,
) -> ObserverGains:
    """Solve and certify the gains of every channel group of ``model``.

    Parameters
    ----------
    vehicle : VehicleParams
        Nominal vehicle (``m, Iz, lf, lr``; ``Cf``, ``Cr`` only through ``slope_box``).
    model : {"camera", "imu", "both"} or MeasurementModel
    frame_period : float
        Camera frame period [s] (camera, both) or IMU sample period [s] (imu).
    noise_std : array (4,)
        Noise std of ``e1`` [m], ``e2`` [rad], ``a_y`` [m/s^2], ``r`` [rad/s] the gains filter
        (floored by the caller).
    speed_range : (float, float)
        Speeds [m/s] to certify (widened by ``design.speed_margin``).
    slope_box : array (2, 2)
        Total axle slopes ``[[k_f_lo, k_f_hi], [k_r_lo, k_r_hi]]`` [N/rad] the learned curves can
        take (the front lower bound is multiplied by ``cos(max_steer)`` here).
    design : GainDesign, optional
    imu_period : float, optional
        IMU sample period [s] (fused estimation).
    cache : bool or path
        Disk cache (default :func:`default_cache_dir`); ``False`` disables it.

    Raises
    ------
    InfeasibleLMIError
        No gains satisfy the LMIs, or a solution fails the numpy certificate (the message
        names the binding vertices).
    """
    model = measurement_model(model)
    design = design or GainDesign()
    if not frame_period > 0:
        raise ParameterError(f"frame_period must be > 0 s, got {frame_period!r}")
    noise = np.asarray(noise_std, dtype=float).reshape(4)
    if not np.all(noise > 0):
        raise ParameterError(f"noise_std must be 4 positive values (e1, e2, a_y, r), got {noise_std!r}")
    box = np.array(slope_box, dtype=float).reshape(2, 2)
    if np.any(box[:, 0] <= 0) or np.any(box[:, 0] >= box[:, 1]):
        raise ParameterError(f"slope_box must hold 0 < lo < hi per axle [N/rad], got {box.tolist()}")
    box[0, 0] *= math.cos(design.max_steer)
    lo, hi = (float(v) for v in speed_range)
    lo = max(lo * (1.0 - design.speed_margin), 3.0)
    hi = max(hi * (1.0 + design.speed_margin), lo * 1.05)
    edges = speed_cells((lo, hi), design.cell_ratio)
    axle_load = 0.5 * vehicle.m * 9.81
    settings = {
        "vehicle": [vehicle.m, vehicle.Iz, vehicle.lf, vehicle.lr],
        "model": model.name,
        "frame_period": frame_period,
        "imu_period": imu_period,
        "noise_std": noise.tolist(),
        "edges": edges.tolist(),
        "slope_box": box.tolist(),
        "design": design.to_dict(),
    }
    if vehicle.camera_x:  # a camera ahead of the CG changes C (a key only then: the caches of every other design stay)
        settings["camera_x"] = float(vehicle.camera_x)
    cache_root = None
    if cache:
        cache_root = default_cache_dir() if cache is True else Path(cache)
    n_cells = len(edges) - 1
    nx = model.nx
    L_cam = np.zeros((n_cells, nx, 2))
    L_imu = np.zeros((n_cells, nx, 2))
    certs = []
    hits = []
    if model.uses_imu:
        T_imu = frame_period if not model.uses_camera else float(imu_period or frame_period)
        fes = design.imu_force_error * axle_load
        L2, cert, hit = _design_group(vehicle, model, "imu", T_imu, None, edges, box, noise, fes, design.imu_decay_rate,
                                      design, None, cache_root, dict(settings, force_error_N=fes))  # fmt: skip
        L_imu[:, :2, :] = L2
        certs.append(cert)
        hits.append(hit)
    if model.uses_camera:
        fes = design.camera_force_error * axle_load
        Lc, cert, hit = _design_group(vehicle, model, "camera", frame_period, imu_period, edges, box, noise, fes,
                                      design.camera_decay_rate, design, L_imu[:, :2, :] if model.uses_imu else None,
                                      cache_root, dict(settings, force_error_N=fes))  # fmt: skip
        L_cam[:] = Lc
        certs.append(cert)
        hits.append(hit)
    settings["force_error_N"] = {
        "camera": design.camera_force_error * axle_load if model.uses_camera else None,
        "imu": design.imu_force_error * axle_load if model.uses_imu else None,
    }
    return ObserverGains(model, edges, L_cam, L_imu, box, certs, all(hits), settings)
