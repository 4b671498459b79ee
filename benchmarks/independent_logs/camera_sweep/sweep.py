import json, math, sys, zlib
import numpy as np
from gen import *
i = int(sys.argv[1])
rng = np.random.default_rng(1000 + i)
veh = ["compact", "sedan", "suv"][i % 3]
v0 = float(rng.uniform(12, 35))
cam_rate = float(rng.choice([10, 15, 20, 30, 60]))
kind = str(rng.choice(["gaussian", "uniform"]))
s1 = float(rng.uniform(0.005, 0.02)); s2 = math.radians(float(rng.uniform(0.05, 1.0)))
lat = float(rng.uniform(0.0, 0.15))
log_rate = float(rng.choice([50, 100, 200]))
dur = float(rng.choice([60, 120, 300]))
drop = float(rng.uniform(0, 0.15))
road = str(rng.choice(["mixed", "mixed", "lc", "arc"]))
out, truth = simulate(veh, dur, rng, road_kind=road, v0=v0, log_rate=log_rate, cam_rate=cam_rate, latency=lat,
                      cam_noise=(kind, s1, s2), drop=drop, imu=bool(rng.uniform() < 0.5))
name = f"sw{i:02d}"
write_csv(f"logs/{name}.csv", out)
json.dump(vehicle_json(veh, rng), open(f"logs/{name}.json", "w"))
truth.update(veh=veh, v0=v0, cam_rate=cam_rate, noise=[kind, s1, math.degrees(s2)], lat=lat, log_rate=log_rate, dur=dur, drop=drop, road=road)
json.dump(truth, open(f"logs/{name}.truth.json", "w"))
print(name, truth)
