import sys, numpy as np, warnings
warnings.simplefilter("ignore")
from tire_learning_env.io import read_log
from tire_learning_env.io import units as U
for n in sys.argv[1:]:
    log = read_log(f"logs/{n}.csv", check_units=False)
    c = {**log.sensors}
    t, vx, e1, e2 = c["t"], c["vx"], c["e1"], c["e2"]
    frame = np.isfinite(e1) & np.isfinite(e2)
    tf, e1f, e2f, vf = t[frame], e1[frame], e2[frame], vx[frame]
    big_i = U._integral(tf, vf * e2f); dist = U._integral(tf, vf); idx = U._windows(tf, 1.0)
    de1, di, dd = np.diff(e1f[idx]), np.diff(big_i[idx]), np.diff(dist[idx])
    print(n, "cam: sum di2 %.3g" % np.sum(di**2), "k,r2", U._slope(de1, di, dd))
    e2i = np.interp(t, tf, e2f)
    heading = e2i + U._integral(t, vx * np.nan_to_num(c["kappa"]))
    steer = U._integral(t, vx * c["delta"]); idx = U._windows(t, 2.0)
    dh, ds = np.diff(heading[idx]), np.diff(steer[idx])
    print("   steer: sum dh2 %.3g" % np.sum(dh**2), "invL,r2", U._slope(dh, ds))
