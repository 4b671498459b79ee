"""Map a function over many work items as Ray tasks, streaming results to disk.

:func:`run_items` is the one runner the batch command, the benchmarks and the multi-seed
training use::

    from tire_learning_env.fleet import run_items
    results = run_items(score_scenario, scenarios, keys=[s.name for s in scenarios],
                        store="results/gen.jsonl", workers=2)

- **Ray as the engine.** Local Ray by default (``ray.init(num_cpus=workers)``, started and
  stopped here; a Ray session already running in the process is used and left running);
  ``address="auto"`` or ``"HOST:PORT"`` joins an existing cluster. ``engine="serial"``
  runs the same loop in this process without Ray (no extra needed; for debugging and for
  the 1-worker baselines).
- **Failures are rows, not crashes.** An exception raised by ``fn`` is caught in the task
  and recorded (``status="failed"``, ``error`` = one line naming the exception); Ray is not
  asked to retry it (a corrupt log stays corrupt). A *worker* or *node* that dies
  (``WorkerCrashedError``, ``NodeDiedError``, ``OwnerDiedError``, an object lost with its
  node) is retried by Ray up to ``max_retries`` times, then recorded as failed.
- **Streaming and resume.** With ``store``, every finished item is appended to a JSON-lines
  file and flushed to disk (``fsync``) the moment it finishes, so a run killed at any point
  loses no finished result. A later run with the same store skips the items whose stored
  record is ``ok`` and whose fingerprint (if given) is unchanged; they come back with
  ``status="skipped"`` and their stored result. A line cut by a kill is ignored.
"""

from __future__ import annotations

import json
import os
import socket
import sys
import time
import traceback
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

__all__ = ["ItemResult", "ResultStore", "run_items", "RunnerError", "ray_available", "THREAD_ENV"]

# One BLAS/numba thread per task, and one thread for the pieces of the offline fit's passes
# (observer.passes.pass_threads; the pieces, hence the answer, are the same on any thread count):
# parallelism comes from the tasks (2 tasks on 2 cores, not 2 x 2 threads).
THREAD_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1",
              "TIRE_LEARNING_THREADS": "1"}


class RunnerError(RuntimeError):
    """The runner cannot start (Ray missing, a cluster unreachable, duplicate keys, ...)."""


@dataclass
class ItemResult:
    """What happened to one work item.

    Attributes
    ----------
    key : str
        The item's unique key.
    status : {"ok", "failed", "skipped"}
        ``skipped``: done by an earlier run with the same store (``result`` is that run's).
    result : Any
        ``fn(item)``'s return value (JSON-able when a store is used); None when failed.
    error : str
        One line naming what went wrong (empty when ok).
    runtime_s : float
        Wall time of ``fn(item)`` in the task [s] (the earlier run's when skipped).
    cpu_s : float
        CPU time of the task's process during ``fn(item)`` [s]; ``cpu_s / runtime_s`` below 1
        means the task waited for a core (a loaded machine).
    worker : str
        ``host:pid`` that ran it.
    node : str
        Ray node id that ran it (empty in the serial engine).
    fingerprint : str
        The fingerprint given for the item (empty if none).
    finished_at : float
        Unix time the result was recorded [s].
    """

    key: str
    status: str
    result: Any = None
    error: str = ""
    runtime_s: float = float("nan")
    cpu_s: float = float("nan")
    worker: str = ""
    node: str = ""
    fingerprint: str = ""
    finished_at: float = 0.0

    def to_json(self) -> str:
        return json.dumps(asdict(self), default=_json_default, allow_nan=True)


def _json_default(obj: Any) -> Any:
    try:
        import numpy as np

        if isinstance(obj, np.ndarray):
            return obj.tolist()
        if isinstance(obj, (np.generic,)):
            return obj.item()
    except ImportError:  # pragma: no cover
        pass
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"result not JSON serialisable: {type(obj).__name__}")


