"""Independent single-track log generator (Frenet frame, Pacejka axle tires, RK4 at 1 kHz).

Not using tire_learning_env at all.
"""
import json
import math
import sys

import numpy as np

VEHICLES = {
    "compact": dict(m=1100.0, Iz=1400.0, lf=0.95, lr=1.50, Cax_f=70000.0, Cax_r=80000.0, mu=1.0, C=1.4, E=-0.3),
    "sedan": dict(m=1600.0, Iz=2700.0, lf=1.20, lr=1.55, Cax_f=110000.0, Cax_r=125000.0, mu=0.95, C=1.35, E=0.1),
    "suv": dict(m=2300.0, Iz=4600.0, lf=1.40, lr=1.55, Cax_f=150000.0, Cax_r=175000.0, mu=0.9, C=1.5, E=-0.8),
}
G = 9.81


def pacejka(alpha, B, C, D, E):
    x = B * alpha
    return D * math.sin(C * math.atan(x - E * (x - math.atan(x))))


class Road:
    """Curvature as a function of arc length, piecewise."""

    def __init__(self, segments):
        # segments: list of (kind, length, param)
        self.segs = []
        s = 0.0
        for kind, length, p in segments:
            self.segs.append((s, s + length, kind, length, p))
            s += length
        self.length = s

    def kappa(self, s):
        for s0, s1, kind, L, p in self.segs:
            if s0 <= s < s1:
                u = (s - s0) / L
                if kind == "straight":
                    return 0.0
                if kind == "arc":  # p = curvature; smooth entry/exit over 15 % of the length
                    ramp = 0.15
                    f = min(1.0, u / ramp, (1 - u) / ramp)
                    return p * f
                if kind == "lc":  # lane change of width p
                    return p * 2 * math.pi / L**2 * math.sin(2 * math.pi * u)
                if kind == "sine":  # p = (amplitude kappa, n periods)
                    return p[0] * math.sin(2 * math.pi * p[1] * u)
        return 0.0


def make_road(kind, rng, length, v0=25.0, ay_max=4.0):
    segs = []
    s = 0.0
    if kind == "straight":
        return Road([("straight", length, None)])
    segs.append(("straight", 150.0, None))
    s = 150.0
    while s < length:
        c = rng.choice(["arc", "lc", "straight", "lc", "arc"]) if kind == "mixed" else kind
        if c == "arc":
            R = max(rng.uniform(150, 450), v0**2 / ay_max * rng.uniform(1.0, 1.5)) * rng.choice([-1, 1])
            L = rng.uniform(150, 400)
            segs.append(("arc", L, 1 / R))
        elif c == "lc":
            L = max(rng.uniform(60, 110), v0 * rng.uniform(2.5, 4.0))
            segs.append(("lc", L, 3.5 * rng.choice([-1, 1])))
            L2 = rng.uniform(20, 60)
            segs.append(("straight", L2, None))
            L += L2
        else:
            L = rng.uniform(50, 200)
            segs.append(("straight", L, None))
        s += L
    segs.append(("straight", 1e6, None))
    return Road(segs)


