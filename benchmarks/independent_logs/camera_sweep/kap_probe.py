import numpy as np, time
from tire_learning_env.observer import ObserverConfig, build_observer
from tire_learning_env.params import CameraParams, VehicleParams
from tire_learning_env.simulation import simulate
V = VehicleParams()
log = simulate("lane_changes", 30.0, camera=CameraParams.paper_noise(rate=20.0), seed=1)
s = log.sensors
print(len(s["t"]), log.dt, np.isfinite(s["e1"]).sum())
blank = dict(s); k = s["kappa"].copy(); k[~np.isfinite(s["e1"])] = np.nan; blank["kappa"] = k
for name, cols in (("full", s), ("blank", blank)):
    t0=time.time()
    obs = build_observer(V, CameraParams(rate=20.0), ObserverConfig(), physics_dt=log.dt)
    tr = obs.run(cols)
    print(name, time.time()-t0, np.sqrt(np.nanmean(tr.innovation[:, :2]**2, axis=0)), obs.cornering_stiffness())
