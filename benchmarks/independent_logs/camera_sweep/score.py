import json, sys, os
n, rc, dt = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
tr = json.load(open(f"logs/{n}.truth.json"))
line = f"{n:24s} rc={rc} {dt:6.1f}s "
p = f"runs/{n}/metrics.json"
if rc != 0 or not os.path.exists(p):
    err = open(f"runs_{n}.err").read().strip().splitlines()
    line += "ERR: " + (err[-1][:200] if err else "")
else:
    m = json.load(open(p)); s = m["summary"]
    line += f"verdict={s.get('verdict')} "
    for a, k in (("front", "Cf_tire"), ("rear", "Cr_tire")):
        v = s.get(f"stiffness_{a}_N_per_rad"); b = s.get(f"stiffness_{a}_2sigma_N_per_rad")
        t = tr[k]
        if v is None or b is None: line += f"{a}: {v} {b} "; continue
        cov = b[0] <= t <= b[1]
        line += f"{a}: {100*(v/t-1):+.1f}% band[{100*(b[0]/t-1):+.1f},{100*(b[1]/t-1):+.1f}] {'COV' if cov else 'MISS'} "
print(line)
