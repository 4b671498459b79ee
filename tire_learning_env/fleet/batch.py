"""``tire-learning batch``: run ``estimate`` or ``discrepancy`` on every log of a fleet.

Output folder ``DIR``::

    DIR/<name>/              the command's usual outputs for one log (written atomically by it)
    DIR/summary.csv          one row per log: log, status (ok/failed/skipped), error, headline figures
    DIR/summary.parquet      the same table (written at the end)
    DIR/vehicles.csv         estimate: per vehicle (the logs' folder) and axle, the pooled stiffness
                             and its 2-sigma band (:func:`pooled_by_vehicle`)
    DIR/fleet.png            stiffness per log and per vehicle with 2-sigma bands (estimate) or the
                             gap ratio per log by verdict (discrepancy)
    DIR/batch_results.jsonl  the runner's store: one record per finished log (the resume state)
    DIR/batch.json           the batch's command and options (a re-run must match them)

``<name>`` is the log's stem; logs with the same stem in different folders are named
``<folder>__<stem>``. A re-run with the same ``DIR`` skips every log whose earlier result
is ``ok`` and whose file and options are unchanged (``status = skipped``, the figures of the
earlier run); failed logs are run again.

Durability: each finished log is appended to ``summary.csv`` and then to
``batch_results.jsonl``, each ``fsync``-ed, before the next one is recorded, so a kill of the
command, a worker or a node loses no finished row, and ``summary.csv`` holds every log the
store holds. At the end ``summary.csv`` is rewritten atomically in the order of the logs.
"""

from __future__ import annotations

import contextlib
import csv
import glob
import hashlib
import io as _io
import json
import math
import os
import shlex
import shutil
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

from ..io import (MANIFEST_NAME, LogFormatError, OutputPathError, atomic_write_json, atomic_write_text, check_output_dir,
                  read_manifest, run_context)  # fmt: skip
from ..params import ParameterError
from .runner import ItemResult, ResultStore, run_items

__all__ = ["LOG_SUFFIXES", "COMMANDS", "SUMMARY_COLUMNS", "expand_logs", "output_names", "vehicle_ids", "LogJob",
           "run_log", "run_batch", "BatchResult", "pooled_by_vehicle"]  # fmt: skip

LOG_SUFFIXES = (".csv", ".mf4", ".mdf", ".parquet", ".pq", ".mcap")  # and ROS 2 bag folders
COMMANDS = ("estimate", "discrepancy")
STORE_NAME = "batch_results.jsonl"
MARKER_NAME = "batch.json"

COMMON_COLUMNS = ["log", "name", "vehicle", "status", "error", "kind", "rows", "runtime_s", "worker"]
VEHICLE_COLUMNS = ["vehicle", "axle", "logs", "identified_logs", "stiffness_N_per_rad", "lo_N_per_rad", "hi_N_per_rad",
                   "min_log_estimate_N_per_rad", "max_log_estimate_N_per_rad"]  # fmt: skip
SUMMARY_COLUMNS = {
    "estimate": COMMON_COLUMNS + [
        "sensors", "verdict", "stiffness_front_N_per_rad", "stiffness_front_lo_N_per_rad", "stiffness_front_hi_N_per_rad",
        "stiffness_rear_N_per_rad", "stiffness_rear_lo_N_per_rad", "stiffness_rear_hi_N_per_rad", "health_final",
        "curve_nrmse_front", "curve_nrmse_rear", "message",
    ],
    "discrepancy": COMMON_COLUMNS + ["verdict", "effects", "gap_ratio", "message"],
}  # fmt: skip


def _is_bag(p: Path) -> bool:
    return p.is_dir() and (p / "metadata.yaml").is_file()


