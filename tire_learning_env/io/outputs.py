"""Output folders and files of a command: the run context, the safety checks, the manifest and
:func:`atomic_directory` (a whole output directory appears complete or not at all, and nothing
already there is lost half-way)."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

from .writers import atomic_write_json, umask_mode

__all__ = [
    "MANIFEST_NAME",
    "OutputPathError",
    "RunContext",
    "current_run_context",
    "run_context",
    "record_run_info",
    "read_manifest",
    "check_output_dir",
    "check_output_file",
    "write_manifest",
    "atomic_directory",
]


MANIFEST_NAME = ".tire_learning_manifest.json"


class OutputPathError(FileExistsError):
    """An output path that must not be written or replaced; the message names it and says why."""


@dataclass
class RunContext:
    """What the running ``tire-learning`` command allows and records (set by :func:`run_context`).

    Attributes
    ----------
    overwrite : bool
        The user passed ``--overwrite``: a non-empty folder (or file) that the package did not
        write may be replaced. Folders that hold an input, the current directory, its parents
        and the home directory are never replaced.
    inputs : tuple of Path
        Input files of the command; never replaced, never deleted.
    command, argv : str, tuple of str
        Recorded in every output manifest.
    check_units : bool
        :func:`read_log` checks the log's units for plausibility (``--no-unit-checks`` turns
        this off).
    info : dict
        Extra facts recorded in the manifest (e.g. the vehicle used and where it came from).
    """

    overwrite: bool = False
    inputs: tuple[Path, ...] = ()
    command: str = ""
    argv: tuple[str, ...] = ()
    check_units: bool = True
    info: dict = field(default_factory=dict)


_CONTEXT: list[RunContext] = [RunContext()]


def current_run_context() -> RunContext:
    """The innermost active :class:`RunContext` (a permissive-nothing default outside the CLI)."""
    return _CONTEXT[-1]


@contextlib.contextmanager
def run_context(**kwargs: Any) -> Iterator[RunContext]:
    """Activate a :class:`RunContext` for the body (the CLI wraps every command in one)."""
    kwargs["inputs"] = tuple(Path(p) for p in kwargs.get("inputs", ()))
    ctx = RunContext(**kwargs)
    _CONTEXT.append(ctx)
    try:
        yield ctx
    finally:
        for i in range(len(_CONTEXT) - 1, 0, -1):
            if _CONTEXT[i] is ctx:
                del _CONTEXT[i]
                break


def record_run_info(key: str, value: Any) -> None:
    """Record ``value`` under ``key`` in the manifests of the outputs written from now on."""
    current_run_context().info[key] = value


def _real(path: str | Path) -> Path:
    return Path(os.path.realpath(os.path.abspath(os.fspath(path))))


def _is_within(child: Path, parent: Path) -> bool:
    return child == parent or parent in child.parents


def _protected_reason(real: Path) -> str | None:
    """Why ``real`` (a resolved path) may never be replaced, or None."""
    cwd = _real(os.getcwd())
    if _is_within(cwd, real):
        return "it is the current directory or one of its parents"
    home = _real(Path.home())
    if _is_within(home, real):
        return "it is the home directory or one of its parents"
    if real == Path(real.anchor):
        return "it is a file-system root"
    return None


def _files_in(folder: Path) -> list[str]:
    """Relative paths of every file (and symlink) below ``folder``, sorted."""
    found = []
    for root, dirs, files in os.walk(folder):
        rel = Path(root).relative_to(folder)
        for name in files + [d for d in dirs if os.path.islink(os.path.join(root, d))]:
            found.append((rel / name).as_posix())
    return sorted(found)


def read_manifest(folder: str | Path) -> dict | None:
    """The manifest a previous run wrote into ``folder``, or None (absent or unreadable)."""
    try:
        doc = json.loads((Path(folder) / MANIFEST_NAME).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or doc.get("written_by") != "tire_learning_env" or not isinstance(doc.get("files"), list):
        return None
    return doc


def _foreign_files(folder: Path) -> list[str]:
    """Files in ``folder`` that no manifest of the package lists (all of them without a manifest)."""
    files = [f for f in _files_in(folder) if f != MANIFEST_NAME]
    manifest = read_manifest(folder)
    listed = set(manifest["files"]) if manifest else set()
    return [f for f in files if f not in listed]


def _short_list(names: list[str], n: int = 5) -> str:
    shown = ", ".join(repr(x) for x in names[:n])
    return shown + (f" and {len(names) - n} more" if len(names) > n else "")


def _inputs_inside(real: Path, inputs: tuple[Path, ...] | list) -> list[Path]:
    return [p for p in inputs if _is_within(_real(p), real)]


def _check_creatable(path: Path, what: str) -> None:
    """Raise :class:`OutputPathError` unless ``path``'s parent exists or can be created and is
    writable (probed by creating and removing a temporary directory)."""
    parent = path.parent
    existing = parent
    while not existing.exists():
        if existing.parent == existing:
            break
        existing = existing.parent
    if not existing.is_dir():
        raise OutputPathError(f"cannot write {what} {path}: {existing} is a file, not a folder")
    try:
        probe = tempfile.mkdtemp(dir=existing, prefix=".tire_learning_probe.")
        os.rmdir(probe)
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise OutputPathError(f"cannot write {what} {path}: folder {existing} is not writable ({reason})") from None


def _replace_refusal(out: Path, force: bool, inputs) -> str | None:
    """Why the existing directory ``out`` must not be replaced, or None if it may be."""
    real = _real(out)
    reason = _protected_reason(real)
    if reason:
        return f"refusing to replace {out}: {reason}; choose a new sub-folder for --out"
    held = _inputs_inside(real, inputs)
    if held:
        return (f"refusing to replace {out}: it holds the input {_short_list([str(p) for p in held])}, which would be "
                "deleted (even with --overwrite); choose another --out folder")
    foreign = _foreign_files(out)
    if foreign and not force:
        has_manifest = read_manifest(out) is not None
        why = (f"holds files that tire-learning did not write ({_short_list(foreign)})" if has_manifest else
               f"is not empty and was not written by tire-learning (no {MANIFEST_NAME}; it holds {_short_list(foreign)})")
        return (f"refusing to replace {out}: it {why}; replacing it would delete them. Choose a new folder, "
                "or pass --overwrite to replace it and everything in it")
    return None


def check_output_dir(path: str | Path, overwrite: bool = False, inputs=()) -> Path:
    """Check, before any work, that a command may write the output folder ``path``.

    A folder that does not exist, an empty folder, or one the package wrote before (it
    holds the manifest ``.tire_learning_manifest.json`` listing every file in it) may be
    replaced. A non-empty folder the package did not write is refused unless ``overwrite``.
    Never replaced, whatever ``overwrite`` says: a folder that holds one of ``inputs``, the
    current directory or one of its parents, the home directory, a file-system root.
    The parent must exist or be creatable, and be writable.

    Raises
    ------
    OutputPathError
        Naming the folder and what to do.
    """
    out = Path(path)
    if str(path).strip() == "":
        raise OutputPathError("--out is empty; name an output folder")
    if out.exists() or out.is_symlink():
        if not out.is_dir():
            raise OutputPathError(f"--out {out} is a file, not a folder; choose a folder path")
        refusal = _replace_refusal(out, overwrite, tuple(inputs))
        if refusal:
            raise OutputPathError(refusal)
    reason = _protected_reason(_real(out))
    if reason:
        raise OutputPathError(f"refusing to write results as {out}: {reason}; choose a new sub-folder for --out")
    _check_creatable(_real(out), "the output folder")
    return out


def check_output_file(path: str | Path, overwrite: bool = False, inputs=()) -> Path:
    """Check that a command may write the output file ``path``.

    An existing file is replaced only with ``overwrite`` (and never when it is one of
    ``inputs``); a folder is never replaced. The parent must exist or be creatable, and be
    writable.

    Raises
    ------
    OutputPathError
    """
    out = Path(path)
    if str(path).strip() == "":
        raise OutputPathError("--out is empty; name an output file")
    if out.is_dir():
        raise OutputPathError(f"--out {out} is a folder; this command writes one file, give a file path")
    if out.exists():
        if _inputs_inside(_real(out), tuple(inputs)):
            raise OutputPathError(f"refusing to overwrite {out}: it is an input of this command (even with --overwrite)")
        if not overwrite:
            raise OutputPathError(f"refusing to overwrite the existing file {out}; choose another name, "
                                  "or pass --overwrite to replace it")
    _check_creatable(_real(out), "the output file")
    return out


def write_manifest(folder: Path, out: Path) -> None:
    """Write the manifest of the output ``folder`` (to become ``out``): command, time, inputs, every file in it."""
    ctx = current_run_context()
    doc = {
        "written_by": "tire_learning_env",
        "version": _package_version(),
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "command": ctx.command,
        "argv": list(ctx.argv),
        "output": str(out),
        "inputs": [str(p) for p in ctx.inputs],
        **{k: v for k, v in ctx.info.items() if k not in ("files",)},
        "files": _files_in(folder),
    }
    atomic_write_json(folder / MANIFEST_NAME, doc)


def _package_version() -> str:
    try:
        from .. import __version__

        return str(__version__)
    except ImportError:  # pragma: no cover
        return "unknown"


@contextlib.contextmanager
def atomic_directory(out: str | Path, overwrite: bool = True, *, force: bool | None = None) -> Iterator[Path]:
    """Fill a fresh temporary directory, then swap it in as ``out`` at the end.

    If the body raises, ``out`` is left exactly as it was. The new folder gets a manifest
    (``.tire_learning_manifest.json``: command, time, inputs, every file written), which is
    what lets a later run replace it.

    An existing ``out`` is replaced only after the body succeeded, and only if it is empty or
    the package wrote it (its manifest lists every file in it). A non-empty folder the
    package did not write is refused (:class:`OutputPathError`) unless ``force`` is true;
    ``force=None`` takes the ``--overwrite`` flag of the running command (false outside the
    CLI). A folder that holds an input of the command, the current directory, its parents
    and the home directory are never replaced. The check runs before the body and again
    before the swap.

    Parameters
    ----------
    out : str or Path
        The output folder.
    overwrite : bool
        False refuses any existing ``out`` (:class:`FileExistsError`).
    force : bool or None
        Replace a folder the package did not write (see above).
    """
    out = Path(out)
    ctx = current_run_context()
    force = ctx.overwrite if force is None else force
    if (out.exists() or out.is_symlink()) and not out.is_dir():
        raise OutputPathError(f"{out} exists and is not a directory")
    if out.exists() and not overwrite:
        raise FileExistsError(f"{out} exists; pass overwrite=True (or --overwrite) to replace it")

    def check() -> None:
        if out.exists():
            refusal = _replace_refusal(out, force, ctx.inputs)
            if refusal:
                raise OutputPathError(refusal)
        else:
            reason = _protected_reason(_real(out))
            if reason:
                raise OutputPathError(f"refusing to write results as {out}: {reason}")

    check()
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".tmp"))
    os.chmod(tmp, umask_mode(0o777))
    try:
        yield tmp
        write_manifest(tmp, out)
        check()  # again: files may have appeared in out while the body ran
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    old = None
    if out.exists():
        old = out.parent / f".{out.name}.old.{os.getpid()}"
        os.replace(out, old)
    os.replace(tmp, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
