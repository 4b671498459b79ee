import json, sys, os
n, rc, dt = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]); tag = sys.argv[4] if len(sys.argv) > 4 else ""
tr = json.load(open(f"logs/{n}.truth.json"))
line = f"{n+tag:16s} rc={rc} {dt:6.1f}s "
p = f"runs/{n}{tag}/metrics.json"
if rc != 0 or not os.path.exists(p):
    err = open(f"runs/{n}{tag}.err").read().strip().splitlines()
    line += "ERR: " + (err[-1][:200] if err else "")
else:
    m = json.load(open(p)); s = m["summary"]
    line += f"{s.get('sensors')} {s.get('verdict')} "
    for a, k in (("F", "Cf_tire"), ("R", "Cr_tire")):
        v = s.get(f"stiffness_{'front' if a=='F' else 'rear'}_N_per_rad"); b = s.get(f"stiffness_{'front' if a=='F' else 'rear'}_2sigma_N_per_rad")
        t = tr[k]
        if b is None: line += f"{a}: - "; continue
        vs = f"{100*(v/t-1):+.1f}%" if v is not None else "None"
        cov = b[0] <= t <= b[1]
        line += f"{a}:{vs}[{100*(b[0]/t-1):+.1f},{100*(b[1]/t-1):+.1f}]{'C' if cov else 'MISS'} "
    ss = m.get("reference_scores", {}).get("sideslip_rmse_deg", {})
    rep = ss.get("reported_blend", {}).get("whole"); kf = ss.get("linear_kf_baseline", {}).get("whole")
    if rep is not None and kf is not None:
        line += f"beta rep {rep:.3f} kf {kf:.3f} deg{' WORSE' if rep > kf else ''} "
    elif ss: line += "beta " + ",".join(f"{k}:{v.get('whole'):.3f}" for k, v in ss.items() if isinstance(v, dict) and v.get('whole') is not None)
    if not ss:
        import numpy as np
        e = np.genfromtxt(f"runs/{n}{tag}/estimates.csv", delimiter=",", names=True)
        l = np.genfromtxt(f"logs/{n}.csv", delimiter=",", names=True)
        if "vy_hat" in e.dtype.names and len(e) == len(l):
            b = np.degrees(np.arctan2(e["vy_hat"], l["vx"]) - np.arctan2(l["true_vy"], l["vx"]))
            line += f"beta(vy_hat) {np.sqrt(np.nanmean(b**2)):.3f} deg "
    if s.get("model_error_detected"): line += "MED "
print(line)