def expand_logs(specs: Sequence[str | Path]) -> list[Path]:
    """Log files named by ``specs``: files, folders (every log below them, recursively,
    hidden folders skipped; a ROS 2 bag folder, which holds ``metadata.yaml``, is one log) and
    glob patterns (``**`` allowed). Sorted within a spec, duplicates dropped.

    Raises
    ------
    ParameterError
        A path that does not exist, a pattern or folder with no log in it.
    """
    found: list[Path] = []
    seen: set[str] = set()
    for spec in specs:
        text = str(spec)
        if any(ch in text for ch in "*?["):
            paths = sorted(Path(p) for p in glob.glob(text, recursive=True))
            paths = [p for p in paths if (p.is_file() and p.suffix.lower() in LOG_SUFFIXES) or _is_bag(p)]
            if not paths:
                raise ParameterError(f"the pattern {text!r} matches no log ({', '.join(LOG_SUFFIXES)})")
        else:
            p = Path(text)
            if p.is_dir() and _is_bag(p):
                paths = [p]
            elif p.is_dir():
                bags = sorted(q.parent for q in p.rglob("metadata.yaml")
                              if not any(part.startswith(".") for part in q.relative_to(p).parts))  # fmt: skip
                paths = sorted(q for q in p.rglob("*") if q.is_file() and q.suffix.lower() in LOG_SUFFIXES
                               and not any(part.startswith(".") for part in q.relative_to(p).parts)
                               and not any(b in q.parents for b in bags))  # fmt: skip
                paths = sorted(paths + bags)
                if not paths:
                    raise ParameterError(f"the folder {text} holds no log ({', '.join(LOG_SUFFIXES)})")
            elif p.exists():
                paths = [p]
            else:
                raise ParameterError(f"no such log or folder: {text}")
        for q in paths:
            real = os.path.realpath(q)
            if real not in seen:
                seen.add(real)
                found.append(q)
    return found


def output_names(logs: Sequence[Path]) -> list[str]:
    """A unique output sub-folder name per log: its stem, ``<folder>__<stem>`` when stems
    repeat, plus ``_2``, ``_3`` ... if that still repeats."""
    stems = [p.stem for p in logs]
    names = [f"{p.parent.name}__{p.stem}" if stems.count(p.stem) > 1 else p.stem for p in logs]
    out, used = [], set()
    for n in names:
        cand, k = n, 2
        while cand in used or cand.startswith(".") or cand in (STORE_NAME, MARKER_NAME):
            cand, k = f"{n}_{k}", k + 1
        used.add(cand)
        out.append(cand)
    return out


@dataclass(frozen=True)
class LogJob:
    """One log of a batch: everything a worker needs to run the command on it.

    Attributes
    ----------
    log : str
        Absolute path of the log.
    out : str
        Absolute path of its output folder ``DIR/<name>``.
    command : {"estimate", "discrepancy"}
    args : tuple of str
        Extra arguments of the command (``--args``), e.g. ``("--tire", "linear")``.
    channel_map : str or None
        Default channel map for logger files without one beside them.
    check_units : bool
        The log's unit plausibility checks.
    """

    log: str
    out: str
    command: str
    args: tuple[str, ...] = ()
    channel_map: str | None = None
    check_units: bool = True

    def argv(self) -> list[str]:
        return [self.command, self.log, "--out", self.out, "--no-progress", *self.args]


def _redirected(buffer: _io.StringIO):
    stack = contextlib.ExitStack()
    stack.enter_context(contextlib.redirect_stdout(buffer))
    stack.enter_context(contextlib.redirect_stderr(buffer))
    return stack


def run_log(job: LogJob) -> dict:
    """Run ``tire-learning <command>`` on one log (in a worker) and read back its headline figures.

    The command runs through the same parser and :func:`~tire_learning_env.io.run_context`
    as the CLI, so ``job.out`` holds exactly its usual outputs and manifest. Its printed
    lines are returned (``message``), not shown. Raises what the command raises (the runner
    records it as a failed row).
    """
    from ..cli import build_parser, check_output
    from ..formats import default_channel_map

    parser = build_parser()
    buffer = _io.StringIO()
    argv = job.argv()
    try:
        with _redirected(buffer):
            args = parser.parse_args(argv)
    except SystemExit:
        raise ParameterError(f"bad {job.command} arguments {shlex.join(job.args)}: "
                             + " ".join(buffer.getvalue().strip().splitlines()[-1:]))  # fmt: skip
    inputs = [Path(job.log)] + [Path(a) for a in job.args if os.path.exists(a)]
    with (
        run_context(overwrite=False, inputs=inputs, command=job.command, argv=tuple(argv), check_units=job.check_units),
        warnings.catch_warnings(record=True) as caught,
        default_channel_map(job.channel_map),
        _redirected(buffer),
    ):
        warnings.simplefilter("always")
        check_output(args)
        code = int(args.func(args) or 0)
    if code != 0:
        raise RuntimeError(f"{job.command} returned exit code {code}: {buffer.getvalue().strip()[-300:]}")
    figures = headline(job.command, Path(job.out))
    lines = [ln for ln in buffer.getvalue().splitlines() if ln.startswith("wrote ")]
    figures["message"] = lines[-1] if lines else ""
    figures["warnings"] = sorted({str(w.message) for w in caught})
    return figures


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


