"""The residual's training data (``python -m scenarios.train_residual``): one open-loop rollout turned into 100 Hz
samples (features and label; the recording chunk source and sensor it needs), and every planned rollout collected
(spawned processes when ``workers`` > 1) and concatenated."""

from __future__ import annotations

import sys
import time
from dataclasses import asdict

import numpy as np
import torch
from tqdm import tqdm

from policy.residual import FEATURE_DIM, residual_features
from policy.residual_training import clip_norm
from scenarios.train_residual_plan import SAMPLE_HZ, EpisodeSpec

_CACHE: dict = {}


class _RecordingSources:
    """A chunk source proxy that remembers every chunk it answered (observation time, horizon, spacing)."""

    def __init__(self, source) -> None:
        self._source = source
        self.chunks: list[tuple[float, int, float]] = []

    def __getattr__(self, name):
        return getattr(self._source, name)

    @property
    def declared_capabilities(self) -> frozenset[str]:
        from mmact_ctrl.sources.contract import capabilities

        return capabilities(self._source)

    def _keep(self, chunk):
        self.chunks.append((float(chunk.t0_s), int(chunk.horizon), float(chunk.dt_s)))
        return chunk

    def plan(self, observation):
        return self._keep(self._source.plan(observation))

    def plan_inpaint(self, observation, prefix):
        return self._keep(self._source.plan_inpaint(observation, prefix))


def _recording_sensor(world, rate_hz: float, dt_s: float):
    """The world's own 100 Hz oracle channel (``OracleSensor``), recording every capture (t, pos or None)."""
    from mmact_ctrl.perception import OracleSensor

    class RecordingSensor(OracleSensor):
        def reset(self, seed: int) -> None:
            super().reset(seed)
            self.record: list[tuple[float, np.ndarray | None]] = []

        def poll(self, t_s: float):
            out = super().poll(t_s)
            self.record.extend((m.t_capture_s, m.pos_m) for m in out)
            return out

    return RecordingSensor(world, rate_hz, 0.0, dt_s)


def _parts(spec: EpisodeSpec):
    from controllers.robot_model import PandaModel
    from scenarios.world.factory import make_expert, make_world, policy_scene

    skey = ("source", spec.source, spec.lead)
    if skey not in _CACHE:
        if spec.source == "policy":
            from mmact_ctrl.policy_source import PolicyChunkSource

            _CACHE[skey] = PolicyChunkSource()
        else:
            _CACHE[skey] = make_expert(bins=2048, **({"lead": spec.lead} if spec.lead else {}))
    wkey = ("world", spec.source, spec.kind, spec.speed_m_s)
    if wkey not in _CACHE:
        scene = policy_scene(_CACHE[skey]) if spec.source == "policy" else {}
        _CACHE[wkey] = make_world(target=spec.kind, speed_m_s=spec.speed_m_s, **scene)
    if "model" not in _CACHE:
        _CACHE["model"] = PandaModel()
    return _CACHE[wkey], _CACHE[skey], _CACHE["model"]


def rollout_samples(spec: EpisodeSpec, duration_s: float = 6.0, latency_ms: float = 200.0, lead_s: float = 0.05,
                    history_s: float = 0.1, max_correction_m: float = 0.15) -> dict:
    """Run one open-loop episode and turn it into 100 Hz samples (see ``scenarios.train_residual``'s docstring).

    Returns arrays ``features`` (n, FEATURE_DIM), ``label`` (n, 3) m, ``base`` (n, 3) m, ``target`` (n, 3) m
    (truth at the sample time), ``target_lead`` (n, 3) m (truth at ``t + lead_s``), ``t`` (n,) s, and ``info``.
    """
    from mmact_ctrl.config import StackConfig
    from mmact_ctrl.controller import HybridController
    from mmact_ctrl.loop import run_episode

    world, source, model = _parts(spec)
    cfg = StackConfig(mode="open_loop", replan_hz=spec.replan_hz, latency_ms=latency_ms, duration_s=duration_s)
    controller = HybridController(cfg, model=model)
    rec = _RecordingSources(source)
    sensor = _recording_sensor(world, cfg.perception_hz, cfg.dt_s)
    w0 = time.perf_counter()
    log = run_episode(world, rec, controller, seed=spec.seed, sensor=sensor)
    wall = time.perf_counter() - w0
    dt = cfg.dt_s
    lead_k = int(round(lead_s / dt))
    active = _active_chunks(rec.chunks, log.chunk_active_s, latency_ms / 1000.0, dt)
    # the measurement channel: capture times and positions of the measurements that were not dropped
    caps = [(t, p) for t, p in sensor.record if p is not None]
    cap_t = np.array([c[0] for c in caps]) if caps else np.zeros(0)
    cap_p = np.array([c[1] for c in caps]).reshape(-1, 3)
    rows = _sample_rows(len(log.t_s), dt, lead_k, active, cap_t, history_s)
    if not rows:
        return {"features": np.zeros((0, FEATURE_DIM), np.float32), **{key: np.zeros((0, 3), np.float32) for key in
                ("label", "base", "target", "target_lead")}, "t": np.zeros(0, np.float32),
                "info": {**asdict(spec), "n": 0, "wall_s": wall}}
    out = _samples(log, rows, cap_t, cap_p, dt, lead_k, max_correction_m)
    out["info"] = {**asdict(spec), "n": int(len(out["t"])), "wall_s": wall, "rejections": sum(log.rejections.values())}
    return out


