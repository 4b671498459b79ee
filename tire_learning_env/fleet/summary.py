"""The batch's tables and figure: the headline figures of one command output, ``summary.csv``
(streamed row by row, then rewritten in order) and ``summary.parquet``, the per-vehicle pooled
stiffness (``vehicles.csv``) and ``fleet.png`` (:mod:`.batch` runs the logs)."""

from __future__ import annotations

import csv
import io as _io
import json
import math
import os
import warnings
from pathlib import Path
from typing import Any, Sequence

from ..io import atomic_write_text

__all__ = ["VEHICLE_COLUMNS", "headline", "csv_text", "SummaryCSV", "write_summaries", "pooled_by_vehicle"]

VEHICLE_COLUMNS = ["vehicle", "axle", "logs", "identified_logs", "stiffness_N_per_rad", "lo_N_per_rad", "hi_N_per_rad",
                   "min_log_estimate_N_per_rad", "max_log_estimate_N_per_rad"]  # fmt: skip


def _num(x: Any) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return float("nan")
    return v


def headline(command: str, out: Path) -> dict:
    """The summary-row figures of one command output folder ``out``."""
    if command == "estimate":
        m = json.loads((out / "metrics.json").read_text())
        s = m.get("summary", {})
        row: dict[str, Any] = {"sensors": s.get("sensors", ""), "verdict": s.get("verdict", ""),
                               "health_final": s.get("health_final", "")}  # fmt: skip
        for a in ("front", "rear"):
            band = s.get(f"stiffness_{a}_2sigma_N_per_rad") or [None, None]
            row[f"stiffness_{a}_N_per_rad"] = _num(s.get(f"stiffness_{a}_N_per_rad"))
            row[f"stiffness_{a}_lo_N_per_rad"] = _num(band[0])
            row[f"stiffness_{a}_hi_N_per_rad"] = _num(band[1])
            nrmse = float("nan")
            gt = m.get("ground_truth") or {}
            if isinstance(gt.get("tire_curve_nrmse"), dict):
                nrmse = _num(gt["tire_curve_nrmse"].get(a))
            ref = (m.get("reference_scores") or {}).get("tire_curve_nrmse") if isinstance(m.get("reference_scores"), dict) else None
            if ref and not math.isfinite(nrmse):
                final = ref.get("final_learned_curve", {}).get(a, {})
                nrmse = _num(final.get("whole") if isinstance(final, dict) else final)
            row[f"curve_nrmse_{a}"] = nrmse
        row["rows"] = m.get("rows", "")
        return row
    rep = json.loads((out / "report.json").read_text())
    effects = "; ".join(
        e["name"] + "(" + ", ".join(f"{k}={_num(v):.4g}" for k, v in (e.get("parameters") or {}).items()) + ")"
        for e in rep.get("effects", [])
    )  # fmt: skip
    log = rep.get("log") if isinstance(rep.get("log"), dict) else {}
    channels = (rep.get("comparison") or {}).get("channels") or []
    kind = ("camera" if "e1" in channels else "imu") if channels else ""
    return {"verdict": rep.get("verdict", ""), "effects": effects, "gap_ratio": _num(rep.get("gap_ratio")),
            "rows": log.get("rows", ""), "kind": kind}  # fmt: skip


def _cell(v: Any) -> str:
    if isinstance(v, float):
        return "" if not math.isfinite(v) else f"{v:.6g}"
    return str(v)


def csv_text(columns: Sequence[str], rows: Sequence[dict]) -> str:
    """CSV text of ``rows`` (a header of ``columns``, then one line per row; missing cells empty)."""
    buf = _io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for row in rows:
        w.writerow([_cell(row.get(c, "")) for c in columns])
    return buf.getvalue()


