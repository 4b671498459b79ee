import json, sys, numpy as np
from gen import *
for d in (0.5, 1.5, 3.0, 8.0):
    rng = np.random.default_rng(int(d * 10))
    out, truth = simulate("sedan", d, rng, v0=25)
    vj = vehicle_json("sedan", rng)
    for name, o in ((f"short{d}", out), (f"imushort{d}", {k: v for k, v in out.items() if k not in ("e1", "e2", "kappa")})):
        write_csv(f"logs/{name}.csv", o); json.dump(vj, open(f"logs/{name}.json", "w")); json.dump(truth, open(f"logs/{name}.truth.json", "w"))
