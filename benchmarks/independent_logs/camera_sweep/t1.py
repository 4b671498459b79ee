import time, numpy as np, math
from gen import *
rng = np.random.default_rng(1)
for veh, v0 in (("compact", 15), ("sedan", 25), ("suv", 35)):
    t0 = time.time()
    out, truth = simulate(veh, 60, rng, v0=v0)
    te = out["true_alpha_f"]
    e1 = out["e1"]
    print(veh, v0, "time %.1f" % (time.time()-t0), "max|e1| %.2f" % np.nanmax(abs(e1)), "max af deg %.2f ar %.2f" % (np.degrees(abs(te).max()), np.degrees(abs(out["true_alpha_r"]).max())), "max ay %.2f" % abs(out["ay"]).max(), "max delta", abs(out["delta"]).max())