class SummaryCSV:
    """``summary.csv``: the header and ``rows`` (atomically), then one appended + fsync-ed row per finished log."""

    def __init__(self, path: Path, columns: list[str], rows: Sequence[dict] = ()) -> None:
        self.path, self.columns = path, columns
        atomic_write_text(path, csv_text(columns, rows))
        self.fh = open(path, "a", encoding="utf-8", newline="")
        self.writer = csv.writer(self.fh, lineterminator="\n")

    def add(self, row: dict) -> None:
        self.writer.writerow([_cell(row.get(c, "")) for c in self.columns])
        self.fh.flush()
        os.fsync(self.fh.fileno())

    def close(self) -> None:
        self.fh.close()


def write_summaries(out: Path, rows: list[dict], columns: list[str], command: str) -> None:
    """``summary.csv`` (rewritten in the order of ``rows``), ``summary.parquet`` (with pyarrow),
    and for ``estimate`` ``vehicles.csv`` (:func:`pooled_by_vehicle`); then ``fleet.png``."""
    atomic_write_text(out / "summary.csv", csv_text(columns, rows))
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        warnings.warn("pyarrow is not installed: no summary.parquet (pip install 'tire_learning_env[fleet]')", stacklevel=2)
    else:
        table = {}
        for c in columns:
            vals = [row.get(c, "") for row in rows]
            if all(isinstance(v, (int, float)) or v == "" or v is None for v in vals) and any(isinstance(v, (int, float)) for v in vals):
                table[c] = pa.array([float(v) if isinstance(v, (int, float)) else None for v in vals], pa.float64())
            else:
                table[c] = pa.array([_cell(v) for v in vals], pa.string())
        tmp = out / ".summary.parquet.tmp"
        pq.write_table(pa.table(table), str(tmp))
        os.replace(tmp, out / "summary.parquet")
    vehicles = pooled_by_vehicle(rows) if command == "estimate" else []
    if command == "estimate":
        atomic_write_text(out / "vehicles.csv", csv_text(VEHICLE_COLUMNS, vehicles))
    _fleet_figure(out / "fleet.png", rows, command, vehicles)


def pooled_by_vehicle(rows: list[dict]) -> list[dict]:
    """Per vehicle and axle: the inverse-variance weighted mean of its logs' identified
    stiffness [N/rad] and its 2-sigma band (sigma from each log's band, (hi - lo) / 4). This
    assumes one true stiffness per vehicle and axle across its drives (same tires, same road
    conditions); ``min_log_estimate``/``max_log_estimate`` show how far the drives disagree."""
    import numpy as np

    out = []
    order = list(dict.fromkeys(r.get("vehicle", "") for r in rows))
    for vehicle in order:
        mine = [r for r in rows if r.get("vehicle", "") == vehicle and r["status"] in ("ok", "skipped")]
        for axle in ("front", "rear"):
            k = np.array([_num(r.get(f"stiffness_{axle}_N_per_rad")) for r in mine])
            lo = np.array([_num(r.get(f"stiffness_{axle}_lo_N_per_rad")) for r in mine])
            hi = np.array([_num(r.get(f"stiffness_{axle}_hi_N_per_rad")) for r in mine])
            ok = np.isfinite(k) & np.isfinite(lo) & np.isfinite(hi) & (hi > lo)
            row = {"vehicle": vehicle, "axle": axle, "logs": len(mine), "identified_logs": int(ok.sum())}
            if ok.any():
                sd = (hi[ok] - lo[ok]) / 4.0
                wgt = 1.0 / sd**2
                mean = float(np.sum(wgt * k[ok]) / np.sum(wgt))
                sd_pooled = float(1.0 / np.sqrt(np.sum(wgt)))
                row.update(stiffness_N_per_rad=mean, lo_N_per_rad=mean - 2 * sd_pooled, hi_N_per_rad=mean + 2 * sd_pooled,
                           min_log_estimate_N_per_rad=float(k[ok].min()), max_log_estimate_N_per_rad=float(k[ok].max()))
            out.append(row)
    return out