def _fingerprint(path: Path, job: LogJob, extra: str) -> str:
    st = path.stat()
    if path.is_dir():  # a ROS 2 bag: its files' sizes and times
        files = sorted(q for q in path.iterdir() if q.is_file())
        st = type("S", (), {"st_size": sum(q.stat().st_size for q in files),
                            "st_mtime_ns": max((q.stat().st_mtime_ns for q in files), default=0)})()  # fmt: skip
    h = hashlib.sha256(json.dumps([job.command, list(job.args), job.channel_map, job.check_units, extra]).encode())
    return f"{st.st_size}:{st.st_mtime_ns}:{h.hexdigest()[:16]}"


def _file_identity(path: str | None) -> str:
    if not path or not os.path.exists(path):
        return ""
    st = os.stat(path)
    return f"{path}:{st.st_size}:{st.st_mtime_ns}"


@dataclass
class BatchResult:
    """What :func:`run_batch` did.

    Attributes
    ----------
    out : Path
    rows : list of dict
        The summary rows, in the order of the logs.
    counts : dict
        ``{"ok": n, "failed": n, "skipped": n}``.
    wall_s : float
        Wall time of the whole batch [s] (Ray start-up included).
    """

    out: Path
    rows: list[dict]
    counts: dict
    wall_s: float
    results: list[ItemResult] = field(default_factory=list)


def vehicle_ids(logs: Sequence[Path]) -> list[str]:
    """The vehicle of each log: its folder (relative to the logs' common folder) when the logs
    span several folders (one folder per vehicle), else the log's own stem (one log, one vehicle)."""
    parents = [Path(os.path.abspath(p)).parent for p in logs]
    if len(set(parents)) < 2:
        return [Path(p).stem for p in logs]
    common = Path(os.path.commonpath([str(q) for q in parents]))
    return [q.relative_to(common).as_posix() if q != common else "." for q in parents]


def _row(rec: ItemResult, log: Path, name: str, command: str, vehicle: str = "") -> dict:
    row: dict[str, Any] = {c: "" for c in SUMMARY_COLUMNS[command]}
    row.update(log=str(log), name=name, vehicle=vehicle, status=rec.status, error=rec.error, worker=rec.worker,
               runtime_s=rec.runtime_s)  # fmt: skip
    if isinstance(rec.result, dict):
        for k, v in rec.result.items():
            if k in row and k not in ("log", "name", "status", "error"):
                row[k] = v
    return row


def _cell(v: Any) -> str:
    if isinstance(v, float):
        return "" if not math.isfinite(v) else f"{v:.6g}"
    return str(v)


class _SummaryCSV:
    """``summary.csv``: the header and ``rows`` (atomically), then one appended + fsync-ed row per finished log."""

    def __init__(self, path: Path, columns: list[str], rows: Sequence[dict] = ()) -> None:
        self.path, self.columns = path, columns
        buf = _io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(columns)
        for row in rows:
            w.writerow([_cell(row.get(c, "")) for c in columns])
        atomic_write_text(path, buf.getvalue())
        self.fh = open(path, "a", encoding="utf-8", newline="")
        self.writer = csv.writer(self.fh, lineterminator="\n")

    def add(self, row: dict) -> None:
        self.writer.writerow([_cell(row.get(c, "")) for c in self.columns])
        self.fh.flush()
        os.fsync(self.fh.fileno())

    def close(self) -> None:
        self.fh.close()


