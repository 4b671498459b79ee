"""The ``reproduce --all`` report (``tire_learning_env.report``): the paper-vs-observer-vs-UKF table and
the index page, on hand-made metrics (the studies themselves run in ``test_studies.py`` and, through the
command, ``test_cli.py``)."""

from __future__ import annotations

import math

from tire_learning_env.report import RUNS, _index, results_table


def _metrics(e1: float, front_pct: float, tire_level: bool = False) -> dict:
    m = {
        "state_rmse": {"e1": e1, "e2": math.radians(0.5)},
        "slip_rmse_deg": {"front": 0.1, "rear": 0.2},
        "tire_curve_nrmse": {"front": 0.01, "rear": float("nan")},
        "cornering_stiffness": {"front": {"error_pct": front_pct}, "rear": {"error_pct": -1.5}},
        "convergence_time_s": None,
        "cpu_s_per_simulated_s": 0.25,
        "lmi": {"certified": True, "decay_rate": 1.234, "solve_s": 0.5},
    }
    if tire_level:
        m["cornering_stiffness_tire_level"] = {"front": {"error_pct": 2.0}, "rear": {"error_pct": -3.0}}
    return m


def test_results_table_rows_follow_the_runs_and_the_paper():
    results = {  # given out of order; study3 without a baseline
        "study3": (_metrics(0.03, 4.0), None),
        "study2": (_metrics(0.02, 1.25, tire_level=True), _metrics(0.05, -7.0, tire_level=True)),
    }
    lines = results_table(results).splitlines()
    assert lines[0].startswith("| run / estimator |") and lines[1] == "|---|---|---|---|---|---|---|"
    captions = [line for line in lines if line.startswith("| **")]
    assert captions == [f"| **{caption}** | | | | | | |" for name, _, _, caption in RUNS if name in results]
    # the paper's stiffness errors where it gives them (study 2), n/a otherwise
    assert "| paper (Jeon et al. 2021) | n/a | n/a | n/a | -0.49 / -1.09 | n/a | n/a |" in lines
    assert "| paper (Jeon et al. 2021) | n/a | n/a | n/a | n/a | n/a | n/a |" in lines
    observer = [line for line in lines if line.startswith("| neuro-adaptive observer")]
    assert observer[0] == "| neuro-adaptive observer (this package) | 0.02 m, 0.5 deg | 0.1 / 0.2 | 0.01 / n/a | +1.25 / -1.50 | never | 0.25 |"
    assert len(observer) == 2 and sum(line.startswith("| joint UKF baseline") for line in lines) == 1
    extra = [line for line in lines if "tire-level" in line]
    assert len(extra) == 1 and "observer +2.00 / -3.00; UKF +2.00 / -3.00" in extra[0]


def test_index_links_only_the_figures_that_exist(tmp_path):
    (tmp_path / "study1").mkdir()
    for fig in ("states", "tire_curves"):
        (tmp_path / "study1" / f"{fig}.png").write_bytes(b"png")
    text = _index({"study1": (_metrics(0.01, 0.5), None)}, "tire-learning reproduce --all --out r", 12.0, tmp_path)
    assert "Produced by `tire-learning reproduce --all --out r`" in text and "in 12 s" in text
    assert "LMI: certified=True, decay rate 1.23 1/s, solve 0.50 s." in text
    assert [line for line in text.splitlines() if line.startswith("![")] == [
        "![states](study1/states.png)", "![tire_curves](study1/tire_curves.png)",
    ]  # fmt: skip
