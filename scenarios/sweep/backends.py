"""The sweep's backends: every cell still to run, in a local process pool (or in this process) or on a Ray
cluster; each result is written as its cell's JSON file as it arrives, so an interrupted sweep resumes."""

from __future__ import annotations

import json
from pathlib import Path

from scenarios.sweep.cells import _run_and_store, run_cell


def run_local(todo: list[tuple[dict, float, str]], workers: int, progress) -> None:
    import multiprocessing as mp

    if workers <= 1:
        for item in todo:
            _run_and_store(item)
            progress()
        return
    with mp.get_context("spawn").Pool(workers) as pool:
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
