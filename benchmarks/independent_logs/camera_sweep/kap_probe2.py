import numpy as np, time, warnings
from tire_learning_env.observer import ObserverConfig, estimate
from tire_learning_env.params import CameraParams, VehicleParams
from tire_learning_env.simulation import simulate
V = VehicleParams()
log = simulate("study1", 40.0, camera=CameraParams.paper_noise(rate=20.0), seed=1)
s = log.sensors
keep = (np.arange(len(s["t"])) % 10 == 0) | np.isfinite(s["e1"])
s = {k: np.asarray(v)[keep] for k, v in s.items()}
print(len(s["t"]), np.isfinite(s["e1"]).sum(), np.abs(s["kappa"]).max())
blank = dict(s); k = s["kappa"].copy(); k[~np.isfinite(s["e1"])] = np.nan; blank["kappa"] = k
for name, cols in (("full", s), ("blank", blank)):
    t0=time.time()
    r = estimate(cols, V)
    print(name, time.time()-t0, r.verdict, r.cornering_stiffness(), r.cornering_stiffness_std())
