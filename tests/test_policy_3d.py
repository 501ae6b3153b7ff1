"""A policy that sees in 3-D and sees motion: two views, two frames, leading labels, known-prefix training."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from mmact_ctrl.chunk import Observation
from mmact_ctrl.config import StackConfig
from mmact_ctrl.controller import HybridController
from mmact_ctrl.frame_history import EarlierFrame
from mmact_ctrl.loop import run_episode
from policy.bundle import untrained_bundle
from policy.config import ModelConfig
from policy.dataset import DatasetError, PolicyDataset, read_meta
from policy.training.batches import known_prefix_mask
from policy.training.tokenize import load_tokenized
from scenarios.collect import CollectConfig, collect, in_box
from scenarios.world.factory import make_expert, make_world
from scenarios.world.panda_scene import TARGET_RGBA

HOLDOUT = (0.5, 0.65, 0.0, 0.3)


@pytest.fixture(scope="module")
def demos3d(tmp_path_factory):
    out = tmp_path_factory.mktemp("demos3d")
    cfg = CollectConfig(episodes=4, objects=1, motion="linear", duration_s=1.5, cameras=("front", "side"),
                        frame_gap_s=0.1, expert_lead="velocity", seed=21, holdout_box_m=HOLDOUT)
    collect(cfg, out, progress=False)
    return out


def _ball_pixels(frame: np.ndarray, rgba) -> int:
    """Pixels close to a ball's colour (shaded: the hue dominates)."""
    f = frame.astype(int)
    c = np.argmax(rgba[:3])
    return int(np.sum((f[..., c] > 90) & (f[..., c] > f[..., (c + 1) % 3] + 50) & (f[..., c] > f[..., (c + 2) % 3] + 50)))


def test_the_3d_scene_renders_two_views_that_both_see_the_ball():
    world = make_world("static", n_objects=1, plane_z_m=0.0, cameras=("front", "side"))
    try:
        heights = []
        for seed in range(6):
            world.reset(seed)
            frames = world.render()
            assert frames.shape == (2, 96, 96, 3) and frames.dtype == np.uint8
            seen = [_ball_pixels(f, TARGET_RGBA[0]) for f in frames]
            assert min(seen) >= 3, (seed, seen)  # the red ball is in both views
            heights.append(world.target_pos_m()[2])
        assert np.ptp(heights) > 0.05  # anywhere in the box, not one plane
    finally:
        world.close()


def test_collected_samples_hold_two_views_two_frames_and_leading_labels(demos3d):
    meta = read_meta(demos3d)
    assert meta["camera_names"] == ["front", "side"] and meta["frame_offsets_s"] == [0.0, -0.1]
    d = PolicyDataset.load(demos3d).data
    n = len(d["q_rad"])
    assert n == 12  # samples at 0, 0.5 and 1.0 s of four 1.5 s episodes
    assert d["images"].shape == (n, 4, 96, 96, 3) and d["future_images"].shape == (n, 2, 96, 96, 3)
    first = np.arange(n) % 3 == 0  # the first sample of an episode has no earlier frame: it repeats the current one
    assert np.array_equal(d["images"][first, :2], d["images"][first, 2:])
    moved = [not np.array_equal(d["images"][i, :2], d["images"][i, 2:]) for i in np.flatnonzero(~first)]
    assert all(moved)  # 0.1 s earlier, a moving ball (and arm) look different
    # labels: without an earlier frame the chunk ends on the ball; with one it leads it (0.2 m/s over 1.6 s)
    lead = np.linalg.norm(d["actions"][:, -1, :3] - d["target_pos_m"], axis=1)
    assert np.all(lead[first] < 1e-3)
    assert np.median(lead[~first]) > 0.1
    assert not any(in_box(p, HOLDOUT) for p in d["target_pos_m"][first])  # the held-out region is never the start


