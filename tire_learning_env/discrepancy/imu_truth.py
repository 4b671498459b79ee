"""Hidden-effect truth data for IMU-only logs: a race-car drive with named effects.

The IMU counterpart of :mod:`.truth`: :func:`simulate_hidden_imu` simulates the
body-frame bicycle model (states ``vy, r``; Pacejka axle tires) on a race-track-like
drive (accelerate on straights, brake at up to ``brake`` m/s^2 while turning in, corner at
up to ``ay_max``, accelerate out, chicanes; both directions) and logs what an IMU-only log
holds: ``t, vx, delta, yaw_rate, ay, ax`` with white sensor noise, plus the truth
(``true_vy``, ``true_beta``, slips and axle forces) apart.

Named effects (:data:`HIDDEN_IMU_EFFECTS`) use the stable names of the IMU candidate
library (:data:`.effects.IMU_LIBRARY`) with the same forms, implemented here
independently of the compiled model (plain Python, RK4 with sub-steps), so a test
checks the model code as well as the selection. ``combined_slip`` (a friction-ellipse
loss of lateral force under braking and traction) is deliberately *not* in the library:
data for the ``unexplained`` verdict.

The driver steers with a feed-forward on the commanded lateral acceleration plus a light
yaw-rate feedback; the steering is continuous (piecewise linear between the logged
samples), so the workflow's ``linear`` steering between rows reproduces it exactly.
"""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np
from numpy.typing import NDArray

from ..params import ParameterError, TireParams, VehicleParams
from .._kernels import bicycle_slip_angles
from ..tires import PacejkaTire

__all__ = ["HIDDEN_IMU_EFFECTS", "parse_imu_effects", "race_drive", "simulate_hidden_imu", "REVS_LIKE_VEHICLE"]

_G = 9.81


class TruthState(IntEnum):
    """Components of the truth's state ``x`` (body-frame bicycle model with slip lags)."""

    VY = 0  # lateral velocity at the CG [m/s]
    R = 1  # yaw rate [rad/s]
    LAG_F = 2  # lagged front slip angle [rad] (relaxation; the kinematic slip without)
    LAG_R = 3  # lagged rear slip angle [rad]


#: a vehicle like the Revs Ferrari 250 LM (``revs_250lm_vehicle.json``)
REVS_LIKE_VEHICLE = VehicleParams(m=982.0, Iz=1605.0, lf=1.33, lr=1.07, Cf=35000.0, Cr=60000.0)

#: stable name -> (internal key(s), unit, what it does)
HIDDEN_IMU_EFFECTS: dict[str, tuple[tuple[str, ...], str, str]] = {
    "tire_relaxation": (("relax",), "m", "relaxation length of both axles"),
    "cornering_stiffness_scale": (("scale_f", "scale_r"), "-", "both axle forces scaled"),
    "cornering_stiffness_scale_front": (("scale_f",), "-", "front axle force scaled"),
    "cornering_stiffness_scale_rear": (("scale_r",), "-", "rear axle force scaled"),
    "longitudinal_load_transfer": (("h",), "m", "effective CG height of the longitudinal load transfer"),
    "lateral_load_transfer": (("lat_f", "lat_r"), "-", "axle force loss at 1 g lateral (both axles)"),
    "lateral_load_transfer_front": (("lat_f",), "-", "front axle force loss at 1 g lateral"),
    "lateral_load_transfer_rear": (("lat_r",), "-", "rear axle force loss at 1 g lateral"),
    "steering_offset": (("offset",), "rad", "road-wheel angle offset"),
    "steering_compliance": (("compliance",), "rad/N", "road-wheel angle lost per newton of front axle force"),
    "steering_ratio_nonlinearity": (("quick",), "-", "road-wheel angle delta (1 + q (delta / 0.1)^2)"),
    "steering_delay": (("delay",), "s", "road wheels follow the logged steering this much later"),
    "yaw_rate_bias": (("yaw_bias",), "rad/s", "gyro bias"),
    "ay_bias": (("ay_bias",), "m/s^2", "lateral accelerometer bias"),
    "ay_scale": (("ay_scale",), "-", "lateral accelerometer scale error (roll-induced gravity component)"),
    "road_bank": (("bank",), "rad", "road bank angle (positive raises the left edge)"),
    "accelerometer_offset": (("acc_x",), "m", "accelerometer ahead of the CG"),
    "yaw_inertia_scale": (("iz_scale",), "-", "true yaw inertia = Iz times this"),
    "speed_dependent_stiffness": (("speed_coef",), "s^2/m^2", "axle forces times 1 - c vx^2"),
    "combined_slip": (("mu_x",), "-", "friction ellipse: axle forces times sqrt(1 - (a_x / (mu_x g))^2) "
                      "(NOT in the candidate library)"),
}  # fmt: skip

