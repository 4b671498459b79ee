"""``tire-learning reproduce --all``: every study, the UKF baseline, and one Markdown report.

Writes ``OUT/study1``, ``OUT/study1_camera20hz_noise``, ``OUT/study2``, ``OUT/study3``
(each with ``metrics.json``, ``metrics_ukf.json`` and figures) and ``OUT/index.md``: the
paper-vs-observer-vs-UKF table, the figures, and the exact command and version that
produced them. The whole directory is replaced atomically.
"""

from __future__ import annotations

import math
import platform
import sys
import time
from pathlib import Path

from tqdm import tqdm

from . import __version__
from .io import atomic_directory, atomic_write_text
from .studies import PAPER_RESULTS, run_study, study_spec

__all__ = ["reproduce_all", "results_table"]

#: (directory name, study id, camera variant or None, caption)
RUNS = (
    ("study1", 1, None, "Study 1: low-order model, Pacejka truth, known stiffness, 1 kHz noise-free camera"),
    ("study1_camera20hz_noise", 1, (20.0, "paper"), "Study 1 with a 20 Hz camera and the paper's +/-1 cm / +/-1 deg noise"),
    ("study2", 2, None, "Study 2: high-order model, stiffness assumed 13.6 % / 16.5 % too high"),
    ("study3", 3, None, "Study 3: high-order model, known stiffness, +/-1 cm / +/-1 deg noise"),
)


def _fmt(x, digits=4):
    if x is None:
        return "never"
    if isinstance(x, float) and math.isnan(x):
        return "n/a"
    return f"{x:.{digits}g}"


def _row(label: str, m: dict | None, paper: dict | None = None) -> str:
    if m is None:
        p = paper or {}
        cs = p.get("cornering_stiffness")
        cs_txt = f"{cs['front']['error_pct']:+.2f} / {cs['rear']['error_pct']:+.2f}" if cs else "n/a"
        return f"| {label} | n/a | n/a | n/a | {cs_txt} | n/a | n/a |"
    state = m["state_rmse"]
    slip = m["slip_rmse_deg"]
    curve = m["tire_curve_nrmse"]
    cs = m["cornering_stiffness"]
    return (
        f"| {label} | {_fmt(state['e1'], 3)} m, {_fmt(state['e2'] * 180 / math.pi, 3)} deg "
        f"| {_fmt(slip['front'], 3)} / {_fmt(slip['rear'], 3)} "
        f"| {_fmt(curve['front'], 3)} / {_fmt(curve['rear'], 3)} "
        f"| {cs['front']['error_pct']:+.2f} / {cs['rear']['error_pct']:+.2f} "
        f"| {_fmt(m.get('convergence_time_s'), 3)} "
        f"| {_fmt(m.get('cpu_s_per_simulated_s'), 3)} |"
    )


def _runs_done(results: dict[str, tuple[dict, dict | None]]):
    """``(name, study, caption, (observer, baseline))`` of each run in :data:`RUNS` that ``results`` holds, in order."""
    for name, study, _, caption in RUNS:
        if name in results:
            yield name, study, caption, results[name]


def results_table(results: dict[str, tuple[dict, dict | None]]) -> str:
    """Markdown table: paper vs observer vs UKF per run (``results[name] = (observer, ukf)``)."""
    lines = [
        "| run / estimator | state RMSE (e1, e2) | slip RMSE front / rear [deg] | tire_curve_nrmse front / rear "
        "| stiffness error front / rear [%] | convergence time [s] | CPU s per simulated s |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, study, caption, (obs, ukf) in _runs_done(results):
        lines.append(f"| **{caption}** | | | | | | |")
        lines.append(_row("paper (Jeon et al. 2021)", None, PAPER_RESULTS.get(study)))
        lines.append(_row("neuro-adaptive observer (this package)", obs))
        if ukf is not None:
            lines.append(_row("joint UKF baseline", ukf))
        if "cornering_stiffness_tire_level" in obs:
            tl = obs["cornering_stiffness_tire_level"]
            tu = (ukf or {}).get("cornering_stiffness_tire_level")
            extra = f"observer {tl['front']['error_pct']:+.2f} / {tl['rear']['error_pct']:+.2f}"
            if tu:
                extra += f"; UKF {tu['front']['error_pct']:+.2f} / {tu['rear']['error_pct']:+.2f}"
            lines.append(f"| &nbsp;&nbsp;stiffness error vs the *tire-level* static-load figure [%] | | | | {extra} | | |")
    return "\n".join(lines)


def reproduce_all(out: str | Path, baseline: str | None = "ukf", duration: float | None = None) -> dict:
    """Run every study (and the UKF baseline) and write ``out/index.md``.

    Returns
    -------
    dict
        ``{run name: (observer metrics, baseline metrics or None)}``.
    """
    baseline = baseline or "ukf"
    out = Path(out)
    command = "tire-learning reproduce --all --out " + str(out)
    started = time.time()
    results: dict[str, tuple[dict, dict | None]] = {}
    with atomic_directory(out) as tmp:
        for name, study, camera, _ in tqdm(RUNS, desc="studies", disable=None):
            spec = study_spec(study, duration)
            if camera is not None:
                spec = spec.with_camera(*camera)
            m = run_study(spec, tmp / name, baseline=baseline)
            results[name] = (m, m.pop("baseline", None))
        atomic_write_text(tmp / "index.md", _index(results, command, time.time() - started, tmp))
    return results


def _index(results: dict, command: str, elapsed: float, root: Path) -> str:
    parts = [
        "# tire_learning_env: the paper's studies reproduced",
        "",
        f"Produced by `{command}` with tire_learning_env {__version__}, Python {sys.version.split()[0]}, "
        f"{platform.platform()}, in {elapsed:.0f} s. Every number below is read from the `metrics.json` "
        "files next to this report; the estimators saw camera data and known inputs only.",
        "",
        "## Paper vs this observer vs the joint UKF",
        "",
        results_table(results),
        "",
        "Definitions: `metrics.py` (state and slip RMSE after 2 s; `tire_curve_nrmse` = RMS error of the "
        "learned axle curve over the excited slip range (0.5-99.5 % quantiles of the true slip) divided by the "
        "largest true force there; stiffness per tire from the slope at zero slip; convergence time = when the "
        "online (first-run) curve error stays below 5 %). For the high-order plant the truth curve and "
        "stiffness are the *effective* axle characteristics (what a bicycle model can represent, "
        "docs/high_order.md §6); the tire-level figures are in the extra row.",
        "",
    ]
    for name, _, caption, (m, _) in _runs_done(results):
        parts += [f"## {caption}", "", f"Settings: `{name}/metrics.json` → `study`. LMI: certified={m['lmi']['certified']}, "
                  f"decay rate {m['lmi']['decay_rate']:.2f} 1/s, solve {m['lmi']['solve_s']:.2f} s.", ""]
        for fig in ("path_and_steering", "states", "slip_angles", "nonlinear_force", "weights", "tire_curves", "force_slip_loop"):
            if (root / name / f"{fig}.png").exists():
                parts.append(f"![{fig}]({name}/{fig}.png)")
        parts.append("")
    return "\n".join(parts)