def _prepare_out(out: Path, command: str, overwrite: bool, inputs: list[Path], options: dict) -> bool:
    """Check (and with ``overwrite`` clear) ``out``; True when an earlier batch is resumed."""
    marker = out / MARKER_NAME
    if out.is_dir() and marker.is_file() and not overwrite:
        try:
            old = json.loads(marker.read_text())
        except ValueError:
            old = {}
        if old.get("command") != command:
            raise OutputPathError(f"{out} holds a batch of {old.get('command')!r}, not {command!r}; choose another "
                                  "--out, or pass --overwrite to start over")  # fmt: skip
        check_output_dir(out, overwrite=True, inputs=inputs)  # never the cwd, a parent, or a folder holding an input
        return True
    check_output_dir(out, overwrite=overwrite, inputs=inputs)
    if out.exists() and any(out.iterdir()):
        shutil.rmtree(out)  # allowed by check_output_dir: written by tire-learning, or --overwrite
    out.mkdir(parents=True, exist_ok=True)
    return False


def _clean_leftovers(out: Path, names: list[str]) -> None:
    """Remove the temporary folders of a killed earlier run (``.NAME.*.tmp``, ``.NAME.old.*``)."""
    wanted = set(names)
    for p in out.iterdir():
        if not (p.name.startswith(".") and p.is_dir()):
            continue
        base = p.name[1:].split(".")[0]
        if base in wanted and (p.name.endswith(".tmp") or ".old." in p.name):
            shutil.rmtree(p, ignore_errors=True)


def run_batch(
    logs: Sequence[str | Path],
    out: str | Path,
    command: str = "estimate",
    *,
    workers: int | None = None,
    address: str | None = None,
    args: Sequence[str] = (),
    channel_map: str | Path | None = None,
    check_units: bool = True,
    overwrite: bool = False,
    engine: str = "ray",
    progress: bool = True,
    max_retries: int = 3,
) -> BatchResult:
    """Run ``command`` on every log and write ``out`` (see the module docstring).

    Parameters
    ----------
    logs : sequence of str or Path
        Log files, folders or glob patterns (:func:`expand_logs`).
    out : str or Path
        The batch folder ``DIR``.
    command : {"estimate", "discrepancy"}
    workers : int, optional
        Parallel tasks on local Ray (default: all cores).
    address : str, optional
        Join this Ray cluster instead (``auto``, ``HOST:PORT``).
    args : sequence of str
        Extra arguments for the command, e.g. ``["--tire", "linear"]``.
    channel_map : str or Path, optional
        Channel map for logger files that have none beside them.
    check_units, overwrite : bool
        As the CLI flags ``--no-unit-checks`` (inverted) and ``--overwrite`` (start over).
    engine : {"ray", "serial"}
    progress : bool
        A bar counting logs.
    max_retries : int
        Re-executions of a log whose worker or node died.

    Returns
    -------
    BatchResult
    """
    t_start = time.perf_counter()
    if command not in COMMANDS:
        raise ParameterError(f"--command must be one of {COMMANDS}, got {command!r}")
    paths = expand_logs(logs)
    names = output_names(paths)
    vehicles = vehicle_ids(paths)
    out = Path(out)
    args = tuple(args)
    _validate_args(command, args)
    if channel_map is not None:
        from ..formats import load_channel_map

        load_channel_map(channel_map)  # a bad map is one error now, not one failed row per log
    options = {"command": command, "args": list(args), "channel_map": None if channel_map is None else str(channel_map),
               "check_units": check_units}  # fmt: skip
    resumed = _prepare_out(out, command, overwrite, list(paths), options)
    if resumed:
        _clean_leftovers(out, names)
    atomic_write_json(out / MARKER_NAME, {**options, "logs": [str(p) for p in paths], "names": names,
                                          "written_by": "tire-learning batch"})  # fmt: skip
    extra = json.dumps([_file_identity(channel_map and str(channel_map))]
                       + [_file_identity(a) for a in args if os.path.exists(a)])  # fmt: skip
    jobs = [LogJob(str(Path(p).resolve()), str((out / n).resolve()), command, args,
                   None if channel_map is None else str(Path(channel_map).resolve()), check_units)
            for p, n in zip(paths, names)]  # fmt: skip
    prints = [_fingerprint(p, j, extra) for p, j in zip(paths, jobs)]
    columns = SUMMARY_COLUMNS[command]
    index = {n: i for i, n in enumerate(names)}
    # the rows of the logs an earlier run finished go into the new summary.csv in the same atomic
    # write as its header: at no moment does the file lack a finished row
    stored = ResultStore(out / STORE_NAME).load()
    done_before = []
    for p, n, fp in zip(paths, names, prints):
        old = stored.get(n)
        if old is not None and old.status in ("ok", "skipped") and old.fingerprint == fp:
            old.status = "skipped"
            done_before.append(_row(old, p, n, command, vehicles[index[n]]))
    summary = _SummaryCSV(out / "summary.csv", columns, done_before)

    def on_result(rec: ItemResult) -> None:
        if rec.status != "skipped":  # skipped rows are already in the file
            summary.add(_row(rec, paths[index[rec.key]], rec.key, command, vehicles[index[rec.key]]))

    try:
        results = run_items(run_log, jobs, keys=names, fingerprints=prints, store=out / STORE_NAME, workers=workers,
                            address=address, engine=engine, max_retries=max_retries, progress=progress, desc="logs",
                            on_result=on_result)  # fmt: skip
    finally:
        summary.close()
    rows = [_row(r, paths[index[r.key]], r.key, command, vehicles[index[r.key]]) for r in results]
    for r, row in zip(results, rows):
        if r.status != "failed" and not row.get("kind"):
            row.update(_log_facts(paths[index[r.key]], out / r.key))
    _write_summaries(out, rows, columns, command)
    counts = {s: sum(r["status"] == s for r in rows) for s in ("ok", "failed", "skipped")}
    _write_batch_manifest(out)
    return BatchResult(out, rows, counts, time.perf_counter() - t_start, results)


