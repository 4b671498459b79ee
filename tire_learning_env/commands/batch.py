"""``tire-learning batch``: run ``estimate`` or ``discrepancy`` on every log of a fleet, on Ray."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text!r}")
    return value


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "batch",
        help="run estimate or discrepancy on many logs in parallel (Ray), resumable",
        description="Run `tire-learning estimate` (default) or `discrepancy` on every log (CSV, MF4, Parquet, MCAP; "
        "files, folders searched recursively, or glob patterns) as Ray tasks: local Ray with --workers CPUs, or an "
        "existing cluster with --address. Writes DIR/<log stem>/ (the command's usual outputs), DIR/summary.csv "
        "(one row per log: log, status ok/failed/skipped, error, headline figures, runtime), DIR/summary.parquet, "
        "DIR/fleet.png and DIR/batch_results.jsonl (the resume state). A failing log is a 'failed' row, never the "
        "end of the batch. Re-running with the same --out skips the logs already done (status 'skipped'); every "
        "finished row is on disk the moment it finishes (after updating the package, start over with --overwrite). "
        "Exit code 1 when a log failed. Needs the fleet extra: pip install "
        "'tire_learning_env[fleet]'. See docs/fleet.md.",
    )
    p.add_argument("logs", nargs="+", metavar="LOG", help="log files, folders (searched recursively) or glob patterns")
    p.add_argument("--out", dest="batch_out", type=str, required=True, metavar="DIR",
                   help="batch folder DIR; an earlier batch of the same command there is resumed "
                   "(--overwrite starts over)")  # fmt: skip
    p.add_argument("--command", dest="batch_command", choices=["estimate", "discrepancy"], default="estimate",
                   help="command run on each log")  # dest: 'command' is the CLI's subcommand name
    p.add_argument("--workers", type=_positive_int, default=None,
                   help="CPUs of the local Ray instance = logs run at once (default: all cores); ignored with --address")
    p.add_argument("--address", default=None,
                   help="join an existing Ray cluster (auto, HOST:PORT or ray://HOST:10001) instead of starting a "
                   "local one; every node needs this package and read access to the logs and DIR (docs/fleet.md)")
    p.add_argument("--args", dest="command_args", default="",
                   help="extra arguments for the command on each log, as one quoted string after '=', e.g. "
                   "--args='--vehicle car.json --sensors imu' or --args='--tire linear' (the '=' keeps a leading "
                   "'--' from being read as a batch option)")
    p.add_argument("--channel-map", type=Path, default=None,
                   help="channel map (YAML/JSON) for MF4/Parquet/MCAP logs that have no <stem>.channels.yaml beside them")
    p.add_argument("--serial", action="store_true", help="run in this process without Ray (debugging)")
    p.add_argument("--retries", type=int, default=3,
                   help="re-runs of a log whose worker or node died (an error in the log is not retried)")
    p.add_argument("--no-unit-checks", action="store_true",
                   help="skip the logs' unit plausibility checks (see estimate --help)")
    p.add_argument("--seed", type=int, default=None,
                   help="passed to the command on every log (discrepancy: seed of its Monte Carlo null distributions)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..fleet.batch import run_batch
    from ..fleet.runner import RunnerError
    from ..params import ParameterError

    extra = shlex.split(args.command_args)
    if args.seed is not None:
        if args.batch_command == "discrepancy":
            extra += ["--seed", str(args.seed)]
    try:
        result = run_batch(
            args.logs, Path(args.batch_out), args.batch_command, workers=args.workers, address=args.address, args=extra,
            channel_map=args.channel_map, check_units=not args.no_unit_checks, overwrite=bool(args.overwrite),
            engine="serial" if args.serial else "ray", progress=not args.no_progress, max_retries=args.retries,
        )  # fmt: skip
    except RunnerError as exc:
        # the runner speaks of its API (engine='serial'); a CLI user has --serial
        raise ParameterError(str(exc).replace("engine='serial'", "--serial runs without Ray")) from None
    c = result.counts
    written = ", ".join(f for f in ("summary.csv", "summary.parquet", "vehicles.csv", "fleet.png")
                        if (Path(args.batch_out) / f).is_file())  # no summary.parquet without pyarrow
    print(f"wrote {args.batch_out}: {len(result.rows)} logs, {c['ok']} ok, {c['failed']} failed, {c['skipped']} skipped "
          f"(done before) in {result.wall_s:.1f} s; {written}")  # fmt: skip
    if c["failed"]:
        for row in result.rows:
            if row["status"] == "failed":
                print(f"tire-learning batch: failed: {row['name']}: {row['error']}", file=sys.stderr)
    return 0 if not c["failed"] else 1