class ResultStore:
    """Append-only JSON-lines file of :class:`ItemResult` records (the resume state).

    Each record is written with one ``write`` of a whole line, flushed and ``fsync``-ed, so
    a kill leaves at most one partial last line, which :meth:`load` ignores. The latest
    record of a key wins.

    Parameters
    ----------
    path : str or Path
        The ``.jsonl`` file (created with its folder when absent).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh = None

    def load(self) -> dict[str, ItemResult]:
        """The latest stored record of every key (unreadable lines skipped)."""
        out: dict[str, ItemResult] = {}
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return out
        names = set(ItemResult.__dataclass_fields__)
        for line in text.splitlines():
            try:
                doc = json.loads(line)
                rec = ItemResult(**{k: v for k, v in doc.items() if k in names})
            except (ValueError, TypeError):
                continue  # a line cut by a kill
            out[rec.key] = rec
        return out

    def append(self, rec: ItemResult) -> None:
        """Write ``rec`` durably (one line, flushed and fsync-ed)."""
        if self._fh is None:
            needs_newline = self.path.exists() and self.path.stat().st_size > 0 and not self.path.read_bytes().endswith(b"\n")
            self._fh = open(self.path, "a", encoding="utf-8")
            if needs_newline:  # the cut line of a killed run stays on its own line
                self._fh.write("\n")
        self._fh.write(rec.to_json() + "\n")
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


def ray_available() -> bool:
    """True when Ray can be imported (the ``fleet`` extra is installed)."""
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    if len(text) > 500:
        text = text[:497] + "..."
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _call(fn: Callable[[Any], Any], item: Any) -> dict:
    """Run ``fn(item)``, catching its exception; what a task returns."""
    t0, c0 = time.perf_counter(), time.process_time()
    out = {"worker": f"{socket.gethostname()}:{os.getpid()}", "node": ""}
    if "ray" in sys.modules:
        try:
            import ray

            if ray.is_initialized():
                out["node"] = ray.get_runtime_context().get_node_id()
        except Exception:  # noqa: BLE001 - the node id is informative only
            pass
    try:
        out.update(status="ok", result=fn(item), error="")
    except Exception as exc:  # noqa: BLE001 - a failing item is a row, never a crash of the run
        out.update(status="failed", result=None, error=_one_line(exc))
        if os.environ.get("TIRE_LEARNING_DEBUG"):
            out["traceback"] = traceback.format_exc()
    out["runtime_s"] = time.perf_counter() - t0
    out["cpu_s"] = time.process_time() - c0
    return out


def _progress(total: int, desc: str, enabled: bool, initial: int = 0):
    from tqdm.auto import tqdm

    return tqdm(total=total, initial=initial, desc=desc, unit=desc.rstrip("s") or "item", disable=not enabled, dynamic_ncols=True,
                file=sys.stderr)  # fmt: skip


def _probe(address: str, timeout: float = 5.0) -> None:
    """Fail fast, naming the address, when nothing listens at ``HOST:PORT`` (``ray.init`` would
    retry for minutes). ``auto`` and other forms are left to Ray."""
    target = address.split("://", 1)[-1]
    host, sep, port = target.rpartition(":")
    if not sep or not port.isdigit() or address == "auto":
        return
    try:
        socket.create_connection((host or "127.0.0.1", int(port)), timeout=timeout).close()
    except OSError as exc:
        raise RunnerError(f"cannot reach the Ray cluster at {address}: {exc.strerror or exc} (is `ray start --head` "
                          "running there, and is the port right?)") from None  # fmt: skip


def _start_ray(workers: int | None, address: str | None, ray_init_kwargs: dict | None):
    try:
        import ray
    except ImportError:
        raise RunnerError("the Ray engine needs Ray: pip install 'tire_learning_env[fleet]' (or engine='serial')") from None
    if address:
        _probe(address)
    if ray.is_initialized():  # a session of the caller (e.g. a test's, or a notebook's): used and left running
        return ray, False
    kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False, "configure_logging": False,
                              "runtime_env": {"env_vars": dict(THREAD_ENV)}}  # fmt: skip
    if address:
        kwargs["address"] = address
    else:
        kwargs["num_cpus"] = int(workers or os.cpu_count() or 1)
        kwargs["object_store_memory"] = 128 * 1024**2
    extra = dict(ray_init_kwargs or {})
    env_vars = dict(extra.pop("runtime_env", {}) or {})
    kwargs["runtime_env"] = {**env_vars, "env_vars": {**THREAD_ENV, **env_vars.get("env_vars", {})}}
    kwargs.update(extra)
    try:
        ray.init(**kwargs)
    except Exception as exc:  # noqa: BLE001 - e.g. no cluster at address
        where = f"the Ray cluster at {address}" if address else "a local Ray instance"
        raise RunnerError(f"cannot start or join {where}: {_one_line(exc)}") from None
    return ray, True


def run_items(
    fn: Callable[[Any], Any],
    items: Sequence[Any],
    *,
    keys: Sequence[str] | None = None,
    fingerprints: Sequence[str] | None = None,
    store: str | Path | ResultStore | None = None,
    workers: int | None = None,
    address: str | None = None,
    engine: str = "ray",
    max_retries: int = 3,
    num_cpus_per_item: float = 1.0,
    progress: bool = True,
    desc: str = "items",
    on_result: Callable[[ItemResult], None] | None = None,
    ray_init_kwargs: dict | None = None,
) -> list[ItemResult]:
    """Run ``fn(item)`` for every item, in parallel, recording each outcome.

    Parameters
    ----------
    fn : callable
        ``fn(item) -> result``; a module-level function or a picklable callable (Ray ships it
        to the workers with cloudpickle). Its exceptions become ``failed`` results.
    items : sequence
        Work items (picklable).
    keys : sequence of str, optional
        A unique key per item (the resume identity); default ``"0"``, ``"1"``, ...
    fingerprints : sequence of str, optional
        Per item, what must be unchanged for a stored ``ok`` result to be reused (e.g. the
        input file's size and mtime and the options); a changed fingerprint re-runs the item.
    store : str, Path or ResultStore, optional
        JSON-lines file where each result is appended as it finishes (and read to resume).
    workers : int, optional
        Local Ray: CPUs given to Ray (= parallel tasks); default all cores. Serial: ignored.
    address : str, optional
        Join an existing Ray cluster (``"auto"``, ``"HOST:PORT"``, ``"ray://HOST:10001"``)
        instead of starting a local one; the cluster's CPUs set the parallelism.
    engine : {"ray", "serial"}
        ``serial`` runs in this process without Ray (same results, store and resume).
    max_retries : int
        Ray re-executions of a task whose worker or node died (not of exceptions of ``fn``).
    num_cpus_per_item : float
        CPUs Ray reserves per task.
    progress : bool
        A tqdm bar counting items (skipped ones included in the count).
    desc : str
        The bar's label.
    on_result : callable, optional
        Called in this process with every :class:`ItemResult` as it finishes, in completion
        order, skipped items first; called *before* the result is appended to the store, so
        whatever it writes (the batch's ``summary.csv`` row) is on disk no later than the
        record that makes a re-run skip the item.
    ray_init_kwargs : dict, optional
        Extra keywords for ``ray.init`` when the runner starts or joins Ray; ``runtime_env``
        ``env_vars`` are added to :data:`THREAD_ENV` (e.g. a ``PYTHONPATH`` for the workers).

    Returns
    -------
    list of ItemResult
        In the order of ``items``.

    Raises
    ------
    RunnerError
        Duplicate keys, an unknown engine, Ray missing or a cluster unreachable.
    """
    n = len(items)
    keys = [str(i) for i in range(n)] if keys is None else [str(k) for k in keys]
    if len(keys) != n:
        raise RunnerError(f"{len(keys)} keys for {n} items")
    if len(set(keys)) != n:
        dup = sorted({k for k in keys if keys.count(k) > 1})[:5]
        raise RunnerError(f"duplicate item keys {dup}: every item needs a unique key")
    prints = [""] * n if fingerprints is None else [str(f) for f in fingerprints]
    if len(prints) != n:
        raise RunnerError(f"{len(prints)} fingerprints for {n} items")
    if engine not in ("ray", "serial"):
        raise RunnerError(f"engine must be 'ray' or 'serial', got {engine!r}")
    if workers is not None and workers < 1:
        raise RunnerError(f"workers must be >= 1, got {workers}")
    own_store = store is not None and not isinstance(store, ResultStore)
    store = ResultStore(store) if own_store else store
    results: list[ItemResult | None] = [None] * n
    done = store.load() if store is not None else {}
    todo = []
    for i, (k, fp) in enumerate(zip(keys, prints)):
        old = done.get(k)
        if old is not None and old.status in ("ok", "skipped") and old.fingerprint == fp:
            results[i] = ItemResult(k, "skipped", old.result, "", old.runtime_s, old.cpu_s, old.worker, old.node, fp,
                                    old.finished_at)  # fmt: skip
        else:
            todo.append(i)

    def record(i: int, out: dict) -> None:
        rec = ItemResult(keys[i], out["status"], out.get("result"), out.get("error", ""), float(out.get("runtime_s", "nan")),
                         float(out.get("cpu_s", "nan")), out.get("worker", ""), out.get("node", ""), prints[i], time.time())  # fmt: skip
        results[i] = rec
        if on_result is not None:  # first: what it writes is on disk no later than the store's record
            on_result(rec)
        if store is not None:
            store.append(rec)

    ray_session = _start_ray(workers, address, ray_init_kwargs) if todo and engine == "ray" else None  # errors before the bar
    bar = _progress(n, desc, progress, initial=n - len(todo))
    try:
        if on_result is not None:
            for r in results:
                if r is not None:
                    on_result(r)
        if todo and engine == "serial":
            for i in todo:
                record(i, _call(fn, items[i]))
                bar.update(1)
        elif todo:
            _run_ray(ray_session, fn, items, todo, record, bar, workers, max_retries, num_cpus_per_item)
    finally:
        bar.close()
        if own_store:
            store.close()
        if ray_session is not None and ray_session[1] and ray_session[0].is_initialized():
            ray_session[0].shutdown()  # started here and not yet stopped (an error before the tasks ran)
    return [r for r in results if r is not None]


_LOST = ("WorkerCrashedError", "NodeDiedError", "OwnerDiedError", "ObjectLostError", "ObjectReconstructionFailedError",
         "ObjectReconstructionFailedMaxAttemptsExceededError", "ObjectFetchTimedOutError", "TaskUnschedulableError",
         "ActorDiedError", "RaySystemError", "LocalRayletDiedError")  # fmt: skip


def _run_ray(session, fn, items, todo, record, bar, workers, max_retries, num_cpus_per_item) -> None:
    ray, started = session
    try:
        remote = ray.remote(_call).options(max_retries=max_retries, retry_exceptions=False, num_cpus=num_cpus_per_item)
        fn_ref = ray.put(fn)
        cpus = int(ray.cluster_resources().get("CPU", workers or 1))
        window = max(4 * max(cpus, 1), 8)  # tasks in flight: enough to keep every CPU busy, not all of a 10k fleet
        pending: dict[Any, int] = {}
        queue = list(todo)
        while queue or pending:
            while queue and len(pending) < window:
                i = queue.pop(0)
                pending[remote.remote(fn_ref, items[i])] = i
            ready, _ = ray.wait(list(pending), num_returns=1)
            for ref in ready:
                i = pending.pop(ref)
                try:
                    out = ray.get(ref)
                except Exception as exc:  # noqa: BLE001 - the worker/node died max_retries + 1 times
                    name = type(exc).__name__
                    what = "worker or node lost" if any(x in name for x in _LOST) else "task error"
                    out = {"status": "failed", "result": None, "error": f"{what} after {max_retries + 1} attempts: "
                           f"{_one_line(exc)}", "runtime_s": float("nan")}  # fmt: skip
                record(i, out)
                bar.update(1)
    finally:
        if started:
            ray.shutdown()
