"""The protocol's overhead on loopback: round trip minus the server's ``infer_ms``, with a trivial policy.

    python -m mmact_ctrl.sources.openpi.bench                       # server in its own process, 300 calls
    python -m mmact_ctrl.sources.openpi.bench --server thread --json out/wire_bench.json

The observation is what a LIBERO-style policy gets: two 224 x 224 x 3 uint8 images, an 8-vector state and a prompt
(about 300 kB per request); the reply is a (10, 7) float chunk. The overhead is everything the protocol adds to the
policy's own time: packing, websocket framing, loopback TCP both ways, unpacking, the server's event loop and its
hand-off to the inference thread. ``--server process`` (default) runs the server in a separate process, as a real
deployment does; ``thread`` runs it in this process (the client and the server then share one GIL).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import sys
import time
from pathlib import Path

import numpy as np

from . import codec
from .client import ClientConfig, PolicyClient
from .server import PolicyServer


class TrivialPolicy:
    """Answers every observation with a constant (10, 7) chunk: the policy's own time is ~0."""

    metadata = {"policy": "trivial"}

    def __init__(self) -> None:
        self.actions = np.zeros((10, 7), dtype=np.float32)

    def infer(self, obs: dict) -> dict:
        t0 = time.perf_counter()
        out = {"actions": self.actions}
        return {**out, "policy_timing": {"infer_ms": (time.perf_counter() - t0) * 1e3}}


def bench_observation(size_px: int = 224, seed: int = 0) -> dict:
    """Two ``size_px`` square uint8 images, an 8-vector state, a prompt."""
    rng = np.random.default_rng(seed)
    return {"observation/image": rng.integers(0, 256, (size_px, size_px, 3), dtype=np.uint8),
            "observation/wrist_image": rng.integers(0, 256, (size_px, size_px, 3), dtype=np.uint8),
            "observation/state": rng.standard_normal(8),
            "prompt": "pick up the red ball"}


def _serve_in_child(port_queue, stop_event) -> None:  # pragma: no cover - runs in the child process
    import asyncio

    async def main() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()

        def watch() -> None:
            stop_event.wait()
            loop.call_soon_threadsafe(stop.set)

        loop.run_in_executor(None, watch)
        await PolicyServer(TrivialPolicy(), port=0).run(on_ready=port_queue.put, stop=stop)

    asyncio.run(main())


def _percentiles(values: list[float]) -> dict:
    a = np.asarray(values, dtype=float)
    return {"median": float(np.median(a)), "p95": float(np.percentile(a, 95)), "max": float(a.max()),
            "mean": float(a.mean())}


def run_bench(calls: int = 300, size_px: int = 224, server: str = "process", warmup: int = 20) -> dict:
    """Time ``calls`` requests after ``warmup``; returns the figures (ms)."""
    obs = bench_observation(size_px)
    stop_child = None
    if server == "process":
        ctx = multiprocessing.get_context("spawn")
        ports, stop_child = ctx.Queue(), ctx.Event()
        child = ctx.Process(target=_serve_in_child, args=(ports, stop_child), daemon=True)
        child.start()
        url, handle = f"ws://127.0.0.1:{ports.get(timeout=60)}", None
    elif server == "thread":
        handle = PolicyServer(TrivialPolicy(), port=0).start()
        url = handle.url
    else:
        raise ValueError(f"server must be 'process' or 'thread', got {server!r}")
    try:
        client = PolicyClient(url, ClientConfig(connect_timeout_s=10.0))
        pack_ms, packer = [], codec.packer()
        for i in range(warmup + calls):
            t0 = time.perf_counter()
            packer.pack(obs)  # the client's own packing cost, measured apart (a packer like its own)
            if i >= warmup:
                pack_ms.append((time.perf_counter() - t0) * 1e3)
            client.infer(obs)
        records = list(client.calls)[warmup:]
        client.close()
    finally:
        if handle is not None:
            handle.stop()
        if stop_child is not None:
            stop_child.set()
            child.join(10)
    rt = [r.round_trip_ms for r in records]
    server_ms = [r.server_infer_ms for r in records]
    overhead = [a - b for a, b in zip(rt, server_ms)]
    request_bytes = len(codec.packb(obs))
    return {"calls": calls, "server": server, "image_px": size_px, "request_bytes": request_bytes,
            "overhead_ms": _percentiles(overhead), "round_trip_ms": _percentiles(rt),
            "server_infer_ms": _percentiles(server_ms), "client_pack_ms": _percentiles(pack_ms),
            "goal_median_overhead_ms": 2.0}


def format_result(r: dict) -> str:
    o, t = r["overhead_ms"], r["round_trip_ms"]
    return (f"openpi protocol on loopback, server in a {r['server']}, {r['calls']} calls, two {r['image_px']} px images "
            f"+ state ({r['request_bytes'] / 1e3:.0f} kB per request):\n"
            f"  overhead (round trip - server infer_ms): median {o['median']:.3f} ms, p95 {o['p95']:.3f} ms, "
            f"max {o['max']:.3f} ms (goal: median <= {r['goal_median_overhead_ms']:g} ms)\n"
            f"  round trip: median {t['median']:.3f} ms, p95 {t['p95']:.3f} ms; server infer_ms median "
            f"{r['server_infer_ms']['median']:.3f} ms; client packing median {r['client_pack_ms']['median']:.3f} ms")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m mmact_ctrl.sources.openpi.bench", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--calls", type=int, default=300, help="timed requests (after 20 warm-up ones)")
    p.add_argument("--size-px", type=int, default=224, help="side of the two square images, px")
    p.add_argument("--server", choices=("process", "thread"), default="process",
                   help="where the server runs: its own process (default) or a thread of this one")
    p.add_argument("--json", metavar="PATH", help="also write the figures as JSON")
    args = p.parse_args(argv)
    if args.calls < 1 or args.size_px < 1:
        p.error(f"--calls and --size-px must be >= 1, got {args.calls} and {args.size_px}")
    result = run_bench(args.calls, args.size_px, args.server)
    print(format_result(result))
    if args.json:
        path = Path(args.json)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(result, indent=2) + "\n")
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