_DEFAULTS = {
    "relax": 0.0, "scale_f": 1.0, "scale_r": 1.0, "h": 0.0, "lat_f": 0.0, "lat_r": 0.0, "offset": 0.0,
    "compliance": 0.0, "quick": 0.0, "delay": 0.0, "yaw_bias": 0.0, "ay_bias": 0.0, "ay_scale": 0.0,
    "bank": 0.0, "acc_x": 0.0, "iz_scale": 1.0, "speed_coef": 0.0, "mu_x": 0.0,
}  # fmt: skip


def parse_imu_effects(effects: dict[str, float] | None) -> dict[str, float]:
    """Internal effect values from ``{stable name: value}`` (unknown names raise, listing the known ones)."""
    out = dict(_DEFAULTS)
    for name, value in (effects or {}).items():
        if name not in HIDDEN_IMU_EFFECTS:
            raise ParameterError(f"unknown IMU effect {name!r}; known: {', '.join(sorted(HIDDEN_IMU_EFFECTS))}")
        if not math.isfinite(value):
            raise ParameterError(f"IMU effect {name}: value must be finite, got {value!r}")
        for key in HIDDEN_IMU_EFFECTS[name][0]:
            out[key] = float(value)
    if out["delay"] < 0:
        raise ParameterError("steering_delay must be >= 0 in the truth simulator")
    return out


def race_drive(duration: float, dt: float, seed: int, ay_max: float = 9.0, brake: float = 8.0,
               speed_range: tuple[float, float] = (20.0, 52.0)) -> tuple[NDArray, NDArray, NDArray]:  # fmt: skip
    """Commanded speed ``vx`` [m/s], its slope ``ax`` [m/s^2] and lateral acceleration ``ay_cmd`` [m/s^2].

    Corners in both directions: accelerate (+3 m/s^2) to a top speed, brake at 0.6-1 times
    ``brake`` while the lateral acceleration builds up (trail braking), hold the corner,
    accelerate out while it falls; every third corner is a chicane (a left-right at
    constant speed). Knots are joined linearly and smoothed over 0.3 s.
    """
    rng = np.random.default_rng(seed)
    v_lo, v_hi = speed_range
    tk, vk, ak = [0.0], [0.5 * (v_lo + v_hi)], [0.0]
    side = 1.0 if rng.random() < 0.5 else -1.0
    i = 0
    while tk[-1] < duration + 5.0:
        v = vk[-1]
        if i % 3 == 2:  # chicane at constant speed
            amp = rng.uniform(0.4, 0.7) * ay_max
            half = rng.uniform(0.9, 1.5)
            for s in (side, -side, 0.0):
                tk.append(tk[-1] + half)
                vk.append(v)
                ak.append(s * amp)
            tk.append(tk[-1] + 1.0)
            vk.append(v)
            ak.append(0.0)
        else:
            v_top = rng.uniform(0.8, 1.0) * v_hi
            if v_top > v:  # straight: accelerate
                tk.append(tk[-1] + (v_top - v) / 3.0)
                vk.append(v_top)
                ak.append(0.0)
            v_c = rng.uniform(v_lo, 0.65 * v_hi)
            ay_c = side * rng.uniform(0.65, 1.0) * ay_max
            decel = rng.uniform(0.6, 1.0) * brake
            t_brake = (vk[-1] - v_c) / decel
            # trail braking: straight-line braking first, then turn-in while still braking
            tk.append(tk[-1] + 0.5 * t_brake)
            vk.append(0.5 * (vk[-1] + v_c))
            ak.append(0.0)
            tk.append(tk[-1] + 0.5 * t_brake)
            vk.append(v_c)
            ak.append(0.8 * ay_c)
            tk.append(tk[-1] + rng.uniform(1.0, 2.5))  # mid corner
            vk.append(v_c)
            ak.append(ay_c)
            t_exit = rng.uniform(1.5, 3.0)  # accelerate out while unwinding
            tk.append(tk[-1] + t_exit)
            vk.append(v_c + 3.0 * t_exit)
            ak.append(0.0)
        side = -side if rng.random() < 0.7 else side
        i += 1
    n = int(round(duration / dt)) + 1
    t = np.arange(n) * dt
    vx = np.interp(t, tk, vk)
    ay = np.interp(t, tk, ak)
    w = max(1, int(round(0.3 / dt)))
    kern = np.ones(w) / w
    pad = w
    vx = np.convolve(np.pad(vx, pad, mode="edge"), kern, mode="same")[pad:-pad]
    ay = np.convolve(np.pad(ay, pad, mode="edge"), kern, mode="same")[pad:-pad]
    return vx, np.gradient(vx, t), ay


