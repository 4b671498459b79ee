import json, sys, math, numpy as np
from gen import *
rng = np.random.default_rng(31)
out, truth = simulate("sedan", 120, rng)
vj = vehicle_json("sedan", rng)
def interp_cam(o):
    for k in ("e1", "e2"):
        x = o[k]; f = np.isfinite(x); o[k] = np.interp(o["t"], o["t"][f], x[f])
def async_cam(o):
    f = np.flatnonzero(np.isfinite(o["e2"]))
    e2 = np.full(len(o["t"]), np.nan); g = np.minimum(f + 3, len(o["t"]) - 1); e2[g] = o["e2"][f]; o["e2"] = e2
variants = {
    "async": async_cam,
    "kappa0": lambda o: o.__setitem__("kappa", o["kappa"] * 0.0),
    "e2bias05": lambda o: o.__setitem__("e2", o["e2"] + math.radians(0.5)),
    "e2bias1": lambda o: o.__setitem__("e2", o["e2"] + math.radians(1.0)),
    "e1bias10": lambda o: o.__setitem__("e1", o["e1"] + 0.10),
    "dbias": lambda o: o.__setitem__("delta", o["delta"] + 0.003),
    "vscale": lambda o: o.__setitem__("vx", o["vx"] * 1.03),
    "caminterp": interp_cam,
    "noisy5cm": lambda o: (o.__setitem__("e1", o["e1"] + 0.05 * rng.standard_normal(len(o["t"]))), o.__setitem__("e2", o["e2"] + math.radians(2) * rng.standard_normal(len(o["t"])))),
}
for name in sys.argv[1:]:
    o = {k: v.copy() for k, v in out.items()}
    variants[name](o)
    write_csv(f"logs/{name}.csv", o); json.dump(vj, open(f"logs/{name}.json", "w")); json.dump(truth, open(f"logs/{name}.truth.json", "w"))
