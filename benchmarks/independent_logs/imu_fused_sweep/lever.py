import sys, json, numpy as np, pandas as pd
for n in sys.argv[1:]:
    e = pd.read_csv(f"runs/{n}/estimates.csv"); l = pd.read_csv(f"logs/{n}.csv"); v = json.load(open(f"logs/{n}.json"))
    t = l.t.values; dt = np.median(np.diff(t))
    r = l.yaw_rate.values; ay = l.ay.values
    # smoothed derivative of r (central diff over 5 samples + moving avg)
    k = max(1, int(round(0.05 / dt)))
    rs = np.convolve(r, np.ones(2*k+1)/(2*k+1), mode="same")
    rd = np.gradient(rs, t)
    ayh = (e.Fyf_hat.values*np.cos(l.delta.values) + e.Fyr_hat.values)/v["m"]
    ays = np.convolve(ay, np.ones(2*k+1)/(2*k+1), mode="same")
    res = ays - ayh
    ok = np.isfinite(res) & np.isfinite(rd); ok[:200] = False; ok[-50:] = False
    A = np.c_[rd[ok], np.ones(ok.sum())]
    c, *_ = np.linalg.lstsq(A, res[ok], rcond=None)
    print(n, "lever %.3f m  res std %.3f  rdot std %.3f" % (c[0], res[ok].std(), rd[ok].std()))
