"""Latency of one ``<|mm2a|>`` call: one-pass vs k-step re-masking vs autoregressive, and vs camera views.

    python -m policy.bench [--checkpoint PATH] [--json PATH] [--repeats 30] [--k 4] [--views 1,2,4]

Times (ms, batch 1, ``torch.no_grad``, greedy) of the model + decoding given tokenized inputs
(``mm2a_ms``, ``k_step_ms``, ``autoregressive_ms``: each ``median`` / ``p99``), the full
``predict_chunk`` including VQ-encoding the frames and tokenizing text and state
(``predict_chunk_ms``, with the checkpoint's sub-bin refinement window ``refine_bins``; the same
with bin centres: ``predict_chunk_bin_centres_ms``), and the one-pass latency as views grow (``views``). The headline
figures use the checkpoint's own query: ``n_views`` = its cameras x frames (``camera_names``, ``frame_offsets_s``; 4
for two cameras with an earlier frame each), whose ``sequence_length`` is reported. ``speedup`` =
autoregressive median / one-pass median. Without a checkpoint (none given and
``DEFAULT_CHECKPOINT`` absent) a randomly initialised model of the default size is timed: the
latency is the same, the actions are meaningless.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np
import torch

from policy.bundle import untrained_bundle
from policy.decoding import decode_autoregressive, decode_parallel
from policy.inference import DEFAULT_CHECKPOINT, MMActPolicy


def _stats(ts: list[float]) -> dict[str, float]:
    a = np.asarray(ts) * 1e3
    return {"median": float(np.median(a)), "p99": float(np.percentile(a, 99)), "mean": float(a.mean()), "n": len(a)}


def _time(fn, repeats: int, warmup: int = 2) -> dict[str, float]:
    for _ in range(warmup):
        fn()
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return _stats(ts)


def run_bench(policy: MMActPolicy, repeats: int = 30, ar_repeats: int = 3, k: int = 4, views=(1, 2, 4),
              seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    s = policy.bundle.image_cfg.image_size_px
    n_views = policy.bundle.n_views  # the checkpoint's own query: cameras x frames
    img = rng.integers(0, 256, size=(n_views, s, s, 3), dtype=np.uint8)
    q = np.zeros(7)
    q[3], q[5] = -1.5, 1.5
    instr = "reach the red ball"
    toks, lay = policy.mm2a_batch(img, instr, q)
    m = policy.model
    res: dict = {
        "device": str(policy.device), "threads": torch.get_num_threads(), "platform": platform.processor() or platform.machine(),
        "n_params": m.n_params(), "sequence_length": lay.length, "chunk_tokens": int(len(lay.target_idx)),
        "n_views": n_views, "camera_names": list(policy.bundle.camera_names),
        "frame_offsets_s": list(policy.bundle.frame_offsets_s),
    }
    with torch.no_grad():
        res["mm2a_ms"] = _time(lambda: policy.decode_mm2a(toks, lay, 1), repeats)  # two passes for an aux-first model
        res["mm2a_passes"] = 2 if policy.aux_first else 1
        res["k_step_ms"] = {**_time(lambda: decode_parallel(m, toks, lay, k), max(5, repeats // 3)), "k": k}
        res["autoregressive_ms"] = _time(lambda: decode_autoregressive(m, toks, lay), ar_repeats, warmup=1)
        res["predict_chunk_ms"] = _time(lambda: policy.predict_chunk(img, instr, q), repeats)
        res["refine_bins"] = policy.default_refine_bins
        res["predict_chunk_bin_centres_ms"] = _time(lambda: policy.predict_chunk(img, instr, q, refine_bins=0), repeats)
        res["views"] = {}
        for v in views:
            if v > policy.bundle.model_cfg.max_views or policy.bundle.model_cfg.ball_views:
                continue  # a model with ball tokens takes its own views only
            imv = rng.integers(0, 256, size=(v, s, s, 3), dtype=np.uint8)
            t, ly = policy.mm2a_batch(imv, instr, q)
            res["views"][str(v)] = {"sequence_length": ly.length, "mm2a_ms": _time(lambda: decode_parallel(m, t, ly, 1), repeats),
                                    "predict_chunk_ms": _time(lambda: policy.predict_chunk(imv, instr, q), max(5, repeats // 3))}
    res["speedup"] = res["autoregressive_ms"]["median"] / res["mm2a_ms"]["median"]
    return res


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(prog="python -m policy.bench", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--checkpoint", default=None, help=f"default: {DEFAULT_CHECKPOINT} if present, else an untrained model")
    ap.add_argument("--json", default=None, help="write the results here")
    ap.add_argument("--repeats", type=int, default=30)
    ap.add_argument("--ar-repeats", type=int, default=3)
    ap.add_argument("--k", type=int, default=4)
    ap.add_argument("--views", default="1,2,4")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--threads", type=int, default=None)
    a = ap.parse_args(argv)
    if a.threads:
        torch.set_num_threads(a.threads)
    path = Path(a.checkpoint) if a.checkpoint else (DEFAULT_CHECKPOINT if DEFAULT_CHECKPOINT.is_file() else None)
    if path is not None:
        policy = MMActPolicy.load(path, a.device)
    else:
        print("no checkpoint: timing an untrained model of the default size")
        policy = MMActPolicy(untrained_bundle().to(a.device))
    res = run_bench(policy, a.repeats, a.ar_repeats, a.k, tuple(int(v) for v in a.views.split(",")))
    res["checkpoint"] = str(path) if path else None
    print(f"mm2a one pass: median {res['mm2a_ms']['median']:.1f} ms, p99 {res['mm2a_ms']['p99']:.1f} ms "
          f"(L={res['sequence_length']}: {res['n_views']} views = cameras {res['camera_names']} x frames "
          f"{res['frame_offsets_s']} s, {res['n_params'] / 1e6:.2f} M params)")
    print(f"k={a.k} re-masking: median {res['k_step_ms']['median']:.1f} ms")
    print(f"autoregressive ({res['chunk_tokens']} passes): median {res['autoregressive_ms']['median']:.1f} ms -> "
          f"speedup {res['speedup']:.1f}x")
    print(f"predict_chunk (incl. tokenizing, refine +-{res['refine_bins']} bins): median "
          f"{res['predict_chunk_ms']['median']:.1f} ms; with bin centres {res['predict_chunk_bin_centres_ms']['median']:.1f} ms")
    for v, r in res["views"].items():
        print(f"  {v} view(s): L={r['sequence_length']}, mm2a median {r['mm2a_ms']['median']:.1f} ms, "
              f"predict_chunk {r['predict_chunk_ms']['median']:.1f} ms")
    if a.json:
        Path(a.json).write_text(json.dumps(res, indent=1))
    return res


if __name__ == "__main__":
    main()
