"""A simulated multi-node Ray cluster on one machine, and a batch whose node is killed mid-run.

:func:`kill_node_run` starts a head node without CPUs (so every task runs on a worker node)
and ``worker_nodes`` raylets (``ray.cluster_utils.Cluster``), maps a sleeping task over
``n_items`` items with :func:`~tire_learning_env.fleet.runner.run_items`, and hard-kills
one worker node (its raylet and its workers, no graceful shutdown) after ``kill_after``
results are in. Ray re-runs the killed node's tasks on the surviving nodes; the results
already recorded stay in the store. Used by ``benchmarks/bench_fleet.py`` and the slow test.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from .runner import ResultStore, run_items

__all__ = ["kill_node_run"]


def _work(item: tuple[int, float]) -> dict:
    """Sleep ``item[1]`` s and return the item number (a stand-in for one log)."""
    i, seconds = item
    time.sleep(seconds)
    import ray

    return {"item": i, "square": i * i, "node": ray.get_runtime_context().get_node_id(), "pid": os.getpid(),
            "finished_at": time.time()}  # fmt: skip


def kill_node_run(store: str | Path, n_items: int = 12, task_s: float = 1.0, worker_nodes: int = 2,
                  cpus_per_node: int = 1, kill_after: int = 3, max_retries: int = 3) -> dict:  # fmt: skip
    """Run ``n_items`` tasks on a simulated cluster and kill a worker node mid-batch.

    Parameters
    ----------
    store : str or Path
        The runner's JSON-lines store.
    n_items : int
        Tasks in the batch.
    task_s : float
        Duration of each task [s].
    worker_nodes, cpus_per_node : int
        Raylets besides the head, and the CPUs of each.
    kill_after : int
        The node is killed when this many results are recorded.
    max_retries : int
        Ray re-executions of a task whose node died.

    Returns
    -------
    dict
        ``items``, ``ok``, ``failed``, ``stored_records`` (lines in the store), ``lost``
        (results recorded before the kill that are missing afterwards: must be 0),
        ``killed_node``, ``results_from_killed_node`` (recorded before it died),
        ``collected_after_kill_from_killed_node`` (finished by the victim before it died but
        collected after the kill: legitimate), ``finished_after_kill_on_killed_node`` (must be 0),
        ``recorded_before_kill``, ``wall_s`` and the per-item results.
    """
    from ray.cluster_utils import Cluster

    store = Path(store)
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0, "include_dashboard": False})
    try:
        nodes = [cluster.add_node(num_cpus=cpus_per_node, include_dashboard=False) for _ in range(worker_nodes)]
        cluster.wait_for_nodes()
        victim = nodes[0]
        victim_id = victim.node_id
        before: list = []
        state = {"killed_at": None, "killed_wall": None}

        def on_result(rec) -> None:
            if state["killed_at"] is None and rec.status == "ok":
                before.append(rec)
                if len(before) >= kill_after:
                    cluster.remove_node(victim, allow_graceful=False)
                    state["killed_at"] = time.perf_counter()
                    state["killed_wall"] = time.time()  # the node is dead from here on

        t0 = time.perf_counter()
        results = run_items(_work, [(i, task_s) for i in range(n_items)], keys=[f"item{i:03d}" for i in range(n_items)],
                            store=store, address=cluster.address, max_retries=max_retries, progress=False,
                            on_result=on_result)  # fmt: skip
        wall = time.perf_counter() - t0
    finally:
        cluster.shutdown()
    stored = ResultStore(store).load()
    lost = [r.key for r in before if r.key not in stored or stored[r.key].status != "ok"]
    return {
        "items": n_items,
        "ok": sum(r.status == "ok" for r in results),
        "failed": sum(r.status == "failed" for r in results),
        "errors": sorted({r.error for r in results if r.error}),
        "stored_records": len(stored),
        "recorded_before_kill": len(before),
        "lost": len(lost),
        "killed": state["killed_at"] is not None,
        "killed_node": victim_id,
        "results_from_killed_node": sum(1 for r in before if isinstance(r.result, dict) and r.result.get("node") == victim_id),
        # a task the victim finished just before it died can reach the driver after the kill: legitimate;
        # a result the victim *finished* after it was killed would mean the kill did not happen
        "collected_after_kill_from_killed_node": sum(
            1 for r in results if r.key not in {b.key for b in before} and isinstance(r.result, dict)
            and r.result.get("node") == victim_id),
        "finished_after_kill_on_killed_node": sum(
            1 for r in results if isinstance(r.result, dict) and r.result.get("node") == victim_id
            and state["killed_wall"] is not None and r.result.get("finished_at", 0.0) > state["killed_wall"]),
        "nodes_used": len({r.result.get("node") for r in results if isinstance(r.result, dict)}),
        "wall_s": wall,
        "task_s": task_s,
        "worker_nodes": worker_nodes,
    }
