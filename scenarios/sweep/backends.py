"""The sweep's backends: every cell still to run, in a local process pool (or in this process) or on a Ray
cluster; each result is written as its cell's JSON file as it arrives, so an interrupted sweep resumes."""

from __future__ import annotations

import json
from pathlib import Path

from scenarios.sweep.cells import _run_and_store, run_cell


#: what the worker server imports before it forks the workers (the modules every cell needs)
PRELOAD: tuple[str, ...] = ("numpy", "mujoco", "pinocchio", "osqp", "casadi", "scenarios.sweep.cells",
                            "mmact_ctrl.controller", "mmact_ctrl.loop", "mmact_ctrl.metrics", "scenarios.world.factory")


def run_local(todo: list[tuple[dict, float, str]], workers: int, progress) -> None:
    import multiprocessing as mp

    if workers <= 1:
        for item in todo:
            _run_and_store(item)
            progress()
        return
    # forkserver: the server imports the stack once (PRELOAD) and each worker forks from it, where spawn made every
    # worker import torch, MuJoCo, CasADi, numba's kernels again (measured: 2 workers 1.6x one on --quick, ~3 s of
    # imports each); nothing is forked from this process (its threads, renderers)
    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload(list(PRELOAD))
    with ctx.Pool(workers) as pool:
        for _ in pool.imap_unordered(_run_and_store, todo):
            progress()


def run_ray(todo: list[tuple[dict, float, str]], address: str | None, progress) -> None:
    try:
        import ray
    except ImportError:
        raise SystemExit("--backend ray needs Ray: pip install -e '.[cluster]'") from None
    ray.init(address=address or "auto", ignore_reinit_error=True, log_to_driver=False)
    remote = ray.remote(num_cpus=1)(run_cell)
    refs = {remote.remote(cell, duration_s): path for cell, duration_s, path in todo}
    pending = list(refs)
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        row = ray.get(done[0])
        Path(refs[done[0]]).write_text(json.dumps(row))  # results are files on the driver: resumable
        progress()
