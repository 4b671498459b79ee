"""Key numba's on-disk cache of a family of compiled modules on the family's whole source.

numba's cache (``@njit(cache=True)``) keys a compiled function on the modification time and
size of *its own* source file only. A compiled function carries the machine code of every
compiled function it calls, so when a callee defined in *another* file changes, the caller's
cache still matches and the next process silently runs the old callee (measured with numba
0.68: ``tests/test_jit_cache.py``). Modules that call each other's compiled functions form a
*family*; :func:`key_on_family` adds the SHA-256 of all the family's source files to the
stamp numba stores in each function's cache index and compares on load. Any edit to any file
of the family then makes every cached function of the family stale, and numba recompiles and
overwrites it the usual way.

Why the stamp and not a guard that deletes cache files: nothing is deleted or written here, so

- a read-only install needs nothing (numba picks its cache folder as before; when it cannot
  cache, it does not, as before);
- concurrent processes (Ray workers, test workers) cannot race: each compares the index it
  reads with the stamp of the source *it* runs, and numba writes an index atomically
  (temporary file + ``os.replace``). A process still running an older source writes its
  index with the older digest, which a process with the newer source treats as stale
  (a deleting guard would let such a process re-store stale code under a fresh stamp file).

The stamp lives in numba's private ``Dispatcher._cache._cache_file._source_stamp`` (numba
0.49 to at least 0.68). When that attribute is missing (another numba, ``NUMBA_DISABLE_JIT``,
no cache) or the source cannot be read, nothing is changed and numba behaves as it always
does; ``tests/test_jit_cache.py`` fails then, so the loss does not go unnoticed.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Mapping
from functools import lru_cache
from pathlib import Path

__all__ = ["family_digest", "key_on_family", "STAMP_TAG"]

#: First element of a family stamp: ``(STAMP_TAG, digest, numba's own stamp)``.
STAMP_TAG = "tire_learning_env family sha256"


@lru_cache(maxsize=None)
def _digest(paths: tuple[str, ...]) -> str | None:
    h = hashlib.sha256()
    try:
        for path in paths:
            data = Path(path).read_bytes()
            h.update(f"{Path(path).name}\0{len(data)}\0".encode())
            h.update(data)
    except OSError:
        return None
    return h.hexdigest()


def family_digest(files: Iterable[str | Path]) -> str | None:
    """SHA-256 of the family's source files (in the given order), ``None`` when one is unreadable.

    Parameters
    ----------
    files : iterable of str or Path
        The family's source files.

    Returns
    -------
    str or None
        Hex digest, computed once per process and family.
    """
    return _digest(tuple(str(f) for f in files))


def key_on_family(namespace: Mapping[str, object], files: Iterable[str | Path]) -> int:
    """Stamp the cache of every compiled function *defined* in ``namespace`` with the family's digest.

    Call it at the end of each module of the family, before any of its functions runs
    (numba reads the cache at a function's first call, not when it is decorated).

    Parameters
    ----------
    namespace : mapping
        The module's ``globals()``. Functions it imports from other modules are left to
        their own module's call.
    files : iterable of str or Path
        The family's source files: every file whose compiled functions (or module-level
        constants frozen into compiled code) the module's functions reach.

    Returns
    -------
    int
        How many functions were stamped (0: no digest, or no numba cache to stamp).
    """
    digest = family_digest(files)
    if digest is None:
        return 0
    module = namespace.get("__name__")
    n = 0
    for obj in namespace.values():
        py_func = getattr(obj, "py_func", None)
        if py_func is None or getattr(py_func, "__module__", None) != module:
            continue
        cache_file = getattr(getattr(obj, "_cache", None), "_cache_file", None)
        stamp = getattr(cache_file, "_source_stamp", None)
        if stamp is None:
            continue
        if isinstance(stamp, tuple) and len(stamp) == 3 and stamp[0] == STAMP_TAG:
            stamp = stamp[2]  # stamped before: replace the digest, keep numba's stamp
        cache_file._source_stamp = (STAMP_TAG, digest, stamp)
        n += 1
    return n
