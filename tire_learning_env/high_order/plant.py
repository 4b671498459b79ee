"""The high-order truth vehicle: CommonRoad's multi-body model behind the plant interface.

:class:`MultiBodyPlant` runs in :class:`~tire_learning_env.simulation.Simulator`'s tick
loop like :class:`~tire_learning_env.dynamics.BicyclePlant`: it has ``vehicle`` (the
*equivalent bicycle*, see :func:`equivalent_bicycle`), ``state`` (``[e1, e1_dot, e2,
e2_dot]`` relative to the road), ``reset(xi)``, ``step(...)`` and ``output()``.
Internally it integrates CommonRoad's 29-state multi-body model (compiled port, see
:mod:`._mb_kernels`) plus four tire-relaxation lags and a PI speed controller with RK4,
and derives the camera errors from the global pose relative to the road's geometry.

Ground truth it reports (SPEC §1 conventions, positive to the left):

- axle lateral force = sum of the axle's two tire forces in the *body* frame (front:
  ``(F_y,LF + F_y,RF) cos(delta) + (F_x,LF + F_x,RF) sin(delta)``);
- axle slip = eq. (13) with the body velocities of the reference point (sprung-mass CG):
  ``alpha_f = delta - (v_y + a r)/v_x``, ``alpha_r = (b r - v_y)/v_x``;
- true per-tire cornering stiffness = slope at zero slip of the model's own
  combined-slip lateral force at the static wheel load (:func:`true_cornering_stiffness`).
"""

from __future__ import annotations

import math
from dataclasses import fields
from typing import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..dynamics import PlantOutput
from ..params import ParameterError, VehicleParams
from ..roads import Road, make_road
from . import _mb_kernels as K
from . import _pac2002 as T
from .params import HighOrderConfig, MultiBodyParams, Pac2002Tire, bmw_320i

__all__ = [
    "MultiBodyPlant",
    "PathTable",
    "parameter_vector",
    "tire_vector",
    "static_wheel_loads",
    "static_state",
    "true_cornering_stiffness",
    "tire_lateral_force",
    "equivalent_bicycle",
    "register_closed_loop_references",
    "WHEELS",
]

WHEELS = ("lf", "rf", "lr", "rr")
_G = 9.81  # CommonRoad's gravity [m/s^2]

#: The closed-loop (quasi-steady) references behind ``reference="effective"``: they drive this
#: plant with the simulator's driver and camera, a layer above the plant, so :mod:`.simulate`
#: registers them on import (the package imports it) instead of the plant importing it.
_CLOSED_LOOP_REFERENCES: dict[str, Callable] = {}


def register_closed_loop_references(
    cornering_stiffness: Callable[[MultiBodyParams, HighOrderConfig], tuple[float, float]],
    axle_curves: Callable[..., dict],
) -> None:
    """Set the functions :class:`MultiBodyPlant` uses for ``reference="effective"``.

    Parameters
    ----------
    cornering_stiffness : callable
        ``(params, config) -> (C_f, C_r)`` [N/rad] (:func:`~.simulate.effective_cornering_stiffness`).
    axle_curves : callable
        ``(params, config, ay_max=, count=) -> dict`` of ``alpha_f, alpha_r`` [rad], ``Fyf, Fyr`` [N]
        (:func:`~.simulate.steady_state_axle_curves`).
    """
    _CLOSED_LOOP_REFERENCES.update(cornering_stiffness=cornering_stiffness, axle_curves=axle_curves)


def _closed_loop_reference(name: str) -> Callable:
    if name not in _CLOSED_LOOP_REFERENCES:
        raise RuntimeError(
            "the effective references need tire_learning_env.high_order.simulate; import tire_learning_env.high_order"
        )
    return _CLOSED_LOOP_REFERENCES[name]