def _active_chunks(chunks: list[tuple[float, int, float]], chunk_active_s, latency_s: float,
                   dt: float) -> list[tuple[float, float, float, float]]:
    """The chunks that became active (at the times ``chunk_active_s``), each matched to the chunk observed
    ``latency_s`` before (rejected ones never are): ``(t active, t observed, span, t of its last waypoint)`` s."""
    obs_times = np.array([c[0] for c in chunks]) if chunks else np.zeros(0)
    active = []
    for t_act in chunk_active_s:
        j = int(np.argmin(np.abs(obs_times - (t_act - latency_s)))) if len(obs_times) else -1
        if j >= 0 and abs(obs_times[j] - (t_act - latency_s)) < 0.5 * dt:
            t0, horizon, cdt = chunks[j]
            active.append((t_act, t0, horizon * cdt, t0 + horizon * cdt))
    return active


def _sample_rows(n: int, dt: float, lead_k: int, active: list, cap_t: np.ndarray,
                 history_s: float) -> list[tuple[int, float, float, int, int]]:
    """The ticks sampled at ``SAMPLE_HZ`` while a chunk is executing and a measurement exists:
    ``(tick, age of the chunk's observation s, chunk span s, index of the latest measurement, of the earlier one)``."""
    every = int(round(1.0 / (SAMPLE_HZ * dt)))
    rows = []
    for k in range(every, n - lead_k, every):
        t = k * dt
        live = [a for a in active if a[0] <= t + 0.5 * dt]
        if not live:
            continue
        t_act, t0, span, t_end = live[-1]
        if t > t_end + 0.5 * dt:  # past the chunk's last waypoint (the watchdog holds): no base waypoint to correct
            continue
        i_last = int(np.searchsorted(cap_t, t + 0.5 * dt, side="right")) - 1
        if i_last < 0:
            continue
        i_prev = int(np.searchsorted(cap_t, t - history_s + 0.5 * dt, side="right")) - 1
        i_prev = i_last if i_prev < 0 else i_prev
        rows.append((k, t - t0, span, i_last, i_prev))
    return rows


def _samples(log, rows: list, cap_t: np.ndarray, cap_p: np.ndarray, dt: float, lead_k: int,
             max_correction_m: float) -> dict:
    """The sample arrays (features, label, base, target, target_lead, t) of the episode ``log`` at ``rows``."""
    k = np.array([r[0] for r in rows])
    age = np.array([r[1] for r in rows])
    span = np.array([r[2] for r in rows])
    i_last = np.array([r[3] for r in rows])
    i_prev = np.array([r[4] for r in rows])
    base = log.ref_pos_m[k]
    tcp = log.ee_pos_m[k]
    tcp_vel = (log.ee_pos_m[k] - log.ee_pos_m[k - 1]) / dt
    feats = residual_features(base, age, span, cap_p[i_last], cap_p[i_prev], cap_t[i_last] - cap_t[i_prev], tcp,
                              tcp_vel)
    target = log.target_pos_m[k]
    target_lead = log.target_pos_m[k + lead_k]
    label = clip_norm(target_lead - base, max_correction_m)
    return {"features": feats.astype(np.float32), "label": label.astype(np.float32), "base": base.astype(np.float32),
            "target": target.astype(np.float32), "target_lead": target_lead.astype(np.float32),
            "t": (k * dt).astype(np.float32)}


def _worker(args):
    spec, kw = args
    torch.set_num_threads(1)
    return rollout_samples(spec, **kw)


def collect_samples(specs: list[EpisodeSpec], duration_s: float = 6.0, latency_ms: float = 200.0,
                    lead_s: float = 0.05, history_s: float = 0.1, max_correction_m: float = 0.15, workers: int = 1,
                    progress: bool = True) -> dict:
    """Roll out every spec (``workers`` > 1: spawned processes) and concatenate the samples.

    Returns ``features``, ``label``, ``base``, ``target``, ``target_lead``, ``t`` (as :func:`rollout_samples`),
    ``episode`` (n,) the index of the spec each sample came from, ``episodes`` (one info dict per spec) and
    ``settings`` (the arguments).
    """
    kw = dict(duration_s=duration_s, latency_ms=latency_ms, lead_s=lead_s, history_s=history_s,
              max_correction_m=max_correction_m)
    jobs = [(s, kw) for s in specs]
    bar = tqdm(total=len(specs), desc="collecting", unit="ep", disable=not progress, file=sys.stderr)
    results: dict[int, dict] = {}
    if workers > 1 and len(specs) > 1:
        import multiprocessing as mp

        with mp.get_context("spawn").Pool(min(workers, len(specs))) as pool:
            for spec, r in zip(specs, pool.imap(_worker, jobs, chunksize=4)):
                results[spec.index] = r
                bar.update(1)
    else:
        for job in jobs:
            results[job[0].index] = rollout_samples(job[0], **kw)
            bar.update(1)
    bar.close()
    order = [s.index for s in specs]
    out = {key: np.concatenate([results[i][key] for i in order]) for key in
           ("features", "label", "base", "target", "target_lead", "t")}
    out["episode"] = np.concatenate([np.full(results[i]["info"]["n"], i, dtype=np.int32) for i in order])
    out["episodes"] = [results[i]["info"] for i in order]
    out["settings"] = kw
    return out
