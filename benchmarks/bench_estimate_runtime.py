"""Runtime of :func:`~tire_learning_env.observer.estimate` with default settings (issue 15's
target: a 30 min, 100 Hz log in <= 10 s and <= 500 MB), printed as JSON.

Two logs, each estimated in its own process (so the peak memory is that log's):

- ``study1_60s_1kHz``: the Study 1 truth (60 s, rows and a noise-free camera at 1 kHz), the
  nominal vehicle right;
- ``lane_changes_30min_100Hz``: ``simulate("lane_changes", 1800, physics_rate=100)`` with the
  paper's camera noise at 20 Hz, the nominal stiffness +8 % / -6 % off.

Per log: the wall time of each step (:attr:`~tire_learning_env.observer.EstimationResult.runtime_s`),
the process CPU time, rows per second, the fixed-weight passes of the offline fit and the
latency profile (count, seconds), the peak resident memory (``ru_maxrss``), the time of the curve
bands the ``estimate`` command computes after the estimate (``bands_s``: learned slip range, curve
file, plot; the peak after them ``peak_after_bands_MB``), for the 30 min log the whole ``tire-learning estimate``
command run on it as a user's CSV (``command_wall_s``, ``command_peak_MB``, ``csv_read_s``) and, so that speed
is never bought with accuracy, the estimated stiffness, its two-sigma band and its error
against the truth. BLAS runs single-threaded (``_bench_common``), as everywhere in the benchmarks.

Run: ``python benchmarks/bench_estimate_runtime.py`` (``--log NAME`` for one log).
"""

from __future__ import annotations

import argparse
import inspect
import json
import resource
import subprocess
import sys
import time

from _bench_common import emit

LOGS = ("study1_60s_1kHz", "lane_changes_30min_100Hz")
TARGET = {"wall_s": 10.0, "peak_MB": 500.0}


def _make_log(name: str):
    from tire_learning_env.params import CameraParams
    from tire_learning_env.simulation import simulate
    from tire_learning_env.studies import _simulate, study_spec

    if name == "study1_60s_1kHz":
        spec = study_spec(1)
        log, _ = _simulate(spec)
        return log.sensors, log.vehicle, spec.nominal_vehicle
    log = simulate("lane_changes", 1800.0, camera=CameraParams.paper_noise(rate=20.0), physics_rate=100.0)
    v = log.vehicle
    return log.sensors, v, v.replace(Cf=v.Cf * 1.08, Cr=v.Cr * 0.94)


def _bands(res) -> float:
    """Wall time [s] of the curve bands ``tire-learning estimate`` computes from the result after the estimate
    (the learned slip range, the curve file's 161-point grid and the plot's band on every 4th point of its 401-point
    grid, per axle: Newey-West sandwiches of 926 directions over the log's scores, 1526 before the plot drew its band
    through 101 points; since 2026-12-08 a quadratic form each in the scores' long-run covariance where the bandwidth
    is found within a few lags, :class:`~tire_learning_env.observer.longrun.ScoreLongRun`, else two FFTs each)."""
    import math

    import numpy as np

    from tire_learning_env.metrics import excited_range

    t0 = time.perf_counter()
    res.learned_slip_range()
    for i, axle in enumerate(("front", "rear")):
        res.axle_force_std(np.radians(np.linspace(-8, 8, 161)), axle)
        lo, hi = (math.degrees(v) for v in excited_range(res.trace.slip[:, i]))
        span = 1.6 * max(abs(lo), abs(hi), 0.2)
        res.axle_force_std(np.radians(np.linspace(-span, span, 401))[::4], axle)
    return time.perf_counter() - t0


def _command(sensors: dict, nominal) -> dict:
    """What a user times: the log written as a CSV and a vehicle file, ``tire-learning estimate LOG --vehicle V
    --out DIR`` in its own process (reading, the estimate, the bands, estimates.csv, tire_curves.csv, the plot).
    Its wall time, its peak resident memory, and the CSV read alone (:func:`~tire_learning_env.io.read_log`, here)."""
    import os
    import tempfile

    from tire_learning_env.io import read_log, write_log

    with tempfile.TemporaryDirectory() as d:
        log, veh = os.path.join(d, "log.csv"), os.path.join(d, "vehicle.json")
        write_log(log, sensors)
        with open(veh, "w") as fh:
            json.dump({k: float(getattr(nominal, k)) for k in ("m", "Iz", "lf", "lr", "Cf", "Cr")}, fh)
        t0 = time.perf_counter()
        read_log(log)
        read_s = time.perf_counter() - t0
        # the command's own peak: VmHWM of its process image, read as it exits (a child's ru_maxrss starts from
        # this process's resident set at the spawn, which is the estimate's peak here)
        peak_file = os.path.join(d, "peak_kB")
        code = ("import sys\nfrom tire_learning_env.cli import main\ntry:\n    rc = main()\nfinally:\n"
                "    hwm = [l for l in open('/proc/self/status') if l.startswith('VmHWM:')]\n"
                f"    open({peak_file!r}, 'w').write(hwm[0].split()[1] if hwm else '')\nsys.exit(rc)\n")
        cmd = [sys.executable, "-c", code, "estimate", log, "--vehicle", veh, "--out", os.path.join(d, "out")]
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        wall = time.perf_counter() - t0
        with open(peak_file) as fh:
            text = fh.read().strip()
    return {"command_wall_s": round(wall, 3), "command_peak_MB": round(int(text) / 1024.0, 1) if text else None,
            "csv_read_s": round(read_s, 3)}  # fmt: skip


