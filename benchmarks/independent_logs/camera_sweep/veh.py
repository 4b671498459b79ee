import json, sys, math, numpy as np
import gen
from gen import *
gen.VEHICLES.update({
    "race": dict(m=800.0, Iz=900.0, lf=1.15, lr=1.25, Cax_f=90000.0, Cax_r=120000.0, mu=1.3, C=1.5, E=-0.5),
    "van": dict(m=3500.0, Iz=8000.0, lf=1.6, lr=2.1, Cax_f=160000.0, Cax_r=240000.0, mu=0.85, C=1.3, E=0.2),
    "oversteer": dict(m=1400.0, Iz=2200.0, lf=1.35, lr=1.25, Cax_f=110000.0, Cax_r=90000.0, mu=1.0, C=1.4, E=-0.2),
})
cfg = {"race30": ("race", dict(v0=30, ay_max=6)), "van20": ("van", dict(v0=20)), "over25": ("oversteer", dict(v0=25)),
       "slow8": ("compact", dict(v0=8, dv=0.5))}
for name in sys.argv[1:]:
    veh, kw = cfg[name]
    rng = np.random.default_rng(zlib.crc32(name.encode()) if False else 77)
    out, truth = simulate(veh, 120, rng, **kw)
    write_csv(f"logs/{name}.csv", out); json.dump(vehicle_json(veh, rng), open(f"logs/{name}.json", "w")); json.dump(truth, open(f"logs/{name}.truth.json", "w"))
