"""The ``tire-learning`` command.

Each subcommand lives in its own module of :mod:`tire_learning_env.commands` and defines
``register(subparsers)``, which adds its parser and sets ``func``; modules are discovered
automatically, so adding a subcommand never edits this file.

What this file adds to every subcommand, centrally:

- ``--overwrite`` where there is an ``--out``, and a check of ``--out`` *before* any work
  starts (:func:`tire_learning_env.io.check_output_dir`, or ``check_output_file`` for a
  subcommand that sets ``out_kind="file"``): a folder the package did not write, a folder
  holding an input, the current directory and its parents are never silently replaced.
- ``--no-unit-checks`` where there is a ``log`` input (the plausibility checks of
  :func:`tire_learning_env.io.read_log`), ``--no-progress`` everywhere.
- ``--seed`` everywhere: a subcommand with randomness defines its own (and passes it on);
  elsewhere it is accepted and documented as having no effect. Either way ``main`` seeds
  numpy's global generator with it.
- ``--quiet`` everywhere: the command's normal stdout lines are suppressed (stdout goes to
  :data:`os.devnull` while it runs); warnings and errors on stderr are never suppressed.
- Defaults shown in ``--help``.
- Errors as one line on stderr with exit code 2; Ctrl-C as one line with exit code 130.
  ``TIRE_LEARNING_DEBUG=1`` shows the traceback of an unexpected error.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import pkgutil
import sys
import warnings
from pathlib import Path
from typing import Iterator

from . import __version__, commands
from .io import LogFormatError, OutputPathError, check_output_dir, check_output_file, run_context
from .params import ParameterError

__all__ = ["main", "build_parser"]


class _HelpFormatter(argparse.HelpFormatter):
    """Shows ``(default: X)`` after an option's help unless the help already states it or
    the default is empty (None / False)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        help_text = action.help or ""
        default = action.default
        if (
            "default" in help_text.lower()
            or default is None
            or default is False
            or default is argparse.SUPPRESS
            or not action.option_strings
        ):
            return help_text
        return help_text + " (default: %(default)s)"


def _add_common_options(name: str, parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = _HelpFormatter
    options = parser._option_string_actions  # noqa: SLF001 (argparse has no public accessor)
    dests = {a.dest for a in parser._actions}  # noqa: SLF001
    if "--out" in options and "--overwrite" not in options:
        if parser.get_default("out_kind") == "file":
            text = ("replace an existing --out file (never one of this command's inputs); "
                    "without it an existing file is refused")
        else:
            text = ("replace --out even if it is a non-empty folder that tire-learning did not write "
                    "(everything in it is deleted). Never replaced, even with this flag: a folder that "
                    "holds an input, the current directory or its parents, the home directory. "
                    "Without it, --out must be new, empty, or a folder tire-learning wrote before "
                    "(it holds .tire_learning_manifest.json)")
        parser.add_argument("--overwrite", action="store_true", help=text)
    if "log" in dests and "--no-unit-checks" not in options:
        parser.add_argument("--no-unit-checks", action="store_true",
                            help="skip the log's unit plausibility checks (speed in km/h, angles in degrees, "
                            "time in ms, ...) when you are sure the units are SI")
    if "--no-progress" not in options:
        parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    if "--seed" not in options:
        parser.add_argument("--seed", type=int, default=None,
                            help=f"random seed; no effect: '{name}' is deterministic (accepted for a uniform CLI)")
    if "--quiet" not in options:
        parser.add_argument("--quiet", "-q", action="store_true",
                            help="print nothing on stdout (warnings and errors still go to stderr)")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tire-learning",
        description="Learn a car's tire model from lane-camera e1/e2 (and IMU) while it drives.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{commands.__name__}.{info.name}")
        module.register(sub)
    for name, subparser in sub.choices.items():
        _add_common_options(name, subparser)
    return parser


def _inputs(args: argparse.Namespace) -> list[Path]:
    """The command's input files: every path argument other than ``--out`` that exists."""
    found = []
    for key, value in vars(args).items():
        values = value if isinstance(value, (list, tuple)) else [value]
        for v in values:
            if key != "out" and isinstance(v, Path) and v.exists():
                found.append(v)
    return found


def check_output(args: argparse.Namespace) -> None:
    """Check ``args.out`` before any work (no-op without an ``out`` argument)."""
    out = getattr(args, "out", None)
    if out is None:
        return
    overwrite = bool(getattr(args, "overwrite", False))
    if getattr(args, "out_kind", "dir") == "file":
        check_output_file(out, overwrite, _inputs(args))
    else:
        check_output_dir(out, overwrite, _inputs(args))


@contextlib.contextmanager
def _warnings_as_lines(command: str) -> Iterator[None]:
    """Warnings print as ``tire-learning CMD: warning: ...`` (no source line)."""
    original = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):  # noqa: ANN001
        print(f"tire-learning {command}: warning: {message}", file=file or sys.stderr)

    warnings.showwarning = show
    try:
        yield
    finally:
        warnings.showwarning = original


@contextlib.contextmanager
def _progress_disabled(disabled: bool) -> Iterator[None]:
    """With ``disabled``, every tqdm bar created in the body is off."""
    if not disabled:
        yield
        return
    from tqdm.std import tqdm

    original = tqdm.__init__

    def init(self, *a, **kw):  # noqa: ANN001
        kw["disable"] = True
        original(self, *a, **kw)

    tqdm.__init__ = init
    try:
        yield
    finally:
        tqdm.__init__ = original


@contextlib.contextmanager
def _stdout_quiet(quiet: bool) -> Iterator[None]:
    """With ``quiet``, everything printed on stdout in the body goes to :data:`os.devnull`."""
    if not quiet:
        yield
        return
    with open(os.devnull, "w") as sink, contextlib.redirect_stdout(sink):
        yield


def _seed_global_rng(seed: int | None) -> None:
    """Seed numpy's global generator (code that draws from it is then reproducible)."""
    if seed is not None:
        import numpy as np

        np.random.seed(seed % 2**32)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    prefix = f"tire-learning {args.command}"
    try:
        with (
            run_context(overwrite=bool(getattr(args, "overwrite", False)), inputs=_inputs(args),
                        command=args.command, argv=tuple(sys.argv[1:] if argv is None else argv),
                        check_units=not getattr(args, "no_unit_checks", False)),
            _warnings_as_lines(args.command),
            _progress_disabled(bool(getattr(args, "no_progress", False))),
            _stdout_quiet(bool(getattr(args, "quiet", False))),
        ):
            check_output(args)
            _seed_global_rng(getattr(args, "seed", None))
            return int(args.func(args) or 0)
    except (LogFormatError, ParameterError, OutputPathError, FileExistsError) as exc:
        print(f"{prefix}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"{prefix}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{prefix}: interrupted; earlier results are unchanged", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - one line for the user, the traceback on request
        if os.environ.get("TIRE_LEARNING_DEBUG"):
            raise
        name = type(exc).__name__
        print(f"{prefix}: error: {name}: {exc} (set TIRE_LEARNING_DEBUG=1 for the traceback)", file=sys.stderr)
        return 2 if name == "InfeasibleLMIError" else 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
