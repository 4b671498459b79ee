import json, sys, warnings, numpy as np
warnings.simplefilter("ignore")
from tire_learning_env.io import read_log, read_vehicle
from tire_learning_env.observer import estimate, ObserverConfig
for n in sys.argv[1:]:
    log = read_log(f"logs/{n}.csv"); veh = read_vehicle(f"logs/{n}.json")
    r = estimate(log.sensors, veh, config=ObserverConfig(sensors="camera"))
    b = r.observer.basis
    G, _ = r.stiffness_functionals()
    nt = b.weight_lower.size
    lo = np.r_[b.weight_lower.ravel(), np.zeros(G.shape[1] - nt)]; hi = np.r_[b.weight_upper.ravel(), np.zeros(G.shape[1] - nt)]
    kmax = np.array([veh.Cf, veh.Cr]) + np.sum(np.maximum(G * hi, G * lo), axis=1)
    kmin = np.array([veh.Cf, veh.Cr]) + np.sum(np.minimum(G * hi, G * lo), axis=1)
    k = np.array(r.cornering_stiffness()); s = np.array(r.cornering_stiffness_std())
    tr = json.load(open(f"logs/{n}.truth.json"))
    print(n, r.verdict, "k", k.round(0), "2s", (2*s).round(0), "kmax", kmax.round(0), "kmin", kmin.round(0), "truth", tr["Cf_tire"], tr["Cr_tire"], "(kmax-k)/2s", ((kmax-k)/(2*s)).round(2))
    w = np.asarray(r.weights)[:nt]
    print("   w/hi", np.round(w / np.where(w > 0, hi[:nt], -lo[:nt]), 3).reshape(2, -1)[:, 2:16])
    print("   G", np.round(G[:, :nt] / np.abs(G[:, :nt]).max(axis=1, keepdims=True), 2)[[0], 2:16], np.round(G[1, nt//2 + 2: nt//2 + 16] / np.abs(G[1]).max(), 2))