def simulate(veh, duration, rng, road_kind="mixed", v0=25.0, dv=2.0, log_rate=100.0, cam_rate=20.0, latency=0.08,
             cam_noise=("gaussian", 0.01, math.radians(0.3)), drop=0.05, imu=True, imu_noise=(0.05, 0.002),
             standstill=(0.0, 0.0), reverse=0.0, freeze=None, dither=0.004, t0=0.0, jitter=0.0, ay_max=4.0, relax=0.0, cam_offset=0.0, bank=0.0):
    v = VEHICLES[veh] if isinstance(veh, str) else veh
    m, Iz, lf, lr = v["m"], v["Iz"], v["lf"], v["lr"]
    L = lf + lr
    Fzf, Fzr = m * G * lr / L, m * G * lf / L
    Df, Dr = v["mu"] * Fzf, v["mu"] * Fzr
    C, E = v["C"], v["E"]
    Bf, Br = v["Cax_f"] / (C * Df), v["Cax_r"] / (C * Dr)
    road = make_road(road_kind, rng, v0 * duration + 500, v0, ay_max)
    dt = 1e-3
    n = int(round(duration / dt))

    # speed profile incl. standstill and reversing
    st0, st1 = standstill

    def speed(t):
        if t < reverse:
            return -2.0 * math.sin(math.pi * t / reverse)
        t_drive = t - reverse
        if t_drive < st0:
            return 0.0
        tt = t_drive - st0
        ramp = min(1.0, tt / 8.0) if st0 > 0 or reverse > 0 else 1.0
        end_ramp = 1.0
        if st1 > 0:
            t_end = duration - st1
            if t >= t_end:
                return 0.0
            end_ramp = min(1.0, (t_end - t) / 8.0)
        return (v0 + dv * math.sin(2 * math.pi * t / 45.0)) * ramp * end_ramp

    def rhs(x, delta, vx, kap):
        s, e1, e2, vy, r, laf, lar = x
        if abs(vx) > 0.5:
            af = delta - math.atan((vy + lf * r) / vx)
            ar = -math.atan((vy - lr * r) / vx)
            if vx < 0:
                af, ar = -af, -ar
        else:
            af = ar = 0.0
        if relax > 0:  # first-order slip lag, relaxation length relax [m]
            dlaf = (af - laf) * abs(vx) / relax
            dlar = (ar - lar) * abs(vx) / relax
            af_use, ar_use = laf, lar
        else:
            dlaf = dlar = 0.0
            af_use, ar_use = af, ar
        Fyf, Fyr = pacejka(af_use, Bf, C, Df, E), pacejka(ar_use, Br, C, Dr, E)
        if abs(vx) > 0.5:
            vyd = (Fyf * math.cos(delta) + Fyr) / m - vx * r + G * math.sin(bank_now[0])
            rd = (lf * Fyf * math.cos(delta) - lr * Fyr) / Iz
        else:  # kinematic at very low speed
            vyd = -vy / 0.05
            rd = (vx * math.tan(delta) / L - r) / 0.05
        sd = (vx * math.cos(e2) - vy * math.sin(e2)) / (1 - kap * e1)
        e1d = vx * math.sin(e2) + vy * math.cos(e2)
        e2d = r - kap * sd
        return np.array([sd, e1d, e2d, vyd, rd, dlaf, dlar]), (af_use, ar_use, Fyf, Fyr)

    bank_now = [0.0]
    x = np.zeros(7)
    delta = 0.0
    delta_cmd = 0.0
    dither_state = 0.0
    rec_every = int(round(1.0 / (log_rate * dt)))
    rows = []
    cam_hist = []  # (t, e1, e2)
    prev_ela = 0.0
    for k in range(n):
        t = k * dt
        vx = speed(t)
        bank_now[0] = bank(t) if callable(bank) else bank
        kap = road.kappa(x[0])
        # driver at 100 Hz: preview feedforward + PD on look-ahead offset
        if k % 10 == 0:
            vabs = max(abs(vx), 1.0)
            la = 0.6 * vabs
            ela = x[1] + la * math.sin(x[2])
            elad = (ela - prev_ela) / 0.01
            prev_ela = ela
            kap_prev = road.kappa(x[0] + 0.4 * vabs)
            dither_state += (-dither_state * 0.01 / 1.5) + dither * math.sqrt(0.01) * rng.standard_normal()
            delta_cmd = L * kap_prev * (1 + 0.0025 * vabs**2) - (0.6 / la**1.0) * ela * 2.0 / vabs * 10 \
                - 0.05 * elad / vabs + dither_state
            delta_cmd = max(-0.3, min(0.3, delta_cmd))
            if vx < 0.5:
                delta_cmd = 0.0
        # steering actuator first-order lag 0.08 s
        delta += (delta_cmd - delta) * dt / 0.08
        k1, aux = rhs(x, delta, vx, kap)
        if k % rec_every == 0:
            ax = (speed(t + dt) - speed(t - dt)) / (2 * dt) if t > 0 else 0.0
            ay = (aux[2] * math.cos(delta) + aux[3]) / m if abs(vx) > 0.5 else vx * x[4]
            rows.append((t, vx, delta, kap, x[1], x[2], x[4], ay, ax, aux[0], aux[1], aux[2], aux[3], x[3], k1[4]))
        # RK4 (delta, vx, kappa held over the step)
        k2, _ = rhs(x + 0.5 * dt * k1, delta, vx, kap)
        k3, _ = rhs(x + 0.5 * dt * k2, delta, vx, kap)
        k4, _ = rhs(x + dt * k3, delta, vx, kap)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    a = np.array(rows)
    cols = dict(zip(["t", "vx", "delta", "kappa", "te1", "te2", "r", "ay", "ax", "true_alpha_f", "true_alpha_r",
                     "true_Fyf", "true_Fyr", "true_vy", "rdot"], a.T))
    nrow = len(a)
    t = cols["t"]
    # camera: frames at cam_rate (with start phase), latency, noise, drops
    e1 = np.full(nrow, np.nan)
    e2 = np.full(nrow, np.nan)
    cam_dt = 1.0 / cam_rate
    tf = np.arange(rng.uniform(0, cam_dt), t[-1], cam_dt)
    kind, s1, s2 = cam_noise
    for tk in tf:
        arrive = tk + latency
        j = int(np.searchsorted(t, arrive - 1e-9))
        if j >= nrow:
            break
        if rng.uniform() < drop:
            continue
        v1 = np.interp(tk, t, cols["te1"]) + cam_offset * math.sin(np.interp(tk, t, cols["te2"]))
        v2 = np.interp(tk, t, cols["te2"])
        if kind == "gaussian":
            v1 += s1 * rng.standard_normal()
            v2 += s2 * rng.standard_normal()
        else:
            v1 += rng.uniform(-s1, s1)
            v2 += rng.uniform(-s2, s2)
        e1[j], e2[j] = v1, v2
    if freeze is not None:
        a0, a1 = freeze
        sel = (t >= a0) & (t < a1) & np.isfinite(e1)
        idx = np.flatnonzero(sel)
        if len(idx):
            e1[idx] = e1[idx[0]]
            e2[idx] = e2[idx[0]]
    out = {"t": t + t0, "vx": cols["vx"], "delta": cols["delta"], "kappa": cols["kappa"], "e1": e1, "e2": e2}
    if imu:
        out["yaw_rate"] = cols["r"] + imu_noise[1] * rng.standard_normal(nrow)
        out["ay"] = cols["ay"] + imu_noise[0] * rng.standard_normal(nrow)
        out["ax"] = cols["ax"]
    for k in ("true_alpha_f", "true_alpha_r", "true_Fyf", "true_Fyr", "true_vy"):
        out[k] = cols[k]
    if jitter > 0:
        out["t"] = out["t"] + rng.uniform(-jitter, jitter, nrow) / log_rate
    truth = {"Cf_tire": v["Cax_f"] / 2, "Cr_tire": v["Cax_r"] / 2}
    out['_r'] = cols['r']; out['_ay'] = cols['ay']; out['_rdot'] = cols['rdot']
    return out, truth