def run_one(name: str, command: bool = False) -> dict:
    """Estimate one log in this process; the figures of :data:`LOGS`."""
    import numpy as np

    import tire_learning_env.observer._kernel as K
    from tire_learning_env.observer import estimate

    sensors, truth, nominal = _make_log(name)
    passes: list = []
    orig = K.run_rows
    # the settings argument by name: its position moves when the kernel gains an argument (f385b80 added
    # ``release`` before it, and this benchmark read the weight box's gains as the settings)
    settings_at = list(inspect.signature(orig.py_func).parameters).index("S")

    def timed(*a):  # every pass of the compiled loop, with its row count
        t0 = time.perf_counter()
        out = orig(*a)
        passes.append((len(a[0]), int(a[settings_at].mode), time.perf_counter() - t0))
        return out

    # warm the compiled kernel (numba cache) on a short slice so that compilation is not timed
    short = {k: np.asarray(v)[:2000] for k, v in sensors.items()}
    estimate(short, nominal)
    K.run_rows = timed
    try:
        t0, c0 = time.perf_counter(), time.process_time()
        res = estimate(sensors, nominal)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    finally:
        K.run_rows = orig
    n = len(np.asarray(sensors["t"]))
    peak_estimate = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    cf, cr = res.cornering_stiffness()
    sf, sr = res.cornering_stiffness_std()
    bands_s = _bands(res)
    fixed = [p for p in passes if p[1] == K.MODE_FIXED]
    return {
        "rows": n,
        "duration_s": float(sensors["t"][-1] - sensors["t"][0]),
        "wall_s": round(wall, 3),
        "cpu_s": round(cpu, 3),
        "rows_per_s": round(n / wall, 1),
        "steps_s": {k: round(float(v), 3) for k, v in res.runtime_s.items()},
        "fixed_passes": len(fixed),
        "fixed_pass_rows": int(sum(p[0] for p in fixed)),
        "fixed_passes_s": round(sum(p[2] for p in fixed), 3),
        "us_per_row_per_pass": round(1e6 * sum(p[2] for p in fixed) / max(sum(p[0] for p in fixed), 1), 3),
        "peak_MB": round(peak_estimate, 1),
        "bands_s": round(bands_s, 3),
        "peak_after_bands_MB": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1),
        "latency_s": res.calibration.get("latency", {}).get("latency_s"),
        "offline_iterations": res.fit.iterations if res.fit is not None else None,
        "stiffness_N_per_rad": [cf, cr],
        "stiffness_2sigma_N_per_rad": [2 * sf, 2 * sr],
        "stiffness_error_pct": [100.0 * (cf / truth.Cf - 1.0), 100.0 * (cr / truth.Cr - 1.0)],
        "nominal_error_pct": [100.0 * (nominal.Cf / truth.Cf - 1.0), 100.0 * (nominal.Cr / truth.Cr - 1.0)],
        "verdict": res.verdict,
        **(_command(sensors, nominal) if command else {}),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--log", choices=LOGS, help="one log, in this process")
    ap.add_argument("--command", action="store_true",
                    help="also time the whole `tire-learning estimate` command on the log written as a CSV (the 30 min "
                         "log always, in the default run)")  # fmt: skip
    args = ap.parse_args()
    if args.log:
        print(json.dumps(run_one(args.log, command=args.command)))
        return
    out: dict = {"target_30min_100Hz": TARGET, "logs": {}}
    for name in LOGS:
        extra = ["--command"] if name == "lane_changes_30min_100Hz" else []
        p = subprocess.run([sys.executable, __file__, "--log", name, *extra], stdout=subprocess.PIPE, text=True, check=True)
        out["logs"][name] = json.loads(p.stdout.strip().splitlines()[-1])
    long = out["logs"]["lane_changes_30min_100Hz"]
    out["meets_target"] = {"wall": long["wall_s"] <= TARGET["wall_s"], "memory": long["peak_MB"] <= TARGET["peak_MB"],
                           "command_wall": long["command_wall_s"] <= TARGET["wall_s"],
                           "command_memory": long["command_peak_MB"] <= TARGET["peak_MB"]}  # fmt: skip
    emit(out)


if __name__ == "__main__":
    main()
