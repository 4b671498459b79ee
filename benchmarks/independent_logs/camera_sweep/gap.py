import json, sys, numpy as np
from gen import *
for seed in (7, 8):
    rng = np.random.default_rng(seed)
    out, truth = simulate("sedan", 120, rng)
    vj = vehicle_json("sedan", rng)
    for name, gap in ((f"g{seed}_nogap", None), (f"g{seed}_gap5", (50, 55)), (f"g{seed}_gap1", (50, 51))):
        o = dict(out)
        if gap:
            keep = ~((o["t"] > gap[0]) & (o["t"] < gap[1]))
            o = {k: v[keep] for k, v in o.items()}
        write_csv(f"logs/{name}.csv", o); json.dump(vj, open(f"logs/{name}.json", "w")); json.dump(truth, open(f"logs/{name}.truth.json", "w"))