def parameter_vector(params: MultiBodyParams, config: HighOrderConfig) -> NDArray:
    """The parameter set and plant options as the kernels' vector (``MB_*``/``OPT_*`` layout)."""
    p = params
    s, lo = p.steering, p.longitudinal
    vec = [
        p.m, p.m_s, p.m_uf, p.m_ur, p.a, p.b, p.I_Phi_s, p.I_y_s, p.I_z, p.I_xz_s,
        p.K_sf, p.K_sdf, p.K_sr, p.K_sdr, p.T_f, p.T_r, p.K_ras, p.K_tsf, p.K_tsr, p.K_rad, p.K_zt,
        p.h_raf, p.h_rar, p.h_s, p.I_uf, p.I_ur, p.I_y_w, p.K_lt, p.R_w, p.T_sb, p.T_se,
        p.D_f, p.D_r, p.E_f, p.E_r,
        s.min, s.max, s.v_min, s.v_max, lo.v_min, lo.v_max, lo.v_switch, lo.a_max,
        config.relaxation_length, config.steering_time_constant, config.speed_kp, config.speed_ki,
    ]  # fmt: skip
    assert len(vec) == K.N_PAR
    return np.array(vec, dtype=float)


def tire_vector(tire: Pac2002Tire, symmetric: bool = False) -> NDArray:
    """The tire coefficients as the kernels' vector (``TY_*`` layout).

    ``symmetric`` zeroes ``p_hy1`` and ``p_vy1`` (see :class:`~.params.HighOrderConfig`).
    """
    vec = np.array([float(getattr(tire, f.name)) for f in fields(tire)])
    assert len(vec) == T.N_TIRE
    if symmetric:
        vec[T.TY_PHY1] = 0.0
        vec[T.TY_PVY1] = 0.0
    return vec


def static_wheel_loads(params: MultiBodyParams) -> tuple[float, float]:
    """Static vertical load of one front and one rear tire [N] (CommonRoad's ``init_mb``)."""
    L = params.a + params.b
    front = params.m_s * _G * params.b / L + params.m_uf * _G
    rear = params.m_s * _G * params.a / L + params.m_ur * _G
    return 0.5 * front, 0.5 * rear


def static_state(params: MultiBodyParams, vx: float) -> NDArray:
    """Straight driving at ``vx`` [m/s] in static equilibrium (N_STATE,).

    Tire deflections as CommonRoad's ``init_mb``; in addition the sprung-mass heave and
    pitch that make every suspension deflection zero, so the suspension forces equal
    their static shares (``init_mb`` leaves them off by ``K_s`` times the tire deflection)
    and the camber is zero.
    """
    x = np.zeros(K.N_STATE)
    fz_f, fz_r = static_wheel_loads(params)
    x[K.S_Z_F] = fz_f / params.K_zt
    x[K.S_Z_R] = fz_r / params.K_zt
    x[K.S_PITCH] = (x[K.S_Z_R] - x[K.S_Z_F]) / (params.a + params.b)
    x[K.S_Z] = x[K.S_Z_F] + params.a * x[K.S_PITCH]
    x[K.S_VX] = vx
    x[K.S_OMEGA_LF : K.S_OMEGA_RR + 1] = vx / params.R_w
    return x


def tire_lateral_force(
    alpha: ArrayLike, fz: float, tire: Pac2002Tire, symmetric: bool = False, camber: float = 0.0, kappa: float = 0.0
) -> NDArray:
    """Lateral force of one tire [N] in the SPEC sign convention (positive slip -> positive force).

    The multi-body model's own combined-slip PAC2002 force at load ``fz`` [N], camber
    [rad] and longitudinal slip ``kappa`` [-], evaluated at CommonRoad slip ``-alpha``
    (CommonRoad's ``alpha = atan(v_y/v_x) - delta`` is the negative of eq. (13)'s).
    """
    ty = tire_vector(tire, symmetric)
    a = np.asarray(alpha, dtype=float)
    out = np.array([T.tire_lateral_force(-float(v), kappa, camber, fz, ty) for v in a.ravel()])
    return out.reshape(a.shape)


def true_cornering_stiffness(params: MultiBodyParams) -> tuple[float, float]:
    """True per-tire cornering stiffness front/rear [N/rad] at static load, zero camber and slip.

    The slope of the model's own lateral force at zero slip: with CommonRoad's PAC2002
    subset it is ``B C D = K_y = -p_ky1 F_z`` (the ``p_hy1``/``p_vy1`` shifts vanish at
    zero camber and the combined-slip factor is 1 at zero longitudinal slip).
    """
    fz_f, fz_r = static_wheel_loads(params)
    k = -params.tire.p_ky1
    return k * fz_f, k * fz_r


