import json, numpy as np, math
from gen import *
rng = np.random.default_rng(21)
out, truth = simulate("sedan", 120, rng)
vj = vehicle_json("sedan", rng)
o = dict(out)
for k in ("e1", "e2"):
    x = o[k].copy(); idx = np.flatnonzero(np.isfinite(x))
    # sample-and-hold: each row carries the latest frame (CAN resampled to a fixed rate)
    j = np.searchsorted(idx, np.arange(len(x)), side="right") - 1
    y = np.where(j >= 0, x[idx[np.maximum(j, 0)]], np.nan); o[k] = y
write_csv("logs/hold_ref.csv", out); write_csv("logs/hold.csv", o)
for n in ("hold_ref", "hold"):
    json.dump(vj, open(f"logs/{n}.json", "w")); json.dump(truth, open(f"logs/{n}.truth.json", "w"))
rng = np.random.default_rng(22)
out, truth = simulate("suv", 300, rng, v0=28, log_rate=1000, cam_rate=30)
write_csv("logs/khz300.csv", out); json.dump(vehicle_json("suv", rng), open("logs/khz300.json", "w")); json.dump(truth, open("logs/khz300.truth.json", "w"))
