"""Make a named case: python mk.py NAME -> logs/NAME.csv (+ NAME.json vehicle) and truth in NAME.truth.json"""
import json, sys, math, zlib
import numpy as np
from gen import *

def case(name):
    rng = np.random.default_rng(abs(hash(name)) % 2**32)
    veh = "sedan"; kw = {}; wkw = {}; vj = True; drop_cols = []
    dur = 120
    if name == "base_sedan": pass
    elif name == "compact_15": veh = "compact"; kw = dict(v0=15)
    elif name == "suv_32": veh = "suv"; kw = dict(v0=32)
    elif name == "compact_30_60hz_unif": veh = "compact"; kw = dict(v0=30, cam_rate=60, cam_noise=("uniform", 0.02, math.radians(1.0)), log_rate=60)
    elif name == "suv_12_10hz": veh = "suv"; kw = dict(v0=12, dv=1, cam_rate=10, latency=0.15)
    elif name == "sedan_jitter_t0": kw = dict(t0=1.7e9, jitter=0.3)
    elif name == "short20": dur = 20
    elif name == "long600": dur = 600
    elif name == "rows200_cam15": kw = dict(log_rate=200, cam_rate=15)
    elif name == "reorder_extra": wkw = dict(order="rev", extra=True)
    elif name == "reverse_start": kw = dict(reverse=6.0)
    elif name == "standstill": kw = dict(standstill=(5.0, 5.0))
    elif name == "straight": kw = dict(road_kind="straight")
    elif name == "imu_only": drop_cols = ["e1", "e2", "kappa"]
    elif name == "no_imu": kw = dict(imu=False)
    elif name == "freeze": kw = dict(freeze=(40.0, 70.0))
    elif name == "integer_crlf": wkw = dict(crlf=True, trailing_empty=True, integer=("vx",))
    elif name == "steer_deg": pass
    elif name == "no_vehicle": vj = False
    else: raise SystemExit("unknown " + name)
    out, truth = simulate(veh, dur, rng, **kw)
    for c in drop_cols: out.pop(c)
    if name == "steer_deg": out["delta"] = np.degrees(out["delta"])
    if name == "integer_crlf": out["vx"] = np.round(out["vx"])
    order = None
    extra = None
    if wkw.get("order") == "rev":
        order = list(reversed(list(out)))
    if wkw.get("extra"):
        extra = {"gps_lat": 48.1 + np.zeros(len(out["t"])), "brake": np.zeros(len(out["t"]))}
    write_csv(f"logs/{name}.csv", out, order=order, extra=extra, crlf=wkw.get("crlf", False),
              trailing_empty=wkw.get("trailing_empty", False), integer=wkw.get("integer", ()))
    if vj:
        json.dump(vehicle_json(veh, rng), open(f"logs/{name}.json", "w"))
    json.dump(truth, open(f"logs/{name}.truth.json", "w"))


def case2(name):
    rng = np.random.default_rng(abs(hash(name)) % 2**32)
    veh = "sedan"; kw = {}; dur = 120; post = None; drop_cols = []
    if name == "reverse_start2": kw = dict(reverse=6.0)
    elif name == "steer_deg_straight": kw = dict(road_kind="straight"); post = lambda o: o.__setitem__("delta", np.degrees(o["delta"]))
    elif name == "steer_deg_compact": veh = "compact"; kw = dict(v0=13, dv=1.0); post = lambda o: o.__setitem__("delta", np.degrees(o["delta"]))
    elif name == "kmh_city": veh = "compact"; kw = dict(v0=13, dv=1.0); post = lambda o: o.__setitem__("vx", o["vx"] * 3.6)
    elif name == "imu_standstill": kw = dict(standstill=(5.0, 5.0)); drop_cols = ["e1", "e2", "kappa"]
    elif name == "imu_jitter": kw = dict(jitter=0.3, t0=1.7e9); drop_cols = ["e1", "e2", "kappa"]
    elif name == "kappa_nan": post = lambda o: o["kappa"].__setitem__(~np.isfinite(o["e1"]), np.nan)
    elif name == "delta_flip": post = lambda o: o.__setitem__("delta", -o["delta"])
    elif name == "e1_flip": post = lambda o: o.__setitem__("e1", -o["e1"])
    elif name == "aggressive": kw = dict(ay_max=7.5, v0=28)
    elif name == "latency250": kw = dict(latency=0.25)
    elif name == "noisy10hz": veh = "compact"; kw = dict(v0=14, cam_rate=10, cam_noise=("gaussian", 0.02, math.radians(1.0)), drop=0.2)
    elif name == "cam_rows30": kw = dict(log_rate=1000/33, cam_rate=1000/33, latency=0.0, drop=0.0)
    elif name == "gap5s":
        def post(o):
            keep = ~((o["t"] > 50) & (o["t"] < 55))
            for k in o: o[k] = o[k][keep]
    elif name == "vx_nan_rows": post = lambda o: o["vx"].__setitem__(slice(500, 503), np.nan)
    elif name == "imu_only_suv": veh = "suv"; kw = dict(v0=30); drop_cols = ["e1", "e2", "kappa"]
    else: raise SystemExit("unknown " + name)
    out, truth = simulate(veh, dur, rng, **kw)
    for c in drop_cols: out.pop(c)
    if post: post(out)
    write_csv(f"logs/{name}.csv", out)
    json.dump(vehicle_json(veh, rng), open(f"logs/{name}.json", "w"))
    json.dump(truth, open(f"logs/{name}.truth.json", "w"))


def case3(name):
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    veh = "sedan"; kw = {}; dur = 120; post = None; drop_cols = []
    if name == "imu_gap5s":
        drop_cols = ["e1", "e2", "kappa"]
        def post(o):
            keep = ~((o["t"] > 50) & (o["t"] < 55))
            for k in o: o[k] = o[k][keep]
    elif name == "imu_reverse": kw = dict(reverse=6.0); drop_cols = ["e1", "e2", "kappa"]
    else: raise SystemExit("unknown " + name)
    out, truth = simulate(veh, dur, rng, **kw)
    for c in drop_cols: out.pop(c)
    if post: post(out)
    write_csv(f"logs/{name}.csv", out)
    json.dump(vehicle_json(veh, rng), open(f"logs/{name}.json", "w"))
    json.dump(truth, open(f"logs/{name}.truth.json", "w"))

if __name__ == "__main__":
    import os; os.makedirs("logs", exist_ok=True)
    for n in sys.argv[1:]:
        try: case(n)
        except SystemExit:
            try: case2(n)
            except SystemExit: case3(n)
