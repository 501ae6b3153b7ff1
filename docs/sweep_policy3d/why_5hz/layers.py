"""Why hybrid trails the residual at 5 Hz with the box policy: hybrid's layers switched one at a time.

    SEED0=100 python docs/sweep_policy3d/why_5hz/layers.py VARIANTS TARGETS HZ N_SEEDS OUT.jsonl

VARIANTS is a comma list of the keys of ``VARIANTS`` below, TARGETS of the sweep's families (speed 0.3 m/s, 200 ms,
the sweep's episode exactly: the hybrid rows on seeds 0-9 equal the sweep's to the digit). One JSON row per episode
is appended to OUT; ``pair.py OUT A B [final_mm|mean_mm]`` prints the paired differences (Wilcoxon), ``sum.py OUT``
the means. Runs from the repository root, two processes of one torch thread."""
import json, sys, os
from dataclasses import replace
from multiprocessing import get_context
import numpy as np

CK = "policy/checkpoints/mmact_3d_box.pt"
VARIANTS = {
    "residual": dict(mode="residual"),
    "hybrid": dict(mode="hybrid"),
    "splice0.3": dict(mode="hybrid", splice_radius_m=0.3),
    "displacement": dict(mode="hybrid", retarget="displacement"),
    "no_ruckig": dict(mode="hybrid", use_ruckig=False),
    "no_mpc": dict(mode="hybrid", use_mpc=False),
    "ruckig_fast": dict(mode="hybrid", smoother_fast=True),
}

def _init():
    import torch
    torch.set_num_threads(1)

def run(job):
    variant, target, hz, seed = job
    from mmact_ctrl.config import StackConfig
    from mmact_ctrl.controller import HybridController
    from mmact_ctrl.loop import run_episode
    from mmact_ctrl.metrics import episode_metrics
    from scenarios.sweep.study import _source_and_world
    cell = dict(source="policy", checkpoint=CK, target=target, speed_m_s=0.3, seed=seed, bins=2048)
    source, world = _source_and_world(cell)
    kw = dict(VARIANTS[variant])
    cfg = StackConfig(mode=kw.pop("mode"), replan_hz=hz, latency_ms=200.0, duration_s=6.0)
    if "retarget" in kw:
        cfg = replace(cfg, retarget=replace(cfg.retarget, rule=kw.pop("retarget")))
    if kw.pop("smoother_fast", False):  # Ruckig's task-space limits 2.5x (a) and 4x (j): the robot's QP limits still hold
        cfg = replace(cfg, smoother=replace(cfg.smoother, a_max_m_s2=15.0, j_max_m_s3=320.0))
    cfg = replace(cfg, **kw)
    log = run_episode(world, source, HybridController(cfg), seed=seed)
    m = episode_metrics(log)
    return dict(variant=variant, target=target, hz=hz, seed=seed, success=m["success"], final_mm=m["final_error_m"] * 1e3,
                mean_mm=m["mean_error_m"] * 1e3, rejected=m["rejected_chunks"], viol=m["limit_violations"])

if __name__ == "__main__":
    os.environ.setdefault("MUJOCO_GL", "egl")
    variants = sys.argv[1].split(","); targets = sys.argv[2].split(","); hz = float(sys.argv[3]); s0 = int(os.environ.get("SEED0", "100")); seeds = range(s0, s0 + int(sys.argv[4]))
    jobs = [(v, t, hz, s) for t in targets for s in seeds for v in variants]
    out = open(sys.argv[5], "a")
    with get_context("spawn").Pool(2, initializer=_init) as pool:
        for r in pool.imap_unordered(run, jobs):
            out.write(json.dumps(r) + "\n"); out.flush()