def _log_facts(log: Path, folder: Path) -> dict:
    """``kind``, ``rows`` and ``duration_s`` from the command's output (cheap: no log re-read)."""
    facts: dict[str, Any] = {}
    for name in ("metrics.json", "report.json"):
        f = folder / name
        if f.is_file():
            try:
                doc = json.loads(f.read_text())
            except ValueError:
                continue
            notes = doc.get("log_notes") or (doc.get("data") or {}).get("notes") or []
            for n in notes if isinstance(notes, list) else []:
                if isinstance(n, str) and n.startswith("read ") and " rows, " in n:
                    parts = n.split()
                    facts["rows"] = int(parts[1])
                    facts["kind"] = parts[3] if len(parts) > 3 else ""
    return facts


def _validate_args(command: str, args: tuple[str, ...]) -> None:
    from ..cli import build_parser

    forbidden = {"--out", "--overwrite", "--quiet", "-q"}
    bad = [a for a in args if a.split("=")[0] in forbidden]
    if bad:
        raise ParameterError(f"--args must not set {bad}: the batch sets each log's --out itself")
    buffer = _io.StringIO()
    try:
        with _redirected(buffer):
            build_parser().parse_args([command, "LOG", "--out", "OUT", *args])
    except SystemExit:
        last = buffer.getvalue().strip().splitlines()[-1:] or [""]
        raise ParameterError(f"--args {shlex.join(args)!r} are not valid for {command}: {last[0]}") from None


def _write_summaries(out: Path, rows: list[dict], columns: list[str], command: str) -> None:
    buf = _io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for row in rows:
        w.writerow([_cell(row.get(c, "")) for c in columns])
    atomic_write_text(out / "summary.csv", buf.getvalue())
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
        buf = _io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(VEHICLE_COLUMNS)
        for v in vehicles:
            w.writerow([_cell(v.get(c, "")) for c in VEHICLE_COLUMNS])
        atomic_write_text(out / "vehicles.csv", buf.getvalue())
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


def _write_batch_manifest(out: Path) -> None:
    """The package manifest listing every file in ``out`` (so a later command may replace it)."""
    from ..io import _write_manifest  # the same manifest atomic_directory writes

    _write_manifest(out, out)
