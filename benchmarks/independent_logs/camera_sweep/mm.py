import json, sys, numpy as np
from gen import *
specs = {"relax05": dict(relax=0.5), "relax10": dict(relax=1.0), "camoff1": dict(cam_offset=1.0), "camoff2": dict(cam_offset=2.0), "mm_ref": {}}
for name in sys.argv[1:]:
    rng = np.random.default_rng(31)
    out, truth = simulate("sedan", 120, rng, **specs[name])
    vj = vehicle_json("sedan", rng)
    write_csv(f"logs/{name}.csv", out); json.dump(vj, open(f"logs/{name}.json", "w")); json.dump(truth, open(f"logs/{name}.truth.json", "w"))
