"""``benchmarks/bench_independent_sweep.py``: logs of a generator that does not import this package, estimated
with defaults beside the joint UKF on the same rows (one of its twelve logs in the default run)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_independent_sweep.py"


def test_an_independent_log_is_estimated_and_scored_beside_the_ukf(tmp_path):
    """Case 1 (60 s: a sedan at 26 m/s, 60 Hz camera, 100 Hz rows, 11 ms latency, a smooth steering): -0.01 /
    -0.02 %, the band holding the truth (+1.01 / +1.55 % before the smooth-steering rule, 3ff7138)."""
    out = tmp_path / "sweep.json"
    proc = subprocess.run([sys.executable, str(BENCH), "--cases", "1", "--out", str(out), "--no-progress"],
                          capture_output=True, text=True, timeout=600)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    printed, written = json.loads(proc.stdout), json.loads(out.read_text())
    assert printed["cases"] == written["cases"] and [r["name"] for r in written["cases"]] == ["sw01"]
    assert not list(tmp_path.glob(".*.tmp")), "atomic write left a temporary file"
    for rec in written["cases"]:
        obs = rec["observer"]
        assert obs["verdict"] == "identified", rec["name"]
        assert all(abs(e) < 0.5 for e in obs["stiffness_error_pct"]), (rec["name"], obs["stiffness_error_pct"])
        assert obs["steering_hold"]["smooth"] and obs["steering_hold"]["reported"] is None, obs["steering_hold"]
        assert all(obs["covered_2sigma"]), (rec["name"], obs)
        assert len(rec["ukf"]["stiffness_error_pct"]) == 2, rec["ukf"]
    summary = written["observer"]
    assert summary["axles"] == 2 and summary["band_coverage"] == 1.0
    assert summary["abs_stiffness_error_pct"]["worst"] < 0.5