def test_the_two_frame_layout_round_trips_through_the_token_sequence(demos3d):
    bundle = untrained_bundle(ModelConfig(d_model=32, n_layers=1, n_heads=2))
    bundle.camera_names, bundle.frame_offsets_s = ["front", "side"], [0.0, -0.1]
    data = load_tokenized(bundle, str(demos3d), progress=False)
    assert data["img"].shape[1:] == (4, 12, 12) and data["fut"].shape[1:] == (2, 12, 12)
    from policy.training.batches import build_task_batch

    idx = np.arange(3)
    toks, lay = build_task_batch(bundle, data, "mm2a", idx)
    assert lay.n_views == 4
    off = bundle.model.vocab.image_offset
    for v in range(4):  # each view's codes sit in their own segment, with their own view id
        seg = lay.slots[f"image{v}"]
        np.testing.assert_array_equal(toks[:, seg] - off, data["img"][idx, v].reshape(3, -1))
        assert set(lay.view[seg]) == {v + 1}
    np.testing.assert_array_equal(bundle.action_tokenizer.decode(toks[:, lay.target_idx].reshape(3, 16, 7)),
                                  bundle.action_tokenizer.decode(bundle.action_tokens(data["actions_f"][idx])))
    _, lay_t2i = build_task_batch(bundle, data, "t2i", idx)  # t2i / mmu see the current frame of each camera
    assert lay_t2i.n_views == 2
    bundle.frame_offsets_s = [0.0]  # a checkpoint of other views refuses the data, naming both
    with pytest.raises(DatasetError, match="frame offsets"):
        load_tokenized(bundle, str(demos3d), progress=False)


