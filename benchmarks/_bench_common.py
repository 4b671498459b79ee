"""Helpers shared by the benchmark scripts: one-core settings, timing, JSON output.

Named ``_bench_common``, not ``_common``: ``agents/`` has its own ``_common`` module, and a test process
that imports scripts from both folders would otherwise get whichever was imported first under that name.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import sys
import time
from typing import Callable

#: the thread counts a benchmark sets to one (unless already set) before numpy or numba is imported
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


def set_one_thread_env() -> None:
    """Default every :data:`THREAD_VARS` to one thread; call before importing numpy or numba.

    This module imports neither and calls it on import, so importing ``_bench_common`` before numpy is
    enough; ``bench_generalization`` also calls it by name at its top, before its own numpy import (a
    process that imported this module earlier does not run it again on import).
    numba refuses a ``NUMBA_NUM_THREADS`` that changes once its threads run: in a process that already
    imported numba (a test importing a benchmark) that one is left as it is (a later compile there raised
    "Cannot set NUMBA_NUM_THREADS").
    """
    for var in THREAD_VARS:
        if not (var == "NUMBA_NUM_THREADS" and "numba" in sys.modules):
            os.environ.setdefault(var, "1")


set_one_thread_env()


def pin_to_one_core() -> None:
    """Pin the process to one CPU (Linux) so 'one core' figures mean one core."""
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})


def median_time(fn: Callable[[], object], repeats: int = 5) -> float:
    """Median wall time [s] of ``repeats`` calls (after one warm-up call)."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def time_env_steps(env, action, seconds: float, warmup: int = 20) -> tuple[int, float]:
    """Step ``env`` with a fixed ``action`` for about ``seconds`` of wall time after ``warmup``
    steps (compilation, caches) and a ``reset(seed=0)``; returns (steps, elapsed s)."""
    for _ in range(warmup):
        env.step(action)
    env.reset(seed=0)
    n = 0
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        _, _, term, trunc, _ = env.step(action)
        n += 1
        if term or trunc:
            env.reset()
    return n, time.perf_counter() - t0


def chosen(parser, text: str, known, what: str) -> list[str]:
    """The comma-separated names of ``text``, each one of ``known``; an unknown one is ``parser``'s error naming it
    (``what``: the plural noun, e.g. ``"variant(s)"``)."""
    names = [c for c in text.split(",") if c]
    unknown = [c for c in names if c not in known]
    if unknown:
        parser.error(f"unknown {what} {unknown}; choose from {list(known)}")
    return names


def map_jobs(fn: Callable, jobs: list, workers: int, desc: str) -> list:
    """``fn`` over ``jobs`` in ``workers`` processes, in order, with a progress bar on stderr."""
    from concurrent.futures import ProcessPoolExecutor

    from tqdm import tqdm

    with ProcessPoolExecutor(workers) as pool:
        return list(tqdm(pool.map(fn, jobs), total=len(jobs), desc=desc, file=sys.stderr))


def emit(result: dict, path: str | None = None) -> None:
    """Print the result as JSON with the machine it ran on; with ``path``, also write it there atomically."""
    result["machine"] = {"python": sys.version.split()[0], "platform": platform.platform(), "cpu_count": os.cpu_count()}
    if path:
        from tire_learning_env.io import atomic_write_json

        atomic_write_json(path, result)
    print(json.dumps(result, indent=2))


def pacejka_truth(nominal, truth: dict) -> tuple:
    """``(truth_vehicle, (front_tire, rear_tire))`` of a low-order Pacejka truth drawn by the generalisation
    benchmark: the vehicle file ``nominal`` with its stiffness scaled by ``truth["stiffness_factor"]``, and per
    axle a Magic Formula of shape ``C``, ``E`` and peak ``D = mu F_z`` (static axle load) whose slope at zero is
    that stiffness (``B C D = 2 C_alpha``). Used by ``bench_generalization.build`` and the highway family."""
    from tire_learning_env.tires import PacejkaTire

    k_true = [nominal.Cf * truth["stiffness_factor"][0], nominal.Cr * truth["stiffness_factor"][1]]
    truth_vehicle = nominal.replace(Cf=k_true[0], Cr=k_true[1])
    loads = truth_vehicle.static_axle_loads
    tires = []
    for j in range(2):
        D = truth["mu"][j] * loads[j]
        C = truth["C"][j]
        tires.append(PacejkaTire(B=2.0 * k_true[j] / (C * D), C=C, D=D, E=truth["E"][j]))
    return truth_vehicle, tuple(tires)
