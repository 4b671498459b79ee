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
import glob
import hashlib
import io as _io
import json
import os
import shlex
import shutil
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

from ..io import OutputPathError, atomic_write_json, check_output_dir, run_context
from ..params import ParameterError
from .runner import ItemResult, ResultStore, run_items
from .summary import SummaryCSV, headline, pooled_by_vehicle, write_summaries

__all__ = ["LOG_SUFFIXES", "COMMANDS", "SUMMARY_COLUMNS", "expand_logs", "output_names", "vehicle_ids", "LogJob",
           "run_log", "run_batch", "BatchResult", "pooled_by_vehicle"]  # fmt: skip

LOG_SUFFIXES = (".csv", ".mf4", ".mdf", ".parquet", ".pq", ".mcap")  # and ROS 2 bag folders
COMMANDS = ("estimate", "discrepancy")
STORE_NAME = "batch_results.jsonl"
MARKER_NAME = "batch.json"

COMMON_COLUMNS = ["log", "name", "vehicle", "status", "error", "kind", "rows", "runtime_s", "worker"]
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
    summary = SummaryCSV(out / "summary.csv", columns, done_before)

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
    write_summaries(out, rows, columns, command)
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


def _write_batch_manifest(out: Path) -> None:
    """The package manifest listing every file in ``out`` (so a later command may replace it)."""
    from ..io.outputs import write_manifest  # the same manifest atomic_directory writes

    write_manifest(out, out)