def vehicle_json(veh, rng, err=(0.05, 0.15)):
    v = VEHICLES[veh]
    sf = rng.choice([-1, 1]) * rng.uniform(*err)
    sr = rng.choice([-1, 1]) * rng.uniform(*err)
    return {"m": v["m"], "Iz": v["Iz"], "lf": v["lf"], "lr": v["lr"], "Cf": v["Cax_f"] / 2 * (1 + sf),
            "Cr": v["Cax_r"] / 2 * (1 + sr)}


def write_csv(path, cols, order=None, fmt="%.9g", crlf=False, trailing_empty=False, extra=None, integer=()):
    names = list(order) if order else list(cols)
    if extra:
        cols = dict(cols, **extra)
        names += list(extra)
    nl = "\r\n" if crlf else "\n"
    n = len(cols["t"])
    lines = [",".join(names)]
    arrs = [np.asarray(cols[c]) for c in names]
    for i in range(n):
        cells = []
        for c, a in zip(names, arrs):
            val = a[i]
            if isinstance(val, str):
                cells.append(val)
            elif not np.isfinite(val):
                cells.append("")
            elif c == "t":
                cells.append("%.6f" % val)
            elif c in integer:
                cells.append(str(int(round(val))))
            else:
                cells.append(fmt % val)
        lines.append(",".join(cells))
    text = nl.join(lines) + nl
    if trailing_empty:
        text += nl
    with open(path, "w", newline="") as f:
        f.write(text)