def test_dataset_meta_with_bad_frame_offsets_is_refused(demos3d, tmp_path):
    meta = json.loads((demos3d / "meta.json").read_text())
    meta["frame_offsets_s"] = [0.0, 0.1]
    (tmp_path / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(DatasetError, match="frame_offsets_s"):
        read_meta(tmp_path)


def test_known_prefix_mask_keeps_the_prefix_out_of_the_loss():
    rng = np.random.default_rng(0)
    base = np.ones((400, 16 * 7), dtype=bool)
    mask, n_known = known_prefix_mask(base, 16, 7, rng, max_waypoints=8, prob=0.5)
    assert 0.4 < np.mean(n_known > 0) < 0.6 and n_known.max() == 8
    for row, n in zip(mask, n_known):
        assert not row[: 7 * n].any() and row[7 * n:].all()  # known waypoints unmasked, the rest masked
    same, none = known_prefix_mask(base, 16, 7, rng, max_waypoints=0, prob=1.0)
    assert same is base and not none.any()


def test_a_model_trained_with_known_prefixes_keeps_them_and_fills_the_rest(tmp_path):
    """Stage 2 with ``--known-prefix-max``: the loss falls, and an inpainting query returns the given prefix
    exactly and valid action tokens elsewhere that follow the data better than the untrained model's."""
    from policy.inference import MMActPolicy
    from policy.synthetic import write_synthetic_dataset
    from policy.train import main as train_main

    syn = write_synthetic_dataset(tmp_path / "syn", n_samples=64, shard_size=64, seed=5)
    common = ["--data", str(syn), "--no-progress", "--seed", "2"]
    s0 = train_main([*common, "--stage", "0", "--out", str(tmp_path / "s0"), "--steps", "2", "--batch-size", "4"])
    tiny = ["--d-model", "48", "--layers", "2", "--heads", "2", "--batch-size", "16", "--aux-batch-size", "2",
            "--eval-samples", "4", "--lr", "2e-3", "--known-prefix-max", "8", "--known-prefix-prob", "1.0"]
    s2 = train_main([*common, "--stage", "2", "--out", str(tmp_path / "s2"), "--init", str(s0), "--steps", "120", *tiny])
    pol = MMActPolicy.load(s2)
    log = pol.bundle.info["log_tail"]
    assert pol.bundle.info["train_config"]["known_prefix_max_waypoints"] == 8
    first = json.loads((tmp_path / "s2" / "MODEL_CARD.md").read_text().split("train config: `")[1].split("`")[0])
    assert first["known_prefix_prob"] == 1.0
    ds = PolicyDataset.load(syn).data
    untrained = MMActPolicy(untrained_bundle(pol.bundle.model_cfg))
    errs = {"trained": [], "untrained": []}
    for i in range(8):
        truth = pol.action_tokenizer.encode(ds["actions"][i].astype(np.float64))[0]
        known = np.full((16, 7), -1, dtype=np.int64)
        known[:6] = truth[:6]
        tokens, actions = pol.predict_chunk(ds["images"][i], str(ds["instructions"][i]), ds["q_rad"][i],
                                            known_actions=known)
        np.testing.assert_array_equal(tokens[:6], truth[:6])  # the prefix comes back exactly
        lo, hi = pol.model.vocab.range_of("action")
        assert np.all((tokens >= lo) & (tokens < hi))
        errs["trained"].append(np.abs(actions[6:, :3] - ds["actions"][i, 6:, :3]).mean())
        ku = known.copy()
        ku[:6] = untrained.action_tokenizer.encode(ds["actions"][i].astype(np.float64))[0][:6]
        _, au = untrained.predict_chunk(ds["images"][i], str(ds["instructions"][i]), ds["q_rad"][i], known_actions=ku)
        errs["untrained"].append(np.abs(au[6:, :3] - ds["actions"][i, 6:, :3]).mean())
    assert np.mean(errs["trained"]) < 0.5 * np.mean(errs["untrained"]), errs
    assert log[-1]["loss_mm2a"] < 0.7 * 7.6  # ln(2048) = 7.6 at the start
    with pytest.raises(SystemExit, match="below the chunk horizon"):
        train_main([*common, "--stage", "2", "--out", str(tmp_path / "bad"), "--init", str(s0), "--steps", "1",
                    "--known-prefix-max", "16", "--d-model", "32", "--layers", "1", "--heads", "2"])


def test_earlier_frame_is_rendered_once_a_gap_before_each_query():
    renders = []
    earlier = EarlierFrame(lambda: renders.append(len(renders)) or np.full((1, 2, 2, 3), len(renders), np.uint8),
                           gap_s=0.1, dt_s=0.001)
    got = {}
    next_plan = 0.0
    for k in range(2500):
        t = k * 0.001
        earlier.tick(t, next_plan)
        if t >= next_plan - 0.0005:
            got[round(t, 3)] = earlier.take(t)
            next_plan += 1.0
    assert len(renders) == 2  # at 0.9 and 1.9 s, not every tick
    assert got[0.0] is None and got[1.0] is not None and got[2.0] is not None and earlier.missing == 1
    with pytest.raises(ValueError, match="gap_s"):
        EarlierFrame(lambda: None, gap_s=-0.1, dt_s=0.001)


def test_a_gap_longer_than_the_replan_period_still_gets_frames_of_the_right_age():
    """A 0.4 s gap at 5 Hz: each query's frame is due before the query ahead of it has run."""
    clock = {"t": 0.0}
    renders = []
    earlier = EarlierFrame(lambda: renders.append(clock["t"]) or np.full((1, 2, 2, 3), len(renders), np.uint8),
                           gap_s=0.4, dt_s=0.001)
    ages, next_plan = {}, 0.0
    for k in range(3001):
        t = clock["t"] = k * 0.001
        earlier.tick(t, next_plan, 0.2)
        if t >= next_plan - 0.0005:
            frame = earlier.take(t)
            ages[round(t, 3)] = None if frame is None else round(t - renders[int(frame[0, 0, 0, 0]) - 1], 3)
            next_plan += 0.2
    # the first two queries come before any frame 0.4 s old can exist; every later one gets exactly that age
    assert ages[0.0] is None and ages[0.2] is None and earlier.missing == 2
    assert all(ages[round(0.2 * i, 3)] == 0.4 for i in range(2, 16)), ages
    assert len(renders) <= 16 + 1  # about one render per query, not one per tick
    n = len(renders)
    earlier.tick(3.5, float("inf"), 0.2)  # an executor that schedules no further query: nothing to render, no error
    assert len(renders) == n and earlier.take(3.6) is None


class _TwoFrameExpert:
    """The expert behind a source that asks for an earlier frame; records what the loop hands it."""

    needs_image = True
    prev_frame_gap_s = 0.1

    def __init__(self, world) -> None:
        self.inner = make_expert(world=world)
        self.seen: list[tuple[float, bool, bool]] = []

    def plan(self, observation: Observation):
        prev = observation.prev_image
        self.seen.append((observation.t0_s, prev is not None,
                          prev is not None and not np.array_equal(prev, observation.image)))
        return self.inner.plan(observation)


def test_the_loop_hands_a_two_frame_source_the_frame_a_gap_earlier():
    world = make_world("linear", 0.2, cameras=("front", "side"))
    try:
        source = _TwoFrameExpert(world)
        log = run_episode(world, source, HybridController(StackConfig(mode="open_loop", duration_s=3.0)), seed=4)
        assert log.safety_counts and sum(log.safety_counts.values()) == 0
    finally:
        world.close()
    assert [round(t, 3) for t, *_ in source.seen] == [0.0, 1.0, 2.0]
    assert source.seen[0][1] is False  # the first query has no earlier frame
    assert all(has and differs for _, has, differs in source.seen[1:])


def test_stage0_init_refreshes_the_image_tokenizer_and_keeps_the_model(tmp_path):
    """New cameras for a trained policy: ``--stage 0 --init CKPT`` fine-tunes the VQ-VAE only; the text tokenizer,
    the token ids and the model's weights are the checkpoint's, so stage 2 continues the same model."""
    from policy.bundle import PolicyBundle
    from policy.synthetic import write_synthetic_dataset
    from policy.train import main as train_main

    syn = write_synthetic_dataset(tmp_path / "syn", n_samples=24, shard_size=24, seed=9)
    common = ["--data", str(syn), "--no-progress", "--seed", "3"]
    s0 = train_main([*common, "--stage", "0", "--out", str(tmp_path / "s0"), "--steps", "2", "--batch-size", "4"])
    tiny = ["--d-model", "32", "--layers", "1", "--heads", "2", "--batch-size", "4", "--eval-samples", "4"]
    s2 = train_main([*common, "--stage", "2", "--out", str(tmp_path / "s2"), "--init", str(s0), "--steps", "2", *tiny])
    r0 = train_main([*common, "--stage", "0", "--out", str(tmp_path / "r0"), "--init", str(s2), "--steps", "3",
                     "--batch-size", "4"])
    old, new = PolicyBundle.load(s2), PolicyBundle.load(r0)
    assert new.text_tokenizer.to_json() == old.text_tokenizer.to_json()
    assert new.action_tokenizer.token_offset == old.action_tokenizer.token_offset
    for (k, a), b in zip(old.model.state_dict().items(), new.model.state_dict().values()):
        assert torch.equal(a, b), k
    changed = [not torch.equal(a, b) for a, b in zip(old.image_tokenizer.state_dict().values(),
                                                     new.image_tokenizer.state_dict().values())]
    assert any(changed)
    assert new.info["figures"]["image_psnr_db_heldout_before"] > 0
    assert train_main([*common, "--stage", "2", "--out", str(tmp_path / "c2"), "--init", str(r0), "--steps", "1",
                       *tiny]).is_file()


SHIPPED_3D = Path(__file__).resolve().parents[1] / "policy" / "checkpoints" / "mmact_3d.pt"


def test_the_shipped_3d_checkpoint_aims_from_two_views_and_two_frames_at_the_instructed_ball(first_query_aims):
    """The shipped 3-D policy (``policy/checkpoints/mmact_3d.pt``): <= 20 MB, two cameras x two frames, balls
    anywhere in the box; from the first query of real rendered scenes its chunk is valid and ends nearer the
    instructed ball than the arm starts, and nearer it than the other ball."""
    from mmact_ctrl.policy_source import PolicyChunkSource
    from scenarios.world.factory import policy_scene

    assert SHIPPED_3D.is_file() and SHIPPED_3D.stat().st_size <= 20e6
    source = PolicyChunkSource(SHIPPED_3D)
    assert source.camera_names == ("front", "side") and source.prev_frame_gap_s == pytest.approx(0.4)
    scene = policy_scene(source)
    assert scene["plane_z_m"] == 0.0 and scene["cameras"] == ("front", "side")

    def views_of_the_first_query(source, obs, chunk, world):
        # [front, side] now, and (first query) again as the earlier frame
        assert source.views(obs).shape == (4, 96, 96, 3)

    start, end, other = first_query_aims(source, range(9000, 9008), views_of_the_first_query)
    assert np.mean(end) < 0.5 * np.mean(start), (end, start)
    assert np.mean(end < other) >= 0.75, (end, other)