def _fleet_figure(path: Path, rows: list[dict], command: str, vehicles: list[dict] | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    import numpy as np

    done = [r for r in rows if r["status"] in ("ok", "skipped")]
    order = list(dict.fromkeys(r.get("vehicle", "") for r in done))
    done.sort(key=lambda r: order.index(r.get("vehicle", "")))  # the logs of a vehicle side by side
    grouped = len(order) < len(done)  # some vehicle has several logs
    x = np.arange(len(done), dtype=float)
    if grouped:  # a gap between vehicles
        x = x + np.array([order.index(r.get("vehicle", "")) for r in done]) * 0.8
    n = max(len(done), 1)
    fig, ax = plt.subplots(figsize=(max(7.0, 0.45 * n + 2), 5.2))
    labels = [f"{r.get('vehicle', '')}: {r['name']}" if grouped else r["name"] for r in done]
    if command == "estimate":
        if grouped:
            for v in vehicles or []:
                xs = [xi for xi, r in zip(x, done) if r.get("vehicle", "") == v["vehicle"]]
                if not xs or not math.isfinite(_num(v.get("stiffness_N_per_rad"))):
                    continue
                colour = "tab:blue" if v["axle"] == "front" else "tab:orange"
                y, lo, hi = (_num(v[c]) / 1e3 for c in ("stiffness_N_per_rad", "lo_N_per_rad", "hi_N_per_rad"))
                ax.fill_between([min(xs) - 0.35, max(xs) + 0.35], lo, hi, color=colour, alpha=0.15, linewidth=0)
                ax.plot([min(xs) - 0.35, max(xs) + 0.35], [y, y], color=colour, linewidth=1.5)
            ax.plot([], [], color="grey", linewidth=1.5, label="per vehicle: pooled estimate and 2 sigma band (shaded)")
        for k, (axle, colour, dx) in enumerate((("front", "tab:blue", -0.12), ("rear", "tab:orange", 0.12))):
            y = np.array([_num(r.get(f"stiffness_{axle}_N_per_rad")) for r in done]) / 1e3
            lo = np.array([_num(r.get(f"stiffness_{axle}_lo_N_per_rad")) for r in done]) / 1e3
            hi = np.array([_num(r.get(f"stiffness_{axle}_hi_N_per_rad")) for r in done]) / 1e3
            ok = np.isfinite(y) & np.isfinite(lo) & np.isfinite(hi)
            if ok.any():
                ax.errorbar(x[ok] + dx, y[ok], yerr=[y[ok] - lo[ok], hi[ok] - y[ok]], fmt="o", color=colour, capsize=3,
                            label=f"{axle}: estimate and 2 sigma band")  # fmt: skip
            band_only = ~np.isfinite(y) & np.isfinite(lo) & np.isfinite(hi)
            if band_only.any():  # not identifiable: the band without a value
                mid = 0.5 * (lo + hi)
                ax.errorbar(x[band_only] + dx, mid[band_only], yerr=0.5 * (hi - lo)[band_only], fmt="none",
                            ecolor=colour, capsize=3, alpha=0.45, linestyle="--",
                            label=f"{axle}: not identified (band only)")  # fmt: skip
        ax.set_ylabel("cornering stiffness per tire [kN/rad]")
        what = f"{len(order)} vehicles, " if grouped else ""
        ax.set_title(f"fleet: stiffness per log and vehicle ({what}{len(done)} of {len(rows)} logs estimated)")
    else:
        colours = {"found": "tab:red", "none": "tab:green", "unexplained": "tab:purple"}
        for verdict, colour in colours.items():
            sel = [i for i, r in enumerate(done) if r.get("verdict") == verdict]
            if sel:
                ax.bar(x[sel], [_num(done[i].get("gap_ratio")) for i in sel], color=colour, label=f"verdict {verdict}")
        ax.set_ylabel("gap ratio: model-log gap before / after the named effects [-]")
        ax.set_title(f"fleet: model discrepancy per log ({len(done)} of {len(rows)} logs analysed)")
    ax.set_xticks(x, labels, rotation=60, ha="right", fontsize=7)
    ax.title.set_fontsize(10)
    if done:
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.3), ncol=2, frameon=False)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    tmp = path.with_name(f".{path.name}.tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    os.replace(tmp, path)


