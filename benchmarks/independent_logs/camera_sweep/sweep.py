"""Random case ``i`` of the independent generator's camera sweep: ``python sweep.py I`` writes logs/swII.csv,
.json (vehicle file, stiffness 5-15 % off) and .truth.json; ``sweep_case(i)`` returns them (used by
``benchmarks/bench_independent_sweep.py``). Seeded by ``1000 + i``: the same case on every machine."""
import json, math, sys, zlib
import numpy as np
from gen import *


def sweep_case(i):
    """``(name, log columns, truth, vehicle file dict)`` of case ``i``."""
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
    vj = vehicle_json(veh, rng)
    truth.update(veh=veh, v0=v0, cam_rate=cam_rate, noise=[kind, s1, math.degrees(s2)], lat=lat, log_rate=log_rate, dur=dur,
                 drop=drop, road=road)
    return f"sw{i:02d}", out, truth, vj


if __name__ == "__main__":
    name, out, truth, vj = sweep_case(int(sys.argv[1]))
    write_csv(f"logs/{name}.csv", out)
    json.dump(vj, open(f"logs/{name}.json", "w"))
    json.dump(truth, open(f"logs/{name}.truth.json", "w"))
    print(name, truth)
