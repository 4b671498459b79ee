"""The generalisation benchmark (issue 15, item 5): a shortened run in the default test run, the full one slow."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_generalization.py"
FAMILIES = ("low_order_pacejka", "multi_body", "held_out")


@pytest.fixture(scope="module")
def bg():
    """``benchmarks/bench_generalization.py`` imported as a module (``benchmarks/`` is not a package)."""
    sys.path.insert(0, str(BENCH.parent))
    try:
        import bench_generalization
    finally:
        sys.path.remove(str(BENCH.parent))
    return bench_generalization


def _run(tmp_path: Path, *args: str, timeout: float) -> tuple[dict, dict, float]:
    out = tmp_path / "generalization.json"
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, str(BENCH), *args, "--out", str(out), "--no-progress"],
        capture_output=True, text=True, timeout=timeout,
    )  # fmt: skip
    wall = time.perf_counter() - t0
    assert proc.returncode == 0, proc.stderr[-3000:]
    printed = json.loads(proc.stdout)  # stdout is the JSON and nothing else
    written = json.loads(out.read_text())
    assert not list(tmp_path.glob(".*.tmp")), "atomic write left a temporary file"
    return printed, written, wall


def _check_structure(result: dict, n: int) -> None:
    assert result["benchmark"] == "generalization"
    assert result["complete"] is True
    assert set(result["families"]) == set(FAMILIES)
    assert result["families"]["held_out"]["held_out"] is True
    for fam in FAMILIES:
        block = result["families"][fam]
        assert len(block["scenarios"]) == n
        for est in ("observer", "ukf"):
            s = block[est]
            for key in ("abs_stiffness_error_pct", "curve_nrmse_pct", "slip_rmse_deg", "runtime_s", "band_coverage"):
                assert key in s
        assert "verdict_counts" in block["observer"]
        for rec in block["scenarios"]:
            assert "error" not in rec, rec.get("error")  # no crash anywhere
            for est in ("observer", "ukf"):
                assert "error" not in rec[est], rec[est].get("error")
                assert len(rec[est]["stiffness_error_pct"]) == 2
            assert rec["ukf"]["camera_given"]["source"] == "estimated from the log"


# -- issue 16: the IMU and fused families ------------------------------------------------------
EXTRA = ("imu_white", "imu_vibration_bias", "fused")
EXTRA_ESTIMATORS = {"imu_white": ("imu_observer", "linear_kf"), "imu_vibration_bias": ("imu_observer", "linear_kf"),
                    "fused": ("camera", "imu", "both")}  # fmt: skip


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    """One ``--quick --n 1`` run of the camera families and the IMU and fused ones together (one process and
    one local Ray start instead of two; each family's scenarios are sampled independently of the others):
    (printed, written, folder)."""
    folder = tmp_path_factory.mktemp("quick")
    printed, written, _ = _run(folder, "--quick", "--n", "1", "--workers", "2", "--families",
                               ",".join(FAMILIES + EXTRA), timeout=480)  # fmt: skip
    assert set(written["families"]) == set(FAMILIES + EXTRA)
    return printed, written, folder


def _only(result: dict, families: tuple) -> dict:
    """``result`` with its ``families`` block restricted to ``families``."""
    return {**result, "families": {f: b for f, b in result["families"].items() if f in families}}


def test_quick_benchmark(quick):
    printed, written, _ = quick
    assert printed == written
    _check_structure(_only(written, FAMILIES), 1)
    # scenario sampling is seeded: the same settings give the same scenarios
    scen = [r["scenario"] for fam in FAMILIES for r in written["families"][fam]["scenarios"]]
    assert all(s["duration_s"] == 12.0 and s["camera"]["rate"] <= 25.0 for s in scen)
    errors = [abs(e) for fam in FAMILIES for r in written["families"][fam]["scenarios"] for e in r["observer"]["stiffness_error_pct"]]
    errors.sort()
    median = 0.5 * (errors[len(errors) // 2 - 1] + errors[len(errors) // 2])
    assert median < 10.0, errors  # loose: 12 s logs, nominal up to 20 % off
    for fam in FAMILIES:
        obs = written["families"][fam]["observer"]
        assert obs["succeeded"] == 1
        assert obs["slip_rmse_deg"]["worst"] < 1.0  # slip is tracked (deg)
        assert 0.0 <= obs["band_coverage"]["fraction"] <= 1.0
        assert written["families"][fam]["ukf"]["succeeded"] == 1


def test_scenarios_are_seeded_and_prefix_stable(bg):
    a = [bg.sample_scenario(f, i, 15, False) for f in FAMILIES for i in range(3)]
    b = [bg.sample_scenario(f, i, 15, False) for f in FAMILIES for i in range(3)]
    assert a == b
    for s in a:
        cam = s["camera"]
        assert 10.0 <= cam["rate"] <= 100.0 and cam["noise"] in ("gaussian", "uniform")
        assert 0.005 <= cam["e1_noise"] <= 0.02 and 0.0 <= cam["latency"] <= 0.1 and 0.0 <= cam["dropout_probability"] <= 0.2
        assert 15.0 <= s["speed"]["vx"] <= 35.0
    held = [s for s in a if s["family"] == "held_out"]
    tuned = [s for s in a if s["family"] != "held_out"]
    assert {s["vehicle"] for s in held}.isdisjoint({s["vehicle"] for s in tuned})
    assert {s["road"]["kind"] for s in held}.isdisjoint({s["road"]["kind"] for s in tuned})


@pytest.mark.slow
def test_full_benchmark(tmp_path):
    _, written, _ = _run(tmp_path, timeout=3600)
    _check_structure(written, written["settings"]["n_per_family"])
    assert written["families"]["low_order_pacejka"]["observer"]["abs_stiffness_error_pct"]["median"] < 5.0


def test_quick_imu_and_fused_families(quick):
    printed, written, folder = quick
    assert printed == written and written["complete"] is True
    assert set(written["families"]) >= set(EXTRA)
    for fam in EXTRA:
        block = written["families"][fam]
        assert block["estimators"] == list(EXTRA_ESTIMATORS[fam])
        assert len(block["scenarios"]) == 1
        rec = block["scenarios"][0]
        assert "error" not in rec, rec.get("error")
        for est in EXTRA_ESTIMATORS[fam]:
            assert "error" not in rec[est], rec[est].get("error")
            assert block[est]["succeeded"] == 1
            assert len(rec[est]["stiffness_error_pct"]) == 2
            assert 0.0 <= rec[est]["sideslip_rmse_deg"] < 2.0  # tracked (deg)
        assert fam in written["target_check"]
    sc = [written["families"][f]["scenarios"][0]["scenario"] for f in EXTRA]
    assert sc[0]["rate_hz"] <= 200.0 and sc[0]["duration_s"] == 15.0 and sc[2]["duration_s"] == 12.0
    # the fused estimators ran the sensor sets they were asked for, on the same log
    assert [written["families"]["fused"]["scenarios"][0][e]["sensors_run"] for e in ("camera", "imu", "both")] == [
        "camera", "imu", "both"]  # fmt: skip
    # the IMU record keeps the observer's own passes beside the reported blend
    imu = written["families"]["imu_white"]["scenarios"][0]["imu_observer"]
    assert set(imu["sideslip_rmse_deg_by_pass"]) >= {"reported_blend", "observer_refined", "observer_online_causal"}
    md = (folder / "generalization.md").read_text()
    assert "imu_observer" in md and "both" in md


def test_imu_and_fused_scenarios_are_seeded_and_in_range(bg):
    a = [bg.sample_scenario(f, i, 15, False) for f in EXTRA for i in range(8)]
    assert a == [bg.sample_scenario(f, i, 15, False) for f in EXTRA for i in range(8)]
    for s in a:
        if s["family"] == "fused":
            assert 100.0 <= s["imu"]["rate_hz"] <= 1000.0 and s["truth"]["plant"] == "low_order_pacejka"
            continue
        assert s["vehicle"] in bg.IMU_VEHICLES and 50.0 <= s["rate_hz"] <= 1000.0
        lo, hi = s["speed"]["range"]
        assert 10.0 <= lo < hi <= 60.0
        imu = s["imu"]
        total = (imu["ay_white_std"] ** 2 + (imu["vibration"]["std"] ** 2 if imu["vibration"] else 0.0)) ** 0.5
        assert 0.2 <= total <= 5.1
        if s["family"] == "imu_white":
            assert imu["vibration"] is None and imu["ay_offset"] == 0.0 and imu["yaw_rate_offset"] == 0.0
        else:
            assert abs(imu["ay_offset"]) <= 0.5 and abs(imu["yaw_rate_offset"]) <= 0.01


def test_a_truth_that_blows_up_is_redrawn_with_the_reason_kept(bg):
    """Multi-body scenario 8 (seed 15) drives the CommonRoad truth into a spin at 21.3 s (steering at its
    0.5 rad limit). Its kernels divided by a zero wheel speed and raised a bare ``ZeroDivisionError``, which
    the benchmark recorded as a failed scenario; now the plant's state turns non-finite, the simulator
    raises ``FloatingPointError`` naming the time, and the benchmark redraws the scenario like any other
    truth that lost control, keeping the reason in ``rejected_draws``."""
    sc = bg.sample_scenario("multi_body", 8, 15, False)
    with pytest.raises(FloatingPointError, match="blew up at t="):
        bg.build(sc)
    out: dict = {}
    kept, built, summary, rejected = bg._build_with_redraws(
        sc, bg.build, lambda b: bg.truth_summary(b[0], b[1], sc), record_error=out)  # fmt: skip
    assert "error" not in out and built is not None and summary["valid"]
    assert kept["attempt"] == 1 and len(rejected) == 1
    assert rejected[0]["truth_summary"]["valid"] is False and "blew up" in rejected[0]["truth_summary"]["blew_up"]


# -- issue 15: highway-env traffic -------------------------------------------------------------
def test_highway_traffic_scenarios_are_seeded_and_in_range(bg):
    a = [bg.sample_scenario("highway_traffic", i, 15, False) for i in range(8)]
    assert a == [bg.sample_scenario("highway_traffic", i, 15, False) for i in range(8)]
    assert {s["scene"]["kind"] for s in a} == {"highway", "racetrack"}
    for s in a:
        cam = s["camera"]
        assert 10.0 <= cam["rate"] <= 100.0 and 0.0 <= cam["latency"] <= 0.1 and 0.0 <= cam["dropout_probability"] <= 0.2
        assert all(0.8 <= f <= 1.2 for f in s["truth"]["stiffness_factor"]) and 30.0 <= s["duration_s"] <= 45.0
    # appended to the families: the other families' seed keys (their index) are unchanged
    assert bg.ALL_FAMILIES[: len(FAMILIES)] == FAMILIES and bg.ALL_FAMILIES[-1] == "highway_traffic"


def test_quick_highway_traffic_family(tmp_path):
    """One quick highway-env scenario: simulated, both estimators scored, the lane changes' e1 steps found."""
    printed, written, _ = _run(tmp_path, "--quick", "--n", "1", "--workers", "1", "--families", "highway_traffic",
                               timeout=300)  # fmt: skip
    assert printed == written and set(written["families"]) == {"highway_traffic"}
    rec = written["families"]["highway_traffic"]["scenarios"][0]
    assert "error" not in rec and "error" not in rec["observer"] and "error" not in rec["ukf"]
    drive = rec["truth_summary"]["drive"]
    assert rec["scenario"]["scene"]["kind"] == "highway" and drive["lane_changes"] >= 1
    assert rec["observer"]["e1_reexpressions"]["detected"] == drive["lane_changes"]
    assert all(abs(e) < 10.0 for e in rec["observer"]["stiffness_error_pct"])  # loose: a 12 s drive
    assert "highway_traffic" in written["target_check"]


def test_a_latency_the_refined_profile_finds_near_the_first_is_used(bg):
    """Highway scenario 2 with a clean 100 Hz camera (3.8 ms latency): the first profile (the nominal curve) finds
    2.5 ms, the second (the refined curve) 4.0 ms, a chi-square decrease of 34 with a standard deviation of 0.27 ms.
    The fit is redone there. A 2 ms floor on that move kept 2.5 ms and read the stiffness -1.1 / -1.5 % against a
    two-sigma band of +/-0.6 / 0.65 % (``benchmarks/bench_highway_latency.py``; about 10 s)."""
    sys.path.insert(0, str(BENCH.parent))
    try:
        import bench_highway_latency as bhl
    finally:
        sys.path.remove(str(BENCH.parent))
    clean = bhl.parse_variant("rate=100,e1_noise=0.002,e2_noise=0.0005,dropout_probability=0,noise=gaussian")
    (run, told) = bhl.run(2, clean, details=True)
    lat = run["calibration_latency"]
    first = lat["first_profile"]["latency_s"]
    assert lat["cost_decrease_chi2"] > 4.0 and abs(lat["latency_s"] - first) < 0.002, lat  # the case
    assert "kept_first" not in lat, lat["kept_first"]
    assert abs(run["latency_used_ms"] - run["latency_true_ms"]) <= 2.0 * run["latency_std_ms"], run
    assert all(run["covered_2sigma"]), (run["stiffness_error_pct"], run["band_2sigma_pct"])
    assert told["latency_told"] and all(abs(e) < 1.0 for e in told["stiffness_error_pct"])


@pytest.mark.slow  # about 30 s
def test_a_1khz_imu_preference_short_of_decisive_keeps_the_other_hold_in_the_band(bg):
    """The IMU family's scenario imu_white 9: a sampled continuous steering wheel at 1 kHz rows. The fit prefers the
    held steering by chi-square 13.7, above the 10 that decides at sparser rows but short of the 100 that rows closer
    than 2 ms need (half a millisecond of timing apart): the held answer (+0.30 / +0.28 %) is reported with the
    ramped one (+0.01 / +0.03 %) inside its band. Decided at 10 its band (+/-0.17 / 0.14 %) missed. About 25 s."""
    from tire_learning_env.imu import estimate_imu

    sc = bg.sample_scenario("imu_white", 9, 15, False)
    sc, (sensors, _, _, nominal, tv), _, _ = bg._build_with_redraws(
        sc, bg.build_imu, lambda b: bg.imu_truth_summary(b[1], b[2]))  # fmt: skip
    assert sc["rate_hz"] == 1000.0
    core = estimate_imu(sensors, nominal).core
    info = core.calibration["steering_hold"]
    assert 10.0 < info["cost_decrease_under_other_chi2"] < info["decisive_chi2"] == 100.0, info
    assert info["used"] == "hold" and info.get("refitted") and len(core.fit.hold_alternatives) == 1, info
    k, sd = np.array(core.cornering_stiffness()), np.array(core.cornering_stiffness_std())
    truth = np.array([tv.Cf, tv.Cr])
    assert np.all(np.abs(k - truth) <= 2.0 * sd), ((k / truth - 1.0) * 100, 200 * sd / truth)


@pytest.mark.slow
def test_a_fused_answer_that_leans_on_the_process_noise_says_so(bg):
    """The fused family's scenario 15 (sedan on curves, a 100 Hz camera whose noise the driver answers at every frame,
    a 200 Hz IMU with a_y noise 0.4 m/s^2): the fit stops at the smallest process noise (0.75 N) and reads
    +0.69 / +0.38 %; one stage up (2.5 N, as consistent by the NIS) it reads about 0.4 / 0.2 points lower. Without
    that change in the bands (+/-0.37 / 0.32 %) both axles missed; over six IMU noise realisations of the drive the
    answer stayed at +0.57 to +0.73 %: the drive's bias, not noise. About 30 s."""
    from tire_learning_env.observer import ObserverConfig, estimate

    sc = bg.sample_scenario("fused", 15, 15, False)
    sc, (log, _, _, nominal, _, k_true), _, _ = bg._build_with_redraws(
        sc, bg.build, lambda b: bg.truth_summary(b[0], b[1], sc))  # fmt: skip
    sensors = bg.add_imu_channels(log.sensors, sc["imu"], sc["sim_seed"])
    res = estimate(sensors, nominal, config=ObserverConfig(sensors="both"))
    k, sd, truth = np.array(res.cornering_stiffness()), np.array(res.cornering_stiffness_std()), np.array(k_true)
    G, _ = res.stiffness_functionals()
    (change,) = res.fit.process_noise_alternatives
    assert np.all(100.0 * (G @ change) / truth < -0.15), 100.0 * (G @ change) / truth  # one stage up reads lower
    assert np.all(k > truth), (k / truth - 1.0) * 100  # the case: read high
    assert np.all(np.abs(k - truth) <= 2.0 * sd), ((k / truth - 1.0) * 100, 200 * sd / truth)


def test_scenarios_option_names_a_bad_item(bg, tmp_path):
    """``--scenarios FAMILY:INDEX,...`` re-runs chosen scenarios; a bad item is an error naming it."""
    assert bg.parse_scenarios("imu_white:4, imu_vibration_bias:17") == [("imu_white", 4), ("imu_vibration_bias", 17)]
    for bad, words in (("imu_white", "FAMILY:INDEX"), ("no_such_family:1", "FAMILY:INDEX"), ("imu_white:-1", "whole number"),
                       ("imu_white:x", "whole number"), (",", "empty")):  # fmt: skip
        with pytest.raises(ValueError, match=words):
            bg.parse_scenarios(bad)
    proc = subprocess.run([sys.executable, str(BENCH), "--scenarios", "imu_white:four", "--out", str(tmp_path / "g.json")],
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    assert proc.returncode == 2 and "'imu_white:four'" in proc.stderr and not (tmp_path / "g.json").exists()


def test_the_steering_census_tells_the_package_s_steps_from_a_noisy_sensor(tmp_path):
    """``benchmarks/bench_steering_census.py`` on one drive of each camera family, one independent sweep case
    and one seed of noisy-sensor variants: the package's drives step the steering at the frames (rough, half the
    changes' power on under 2 % of the rows: the midpoint), the independent generator's steering is smooth, and
    its noisy variants are rough by sensor noise (ramped). The full census (70 package drives, 12 sweep cases,
    40 variants) is in `docs/results.md`."""
    out = tmp_path / "census.json"
    sys.path.insert(0, str(BENCH.parent))  # the census imports its sibling benchmarks as it runs
    try:
        import bench_steering_census

        result = bench_steering_census.main(["--n", "1", "--highway", "0", "--sweep", "1", "--noisy-seeds", "1",
                                             "--out", str(out), "--no-progress"])
    finally:
        sys.path.remove(str(BENCH.parent))
    assert json.loads(out.read_text())["summary"] == result["summary"]
    summary = result["summary"]
    for family in FAMILIES:
        assert summary[family]["midpoint"] == 1 and summary[family]["half_power_share_range"][1] < 0.02, summary
    assert summary["independent_sweep"]["smooth"] == 1 and summary["independent_sweep"]["sensor_noise"] == 0
    noisy = summary["independent_noisy_steering"]
    assert noisy["drives"] == len(bench_steering_census.NOISY_VARIANTS) == noisy["sensor_noise"], noisy
    assert noisy["roughness_range"][0] >= 0.7, noisy


def test_the_census_s_estimates_compare_the_rule_with_and_without_its_sensor_noise_test():
    """``bench_steering_census.estimate_case`` (the ``--estimate`` rows behind the noisy-steering figures of ``docs/results.md``):
    the generator's sedan, seed 0, 0.005 deg of steering noise. With the rule as it is the steering counts as a
    continuous wheel seen through a noisy sensor and is ramped; without the sensor-noise test (the rule before it)
    it is reported at the midpoint, further from the truth (measured +0.11 / -0.02 % against +1.22 / +1.62 %)."""
    sys.path.insert(0, str(BENCH.parent))
    try:
        import bench_steering_census

        row = bench_steering_census.estimate_case(0, 0.005, 0.0, "camera")
    finally:
        sys.path.remove(str(BENCH.parent))
    now, before = row["now"], row["before"]
    assert now["sensor_noise"] and now["hold"] == "ramp" and not before["sensor_noise"] and before["hold"] == "midpoint", row
    assert now["verdict"] == "identified" and now["truth_in_band"], row
    assert max(abs(e) for e in now["stiffness_error_pct"]) < 0.5, row
    assert all(abs(a) < abs(b) for a, b in zip(now["stiffness_error_pct"], before["stiffness_error_pct"])), row