def equivalent_bicycle(params: MultiBodyParams, vx: float = 30.0) -> VehicleParams:
    """The bicycle model (SPEC §1) equivalent to the multi-body vehicle.

    ``m`` = total mass, ``Iz`` = CommonRoad's yaw inertia ``I_z`` (the only yaw inertia of
    its model), ``lf = a``, ``lr = b`` (reference point: sprung-mass CG, as CommonRoad's),
    ``Cf``, ``Cr`` = :func:`true_cornering_stiffness`, ``track`` = mean track width.
    """
    cf, cr = true_cornering_stiffness(params)
    return VehicleParams(
        m=params.m, Iz=params.I_z, lf=params.a, lr=params.b, vx=vx, Cf=cf, Cr=cr,
        width=params.w, track=0.5 * (params.T_f + params.T_r), h_cg=params.h_cg,
    )  # fmt: skip


class PathTable:
    """The road's reference path as global ``x, y, heading, kappa`` every ``ds`` metres.

    Built with :meth:`~tire_learning_env.roads.Road.geometry` (starts at the origin,
    heading 0) and grown on demand.
    """

    def __init__(self, road: Road, ds: float = 0.05, length: float = 600.0) -> None:
        self.road = road
        self.ds = float(ds)
        self.length = 0.0
        self.cover(length)

    def cover(self, length: float) -> None:
        """Make the table reach at least ``length`` metres (doubling when it grows)."""
        if self.length >= length:
            return
        new = max(float(length), 2.0 * self.length)
        geo = self.road.geometry(new, self.ds)
        self.x = np.ascontiguousarray(geo["x"])
        self.y = np.ascontiguousarray(geo["y"])
        self.heading = np.ascontiguousarray(geo["heading"])
        self.kappa = np.ascontiguousarray(geo["kappa"])
        self.length = float(geo["s"][-1])

    def arrays(self) -> tuple:
        return self.x, self.y, self.heading, self.kappa, self.ds


