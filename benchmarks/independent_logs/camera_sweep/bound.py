import json, sys, warnings, numpy as np
warnings.simplefilter("ignore")
from tire_learning_env.io import read_log, read_vehicle
from tire_learning_env.observer import estimate, ObserverConfig
n = sys.argv[1]
log = read_log(f"logs/{n}.csv"); veh = read_vehicle(f"logs/{n}.json")
r = estimate(log.sensors, veh, config=ObserverConfig(sensors="camera"))
b = r.observer.basis
w = np.asarray(r.weights).ravel()[: b.weight_lower.size].reshape(b.weight_lower.shape)
print("verdict", r.verdict, r.cornering_stiffness())
print("lower", np.round(b.weight_lower, 3)); print("upper", np.round(b.weight_upper, 3)); print("w", np.round(w, 3))
print("centres deg", np.round(np.degrees(0.5*(b.lower+b.upper)), 2))