def simulate_hidden_imu(
    effects: dict[str, float] | None = None,
    duration: float = 90.0,
    dt: float = 0.01,
    vehicle: VehicleParams | None = None,
    tire: TireParams | None = None,
    noise_std: tuple[float, float, float] = (1.0, 0.005, 0.5),
    seed: int = 0,
    drive_seed: int | None = None,
    substeps: int = 2,
    ay_max: float = 9.0,
    brake: float = 8.0,
    truth_columns: bool = True,
) -> dict[str, NDArray]:
    """Columns of an IMU-only log (shared format) with hidden ``effects``.

    Parameters
    ----------
    effects : dict
        ``{name: value}`` with the names of :data:`HIDDEN_IMU_EFFECTS`.
    duration, dt : float
        Length [s] and sample period [s].
    vehicle : VehicleParams
        Default :data:`REVS_LIKE_VEHICLE`.
    tire : TireParams
        Magic-Formula shape of the truth tires; default ``mu = 1.4`` (racing tires).
    noise_std : (float, float, float)
        White noise std of ``ay`` [m/s^2], ``yaw_rate`` [rad/s], ``ax`` [m/s^2] (the Revs log's
        own levels are about 1.0, 0.0045, 0.7).
    seed : int
        Noise seed; ``drive_seed`` (default ``seed``) the drive's.
    substeps : int
        RK4 steps per sample.
    """
    vehicle = vehicle or REVS_LIKE_VEHICLE
    tire = tire or TireParams(mu=1.4)
    e = parse_imu_effects(effects)
    rng = np.random.default_rng(seed)
    vx, vxd, ay_cmd = race_drive(duration, dt, seed if drive_seed is None else drive_seed, ay_max, brake)
    n = len(vx)
    t = np.arange(n) * dt
    front = PacejkaTire.for_axle(vehicle, tire, "front")
    rear = PacejkaTire.for_axle(vehicle, tire, "rear")
    ff, fr = front.force, rear.force
    m, lf, lr = vehicle.m, vehicle.lf, vehicle.lr
    slip = bicycle_slip_angles.py_func  # eq. (13), the package's one implementation (plain Python in this loop)
    Iz = vehicle.Iz * e["iz_scale"]
    L = vehicle.wheelbase
    kus = m * (lr / (2 * vehicle.Cf) - lf / (2 * vehicle.Cr)) / L

    delta = np.zeros(n)
    # state components read once: an enum attribute read costs ~0.3 us in the RK4 loop
    VY, R, LAG_F, LAG_R = TruthState.VY, TruthState.R, TruthState.LAG_F, TruthState.LAG_R

    def steer_log(tq: float) -> float:
        # the logged steering is piecewise linear between samples (known up to the current sample)
        u = tq / dt
        if u <= 0:
            return float(delta[0])
        i = min(int(u), n - 2)
        f = u - i
        return float(delta[i] + f * (delta[i + 1] - delta[i]))

    def forces(vy, r, laf, lar, dlog, v, axs):
        """Slips, axle forces, effective steering and the lateral specific force (effect forms of the library)."""
        d0 = dlog * (1.0 + e["quick"] * (dlog / 0.1) ** 2) + e["offset"]
        gv = 1.0 - e["speed_coef"] * v * v
        gf = e["scale_f"] * gv * (1.0 - axs * e["h"] / (_G * lr))
        gr = e["scale_r"] * gv * (1.0 + axs * e["h"] / (_G * lf))
        if e["mu_x"] > 0:
            c = math.sqrt(max(1.0 - (axs / (e["mu_x"] * _G)) ** 2, 1e-4))
            gf *= c
            gr *= c
        gf, gr = max(gf, 0.02), max(gr, 0.02)
        kin_f, ar = slip(vy, r, 0.0, v, lf, lr)  # eq. (13) without the steering (added with its effects)
        if e["relax"] > 0:
            Fyf = gf * ff(laf)
            Fyr = gr * fr(lar)
            deff = d0 - e["compliance"] * Fyf
        else:
            # solve F = gf F_f(kin + d0 - c F) (Newton; the map is monotone)
            Fyf = gf * ff(kin_f + d0)
            for _ in range(30):
                if e["compliance"] == 0.0:
                    break
                a = kin_f + d0 - e["compliance"] * Fyf
                g = Fyf - gf * ff(a)
                dg = 1.0 + e["compliance"] * gf * (ff(a + 1e-6) - ff(a - 1e-6)) / 2e-6
                Fyf -= g / dg
                if abs(g) < 1e-9:
                    break
            deff = d0 - e["compliance"] * Fyf
            Fyr = gr * fr(ar)
        af = deff + kin_f
        cd = math.cos(deff)
        u2 = ((Fyf * cd + Fyr) / (m * _G)) ** 2
        Fyf *= max(1.0 - e["lat_f"] * u2, 0.02)
        Fyr *= max(1.0 - e["lat_r"] * u2, 0.02)
        return af, ar, Fyf, Fyr, cd

    def rhs(x, tq, v, vd):
        vy, r, laf, lar = x[VY], x[R], x[LAG_F], x[LAG_R]
        axs = vd - r * vy  # longitudinal specific force of the body
        dlog = steer_log(tq - e["delay"])
        af, ar, Fyf, Fyr, cd = forces(vy, r, laf, lar, dlog, v, axs)
        ay = (Fyf * cd + Fyr) / m
        out = np.empty(len(TruthState))
        out[VY] = ay - _G * math.sin(e["bank"]) - v * r
        out[R] = (lf * Fyf * cd - lr * Fyr) / Iz
        if e["relax"] > 0:
            out[LAG_F] = v / e["relax"] * (af - laf)
            out[LAG_R] = v / e["relax"] * (ar - lar)
        else:
            out[LAG_F] = out[LAG_R] = 0.0
        return out, af, ar, Fyf, Fyr, ay

    x = np.zeros(len(TruthState))
    vy_true = np.zeros(n)
    r_true = np.zeros(n)
    ay_true = np.zeros(n)
    rd_true = np.zeros(n)
    ax_true = np.zeros(n)
    slips = np.zeros((n, 2))
    fys = np.zeros((n, 2))
    h = dt / substeps
    for k in range(n):
        if k == 0:
            delta[0] = L * ay_cmd[0] / vx[0] ** 2 + kus * ay_cmd[0]
            # start in the lag's steady state
            x[LAG_F], x[LAG_R] = slip(x[VY], x[R], delta[0], vx[0], lf, lr)
        d, af, ar, Fyf, Fyr, ay = rhs(x, t[k], vx[k], vxd[k])
        vy_true[k], r_true[k] = x[VY], x[R]
        ay_true[k], rd_true[k] = ay, d[R]
        ax_true[k] = vxd[k] - x[R] * x[VY]
        slips[k] = (af, ar)
        fys[k] = (Fyf, Fyr)
        if k == n - 1:
            break
        # the next steering sample: feed-forward at t_{k+1} plus yaw feedback on the state at t_k
        a_next = ay_cmd[k + 1]
        v_next = vx[k + 1]
        delta[k + 1] = L * a_next / v_next**2 + kus * a_next + 0.05 * (a_next / v_next - x[R])
        for j in range(substeps):
            s0 = t[k] + j * h
            f0, f1, f2 = j / substeps, (j + 0.5) / substeps, (j + 1.0) / substeps
            v0, v1, v2 = (vx[k] + f * (vx[k + 1] - vx[k]) for f in (f0, f1, f2))
            a0, a1, a2 = (vxd[k] + f * (vxd[k + 1] - vxd[k]) for f in (f0, f1, f2))
            k1 = rhs(x, s0, v0, a0)[0]
            k2 = rhs(x + 0.5 * h * k1, s0 + 0.5 * h, v1, a1)[0]
            k3 = rhs(x + 0.5 * h * k2, s0 + 0.5 * h, v1, a1)[0]
            k4 = rhs(x + h * k3, s0 + h, v2, a2)[0]
            x = x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        if not np.all(np.isfinite(x)) or abs(x[VY]) > 0.5 * vx[k + 1]:
            raise ParameterError(f"the simulated car spun at t = {t[k + 1]:.2f} s (effects {effects})")
    cols = {
        "t": t,
        "vx": vx,
        "delta": delta,
        "yaw_rate": r_true + e["yaw_bias"] + rng.normal(0.0, noise_std[1], n),
        "ay": ay_true * (1.0 + e["ay_scale"]) + e["ay_bias"] + e["acc_x"] * rd_true
        + rng.normal(0.0, noise_std[0], n),
        "ax": ax_true + rng.normal(0.0, noise_std[2], n),
    }
    if truth_columns:
        cols.update(
            true_vy=vy_true, true_beta=np.arctan2(vy_true, vx), true_alpha_f=slips[:, 0], true_alpha_r=slips[:, 1],
            true_Fyf=fys[:, 0], true_Fyr=fys[:, 1],
        )  # fmt: skip
    return cols
