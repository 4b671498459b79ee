"""Atomic writers: a file appears complete or not at all (text, JSON, CSV tables and logs)."""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from numpy.typing import NDArray

from .log import KNOWN_COLUMNS

__all__ = ["write_table", "write_log", "atomic_write_text", "atomic_write_json", "to_jsonable", "umask_mode"]


def write_table(path: str | Path, columns: Mapping[str, NDArray]) -> Path:
    """Write equal-length numeric columns as CSV (header row, NaN as empty), atomically."""
    names = list(columns)
    n = {len(np.asarray(columns[c])) for c in names}
    if len(n) != 1:
        raise ValueError(f"columns have different lengths: { {c: len(columns[c]) for c in names} }")
    table = np.column_stack([np.asarray(columns[c], dtype=float) for c in names])
    body = "\n".join(",".join("" if v != v else "%.10g" % v for v in row) for row in table)
    return atomic_write_text(path, ",".join(names) + "\n" + body + "\n")


def write_log(path: str | Path, columns: Mapping[str, NDArray]) -> Path:
    """Write a shared-format log CSV, atomically: known columns first, in their order."""
    names = [c for c in KNOWN_COLUMNS if c in columns] + [c for c in columns if c not in KNOWN_COLUMNS]
    return write_table(path, {c: columns[c] for c in names})



def umask_mode(mode: int = 0o666) -> int:
    """``mode`` with the process umask applied (what ``open()`` would give a new file)."""
    mask = os.umask(0)
    os.umask(mask)
    return mode & ~mask


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` via a temporary file and ``os.replace`` (normal file permissions)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.chmod(tmp, umask_mode())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return path


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, np.bool_):
        return bool(obj)
    if hasattr(obj, "to_dict"):
        return obj.to_dict()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def to_jsonable(obj: Any) -> Any:
    """``obj`` with numpy values turned into plain Python (NaN becomes ``None``)."""
    return json.loads(json.dumps(obj, default=_json_default, allow_nan=True).replace("NaN", "null"))


def atomic_write_json(path: str | Path, obj: Any) -> Path:
    """Write ``obj`` as indented JSON, atomically (numpy values converted; NaN -> null)."""
    return atomic_write_text(path, json.dumps(to_jsonable(obj), indent=2, allow_nan=False) + "\n")


