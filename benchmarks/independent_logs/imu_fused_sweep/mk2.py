"""python mk2.py NAME... -> logs/NAME.csv, NAME.json, NAME.truth.json (+ NAME.args: extra CLI args)"""
import json, sys, math, zlib
import numpy as np
from gen import simulate, vehicle_json, write_csv

def bandnoise(rng, n, std, lo, hi, fs=1000.0):
    w = rng.standard_normal(n)
    f = np.fft.rfftfreq(n, 1 / fs)
    W = np.fft.rfft(w); W[(f < lo) | (f > hi)] = 0
    x = np.fft.irfft(W, n)
    return x * std / x.std()

def case(name):
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    veh = "sedan"; kw = {}; dur = 90; rate = 100; imu_only = name.startswith("i_")
    an, rn, vib, ab, rb, xs = 0.05, 0.002, 0.0, 0.0, 0.0, 0.0
    camdrop = imudrop = None; args = ["--sensors", "both"] if name.startswith("f_") else []
    p = name[2:].split("_s")[0]
    if p == "base": pass
    elif p.startswith("hz"): rate = int(p[2:])
    elif p.startswith("ay"): an = float(p[2:])
    elif p == "vib": vib = 4.5
    elif p == "vib1k": vib = 4.5; rate = 1000
    elif p == "vib200": vib = 4.5; rate = 200
    elif p.startswith("yawn"): rn = float(p[4:])
    elif p.startswith("abias"): ab = float(p[5:])
    elif p.startswith("rbias"): rb = float(p[5:])
    elif p.startswith("mount"): xs = float(p[5:])
    elif p == "bankvar": kw["bank"] = lambda t: 0.05 * math.sin(2 * math.pi * t / 30.0)
    elif p.startswith("bank"): kw["bank"] = float(p[4:])
    elif p == "compact12": veh = "compact"; kw = dict(v0=12, dv=1.0)
    elif p == "compact20": veh = "compact"; kw = dict(v0=20)
    elif p == "suv35": veh = "suv"; kw = dict(v0=35)
    elif p == "sedan40": kw = dict(v0=40, dv=1.0)
    elif p == "gentle": kw = dict(ay_max=1.5, dither=0.001, v0=33)
    elif p == "aggr": kw = dict(ay_max=7.5, v0=28)
    elif p == "suvaggr": veh = "suv"; kw = dict(ay_max=7.0, v0=25)
    elif p == "camdrop": camdrop = (40.0, 48.0)
    elif p == "imudrop": imudrop = (40.0, 48.0)
    elif p == "imudrop10": imudrop = (30.0, 40.0); an = 0.3
    elif p == "bias": ab, rb = 0.3, 0.005
    elif p == "allbias": ab, rb, xs, an = -0.3, -0.005, 1.2, 0.3
    elif p == "vibbias": vib, ab = 4.5, 0.2
    else: raise SystemExit("unknown " + name)
    out, truth = simulate(veh, dur, rng, log_rate=1000.0, imu=True, imu_noise=(0.0, 0.0), **kw)
    n = len(out["t"])
    ay = out["_ay"] + xs * out["_rdot"] + ab
    if vib: ay = ay + bandnoise(rng, n, vib, 10.0, 60.0)
    r = out["_r"] + rb
    k = int(round(1000 / rate))
    keep = np.arange(0, n, k)
    o = {c: out[c][keep] for c in ("t", "vx", "delta", "kappa")}
    # camera frames: move each to the next kept row
    for c in ("e1", "e2"):
        a = np.full(len(keep), np.nan)
        j = np.flatnonzero(np.isfinite(out[c]))
        jj = np.minimum((j + k - 1) // k, len(keep) - 1)
        a[jj] = out[c][j]
        o[c] = a
    o["yaw_rate"] = r[keep] + rn * rng.standard_normal(len(keep))
    o["ay"] = ay[keep] + an * rng.standard_normal(len(keep))
    o["ax"] = out["ax"][keep]
    for c in ("true_alpha_f", "true_alpha_r", "true_Fyf", "true_Fyr", "true_vy"):
        o[c] = out[c][keep]
    t = o["t"]
    if camdrop:
        s = (t >= camdrop[0]) & (t < camdrop[1]); o["e1"][s] = np.nan; o["e2"][s] = np.nan
    if imudrop:
        s = (t >= imudrop[0]) & (t < imudrop[1]); o["ay"][s] = np.nan; o["yaw_rate"][s] = np.nan
    if imu_only:
        for c in ("e1", "e2", "kappa"): o.pop(c)
    write_csv(f"logs/{name}.csv", o)
    json.dump(vehicle_json(veh, rng), open(f"logs/{name}.json", "w"))
    json.dump(truth, open(f"logs/{name}.truth.json", "w"))
    open(f"logs/{name}.args", "w").write(" ".join(args))

for nm in sys.argv[1:]:
    case(nm); print("made", nm, flush=True)