class MultiBodyPlant:
    """High-order truth vehicle: CommonRoad's multi-body model on a road, for :class:`~.simulation.Simulator`.

    Parameters
    ----------
    road : Road or str
        Reference path (the same road the simulator's driver follows).
    params : MultiBodyParams, optional
        Vehicle and tire (default :func:`~.params.bmw_320i`, CommonRoad's vehicle 2).
    config : HighOrderConfig, optional
        Relaxation length, steering servo, speed controller, tire symmetry.
    vx : float
        Nominal speed of the equivalent bicycle and default speed set-point [m/s].
    record : bool
        Keep a per-tick history of the wheel quantities (:meth:`history`).

    Notes
    -----
    ``step(delta, dt, psi_dot_des, psi_ddot_des, vx, ax)`` takes the commanded road-wheel
    angle ``delta`` [rad], the speed set-point ``vx`` [m/s] and acceleration feed-forward
    ``ax`` [m/s^2]; the desired yaw rates are not needed (the plant knows the road). It
    returns the truth at the start of the step, like the bicycle plant.
    """

    def __init__(
        self,
        road: Road | str = "study1",
        params: MultiBodyParams | None = None,
        config: HighOrderConfig | None = None,
        vx: float = 30.0,
        record: bool = False,
    ) -> None:
        self.params = params if params is not None else bmw_320i()
        if not isinstance(self.params, MultiBodyParams):
            raise ParameterError(f"params must be a MultiBodyParams, got {type(self.params).__name__}")
        self.config = config if config is not None else HighOrderConfig()
        if not isinstance(self.config, HighOrderConfig):
            raise ParameterError(f"config must be a HighOrderConfig, got {type(self.config).__name__}")
        if not (math.isfinite(vx) and vx > 0.1):
            raise ParameterError(f"vx must be > 0.1 m/s, got {vx!r}")
        self.road = make_road(road)
        self.vehicle = equivalent_bicycle(self.params, vx)
        self.par = parameter_vector(self.params, self.config)
        self.ty = tire_vector(self.params.tire, self.config.symmetric_tire)
        self.path = PathTable(self.road)
        self.x = np.zeros(K.N_STATE)
        self.state = np.zeros(4)
        self._work = np.zeros((6, K.N_STATE))
        self._aux = np.zeros(K.N_AUX)
        self._truth = np.zeros(K.N_TRUTH)
        self.record = bool(record)
        self._effective_stiffness: tuple[float, float] | None = None
        self._effective_curves: dict | None = None
        self.reset()

    # -- plant interface --------------------------------------------------------------
    def reset(self, xi: ArrayLike | None = None) -> None:
        """Start at ``s = 0`` with error state ``xi`` (default zero), in static equilibrium.

        ``xi = [e1, e1_dot, e2, e2_dot]`` sets the position left of the path, the heading,
        the lateral velocity ``v_y = (e1_dot - v_x sin e2) / cos e2`` and the yaw rate
        ``r = e2_dot + kappa(0) s_dot``. Speed: the equivalent bicycle's ``vx``; wheels
        roll without slip; relaxation lags start at the kinematic slip.
        """
        xi = np.zeros(4) if xi is None else np.asarray(xi, dtype=float).reshape(4)
        if not np.all(np.isfinite(xi)):
            raise ValueError(f"initial state must be finite, got {xi}")
        e1, e1d, e2, e2d = xi
        vx = self.vehicle.vx
        p = self.params
        x = static_state(p, vx)
        px, py, ph, pk, _ = self.path.arrays()
        th, k0 = ph[0], pk[0]
        vy = (e1d - vx * math.sin(e2)) / math.cos(e2)
        s_dot = (vx * math.cos(e2) - vy * math.sin(e2)) / (1.0 - k0 * e1)
        r = e2d + k0 * s_dot
        x[K.S_X] = px[0] - e1 * math.sin(th)
        x[K.S_Y] = py[0] + e1 * math.cos(th)
        x[K.S_PSI] = th + e2
        x[K.S_VY] = vy
        x[K.S_R] = r
        x[K.S_VY_F] = vy + p.a * r
        x[K.S_VY_R] = vy - p.b * r
        # wheels rolling without slip
        x[K.S_OMEGA_LF] = (vx + 0.5 * p.T_f * r) / p.R_w
        x[K.S_OMEGA_RF] = (vx - 0.5 * p.T_f * r) / p.R_w
        x[K.S_OMEGA_LR] = (vx + 0.5 * p.T_r * r) / p.R_w
        x[K.S_OMEGA_RR] = (vx - 0.5 * p.T_r * r) / p.R_w
        f = np.zeros(K.N_STATE)
        K.plant_rhs(x, 0.0, vx, 0.0, self.par, self.ty, f, self._aux)
        x[K.S_LAG_LF : K.S_LAG_RR + 1] = self._aux[K.AUX_ALPHA : K.AUX_ALPHA + K.N_WHEELS]
        self.x[:] = x
        self.s, e1, e1d, e2, e2d = K.path_errors(x[K.S_X], x[K.S_Y], x[K.S_PSI], vx, vy, r, 0.0, *self.path.arrays())
        self.state[:] = (e1, e1d, e2, e2d)
        self.t = 0.0
        self._last = (0.0, vx, 0.0)
        self._history: list[NDArray] = []
        self._lag_start = x[K.S_LAG_LF : K.S_LAG_RR + 1].copy()

    def step(
        self,
        delta: float,
        dt: float,
        psi_dot_des=None,
        psi_ddot_des=None,
        vx: float | None = None,
        ax: float = 0.0,
    ) -> tuple[float, float, float, float, float, float]:
        """Advance one RK4 step of ``dt`` [s] with road-wheel command ``delta`` [rad].

        Returns
        -------
        tuple of float
            Truth at the start of the step: axle slips ``alpha_f, alpha_r`` [rad], axle
            forces ``F_yf, F_yr`` [N], yaw rate [rad/s], lateral acceleration [m/s^2].

        Raises
        ------
        FloatingPointError
            If the state becomes non-finite, naming the time and the state.
        """
        v_ref = self.vehicle.vx if vx is None else vx
        if self.s + 200.0 > self.path.length:
            self.path.cover(self.s + 400.0)
        before = self.x.copy()
        ok, s = K.plant_tick(
            self.x, self.state, delta, dt, v_ref, ax, self.par, self.ty, self._work, self._aux, self._truth,
            self.s, self.path.x, self.path.y, self.path.heading, self.path.kappa, self.path.ds,
        )  # fmt: skip
        if not ok:
            self._blow_up(before, delta)
        self._lag_start = before[K.S_LAG_LF : K.S_LAG_RR + 1]
        if self.record:
            self._history.append(np.concatenate([[self.t, self.s], self._aux, self._truth, self._lag_start]))
        self.s = s
        self.t += dt
        self._last = (delta, v_ref, ax)
        tr = self._truth
        return (
            tr[K.TR_ALPHA_F], tr[K.TR_ALPHA_R], tr[K.TR_FYF], tr[K.TR_FYR], tr[K.TR_YAW_RATE], tr[K.TR_AY],
        )  # fmt: skip

    def _blow_up(self, before: NDArray, delta: float) -> None:
        named = ", ".join(f"{n}={v:.6g}" for n, v in zip(K.STATE_NAMES, before))
        bad = [n for n, v in zip(K.STATE_NAMES, self.x) if not math.isfinite(v)]
        raise FloatingPointError(
            f"high-order plant blew up at t={self.t:.4f} s (delta={delta!r} rad): non-finite {bad or ['e1/e2']}; "
            f"state at the start of the step: {named}"
        )

    def output(self) -> PlantOutput:
        """Ground truth at the current state (inputs of the last step)."""
        delta, v_ref, ax = self._last
        x = self.x.copy()
        if not self.config.steering_time_constant > 0:
            x[K.S_DELTA] = delta
        f = np.zeros(K.N_STATE)
        aux = np.zeros(K.N_AUX)
        tr = np.zeros(K.N_TRUTH)
        K.plant_rhs(x, delta, v_ref, ax, self.par, self.ty, f, aux)
        K.truth_from_rhs(x, f, aux, self.par, tr)
        slip = np.array([tr[K.TR_ALPHA_F], tr[K.TR_ALPHA_R]])
        force = np.array([tr[K.TR_FYF], tr[K.TR_FYR]])
        veh = self.vehicle
        return PlantOutput(
            xi=self.state.copy(),
            slip=slip,
            force=force,
            force_nonlinear=force - slip * np.array([2.0 * veh.Cf, 2.0 * veh.Cr]),
            yaw_rate=float(tr[K.TR_YAW_RATE]),
            ay=float(tr[K.TR_AY]),
            vy=float(tr[K.TR_VY]),
        )

    # -- scoring references -------------------------------------------------------------
    def true_axle_curve(self, alpha: ArrayLike, axle: str, reference: str = "tire") -> NDArray:
        """True axle lateral force [N] at axle slip(s) ``alpha`` [rad] (the scoring reference).

        Parameters
        ----------
        reference : {"tire", "effective"}
            ``"tire"`` (default): twice the model's own tire force at static load, zero
            camber and zero longitudinal slip (its slope at zero is ``2 C`` of
            :meth:`true_cornering_stiffness`). With CommonRoad's PAC2002 subset lateral
            load transfer leaves the axle force at a given slip unchanged, since stiffness
            and peak are both proportional to load. ``"effective"``: the quasi-steady axle
            force against eq. (13) slip on steady circles
            (:func:`~.simulate.steady_state_axle_curves`, computed once per plant, about
            1.5 s), which also contains the roll-camber thrust: what a bicycle model fitted
            to this vehicle can learn (see ``docs/high_order.md`` §6). Beyond the largest
            steady circle it continues with the tire curve's increments.
        """
        if axle not in ("front", "rear"):
            raise ParameterError(f"axle must be 'front' or 'rear', got {axle!r}")
        fz_f, fz_r = static_wheel_loads(self.params)
        fz = fz_f if axle == "front" else fz_r

        def tire(a):
            return 2.0 * tire_lateral_force(a, fz, self.params.tire, self.config.symmetric_tire)

        if reference == "tire":
            return tire(alpha)
        if reference != "effective":
            raise ParameterError(f"reference must be 'tire' or 'effective', got {reference!r}")
        a_pts, f_pts = self._effective_points(axle)
        a = np.asarray(alpha, dtype=float)
        out = np.interp(a, a_pts, f_pts)
        hi, lo = a > a_pts[-1], a < a_pts[0]
        if np.any(hi):
            out = np.where(hi, f_pts[-1] + tire(a) - tire(a_pts[-1]), out)
        if np.any(lo):
            out = np.where(lo, f_pts[0] + tire(a) - tire(a_pts[0]), out)
        return out

    def true_cornering_stiffness(self, reference: str = "tire") -> tuple[float, float]:
        """True per-tire cornering stiffness front/rear [N/rad].

        ``"tire"`` (default): slope of the model's own tire force at zero slip at static
        load (:func:`true_cornering_stiffness`, equal to ``vehicle.Cf``, ``vehicle.Cr``).
        ``"effective"``: half the quasi-steady axle slope seen by a bicycle model
        (:func:`~.simulate.effective_cornering_stiffness`).
        """
        if reference == "tire":
            return self.vehicle.Cf, self.vehicle.Cr
        if reference != "effective":
            raise ParameterError(f"reference must be 'tire' or 'effective', got {reference!r}")
        if self._effective_stiffness is None:
            self._effective_stiffness = _closed_loop_reference("cornering_stiffness")(self.params, self.config)
        return self._effective_stiffness

    def _effective_points(self, axle: str) -> tuple[NDArray, NDArray]:
        if self._effective_curves is None:
            self._effective_curves = _closed_loop_reference("axle_curves")(self.params, self.config, ay_max=6.0, count=12)
        c = self._effective_curves
        key = "f" if axle == "front" else "r"
        order = np.argsort(c["alpha_" + key])
        return c["alpha_" + key][order], c["Fy" + key][order]

    def wheel_output(self) -> dict[str, NDArray]:
        """Per-wheel quantities at the start of the last step (LF, RF, LR, RR), SPEC sign.

        ``alpha_kinematic`` and ``alpha_lagged`` [rad] (positive slip -> positive force),
        ``fy``, ``fx``, ``fz`` [N] (wheel frame), ``kappa`` [-], ``camber`` [rad].
        """
        return self._wheels(self._aux, self._lag_start)

    def _wheels(self, aux: NDArray, lag: NDArray) -> dict[str, NDArray]:
        kin = -aux[..., K.AUX_ALPHA : K.AUX_ALPHA + K.N_WHEELS]
        return {
            "alpha_kinematic": kin,
            "alpha_lagged": -lag if self.config.relaxation_length > 0 else kin,
            "fy": aux[..., K.AUX_FY : K.AUX_FY + K.N_WHEELS],
            "fx": aux[..., K.AUX_FX : K.AUX_FX + K.N_WHEELS],
            "fz": aux[..., K.AUX_FZ : K.AUX_FZ + K.N_WHEELS],
            "kappa": aux[..., K.AUX_KAPPA : K.AUX_KAPPA + K.N_WHEELS],
            "camber": aux[..., K.AUX_GAMMA : K.AUX_GAMMA + K.N_WHEELS],
        }

    def history(self) -> dict[str, NDArray]:
        """Per-tick history (``record=True``): ``t``, ``s``, the :meth:`wheel_output` keys (n, 4), axle truth."""
        if not self.record:
            raise RuntimeError("construct the plant with record=True to keep a history")
        h = np.array(self._history).reshape(-1, 2 + K.N_AUX + K.N_TRUTH + K.N_WHEELS)
        aux = h[:, 2 : 2 + K.N_AUX]
        tr = h[:, 2 + K.N_AUX : 2 + K.N_AUX + K.N_TRUTH]
        out = {"t": h[:, 0], "s": h[:, 1]}
        out.update(self._wheels(aux, h[:, -K.N_WHEELS:]))
        out.update(
            alpha_f=tr[:, K.TR_ALPHA_F], alpha_r=tr[:, K.TR_ALPHA_R], Fyf=tr[:, K.TR_FYF], Fyr=tr[:, K.TR_FYR],
            vx=tr[:, K.TR_VX], delta=tr[:, K.TR_DELTA],
        )  # fmt: skip
        return out

    @property
    def state_names(self) -> tuple[str, ...]:
        return K.STATE_NAMES
