"""Issue 25: cameras that frame the ball box, ball tokens from the frames, the aux 3-D target, short sequences."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
import torch

from policy.ball_detector import BallDetectorConfig, BallTokenizer, color_masks, detect_balls
from policy.bundle import PolicyBundle, untrained_bundle
from policy.config import ImageTokenizerConfig, ModelConfig
from scenarios.collect import CollectConfig, collect
from scenarios.world.panda_scene import BOX_CAMERAS, TARGET_RADIUS_M
from scenarios.world.targets import TargetSpec

# the arm folded back over its base, out of the box and of both views (joint 1 turned half a turn)
_ARM_AWAY_RAD = np.array([2.8, -0.3, 0.0, -2.4, 0.0, 2.1, 0.8])


def test_the_box_cameras_see_every_ball_position_of_the_workspace_box_whole_in_both_views():
    """A ball at each corner of the box the targets move in (and at its centre) lies whole inside both box views,
    is found by the detector within a pixel of its projection's neighbourhood, and covers a few pixels per cm."""
    from scenarios.world.factory import make_world

    spec = TargetSpec()
    low, high = np.array(spec.workspace_low_m), np.array(spec.workspace_high_m)
    points = [np.array(p) for p in itertools.product(*zip(low, high))] + [(low + high) / 2]
    world = make_world("static", n_objects=1, plane_z_m=0.0, cameras=BOX_CAMERAS)
    try:
        world.reset(0)
        world.set_arm_state(_ARM_AWAY_RAD)
        for p in points:
            world.data.mocap_pos[world._mocap[0]] = p
            world._kinematics_stale = True
            frames = world.render()
            masks = color_masks(frames)[:, 0]  # red
            uv, n = detect_balls(frames)
            for cam, mask, count in zip(BOX_CAMERAS, masks, n[:, 0]):
                border = mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any()
                assert not border, f"{cam}: the ball at {p} touches the frame's border"
                assert count >= 20, f"{cam}: the ball at {p} covers only {count} px"
            assert np.all(np.isfinite(uv[:, 0]))
    finally:
        world.close()
    assert TARGET_RADIUS_M == 0.025  # the margins above were designed for this ball


def test_the_planar_front_camera_is_unchanged():
    """The planar checkpoint's camera keeps its pose (the new cameras are added after it)."""
    from scenarios.world.panda_scene import AVAILABLE_CAMERAS, _CAMERAS

    assert AVAILABLE_CAMERAS[:3] == ("front", "top", "side")
    assert _CAMERAS["front"] == ((1.55, -0.5, 0.75), (0.45, 0.02, 0.3), 45.0)


def test_the_detector_finds_a_disc_to_a_tenth_of_a_pixel_and_nothing_in_grey():
    yy, xx = np.mgrid[0:64, 0:64] + 0.5
    img = np.full((64, 64, 3), 120, np.uint8)
    disc = (xx - 20.3) ** 2 + (yy - 41.7) ** 2 < 4.5**2
    img[disc] = (200, 30, 25)
    uv, n = detect_balls(img)
    assert n[0] == disc.sum() and n[1] == 0
    np.testing.assert_allclose(uv[0], [20.3, 41.7], atol=0.1)
    assert np.all(np.isnan(uv[1]))  # no blue ball
    tok = BallTokenizer(64, 2048, token_offset=1000, absent_id=0)
    t = tok.encode(uv)
    assert t[1].tolist() == [0, 0] and np.all((t[0] >= 1000) & (t[0] < 3048))
    np.testing.assert_allclose(tok.decode(t)[0], uv[0], atol=64 / 2048)
    with pytest.raises(ValueError, match="uint8"):
        detect_balls(img.astype(float))
    with pytest.raises(ValueError, match="colours"):
        BallDetectorConfig(colors=("purple",))


def test_the_aux_position_target_round_trips_through_its_bins_and_is_masked_in_every_query():
    cfg = ModelConfig(d_model=32, n_layers=1, n_heads=2, ball_views=4, aux_positions=2, max_text_len=16)
    b = untrained_bundle(cfg, ImageTokenizerConfig(strides=(2, 2, 3)))
    rng = np.random.default_rng(0)
    spec = TargetSpec()
    pos = np.array(spec.workspace_low_m) + rng.random((50, 2, 3)) * (np.array(spec.workspace_high_m) - spec.workspace_low_m)
    tokens = b.aux_tokens(pos)
    lo, hi = b.model.vocab.range_of("action")
    assert tokens.shape == (50, 2, 3) and np.all((tokens >= lo) & (tokens < hi))
    back = b.aux_positions_m(tokens - lo)
    half_bin = b.action_tokenizer.bin_width[:3] / 2
    assert np.all(np.abs(back - pos) <= half_bin + 1e-12)
    # in the layout: its own slots, between the state and the chunk; None (every query) masks them
    images = np.zeros((1, 2, b.image_cfg.grid, b.image_cfg.grid), np.int64)
    balls = np.full((1, 4 * 2 * 2), b.model.vocab.pad_id)
    state = b.state_tokens(np.zeros((1, 7)))
    toks, lay = b.builder.fill("mm2a", b.text_batch(["reach the red ball"]), images, state, None, ball_tokens=balls)
    assert len(lay.aux_idx) == 6 and np.all(toks[0, lay.aux_idx] == b.model.vocab.mask_id)
    assert lay.slots["state"].stop < lay.aux_idx[0] < lay.target.start
    full, _ = b.builder.fill("mm2a", b.text_batch(["reach the red ball"]), images, state, None, ball_tokens=balls,
                             aux_tokens=tokens[:1].reshape(1, -1))
    np.testing.assert_array_equal(full[0, lay.aux_idx], tokens[0].ravel())
    # two cameras x two frames, ball tokens, the current frame's 8x8 codes only: the L <= 300
    assert lay.length <= 300 and lay.n_views == 2


def test_old_checkpoints_keep_their_layouts():
    """A model without the issue-25 switches builds exactly the sequences it was trained on."""
    b = untrained_bundle(ModelConfig(d_model=32, n_layers=1, n_heads=2))
    assert b.builder.get("mm2a", 1).length == 296 and b.builder.get("mm2a", 4).length == 734
    assert "balls" not in b.builder.get("mm2a", 4).slots and not len(b.builder.get("mm2a", 4).aux_idx)


@pytest.fixture(scope="module")
def box_data(tmp_path_factory):
    """Three short episodes seen by the box cameras at t and t - 0.4 s, and a stage-0 tokenizer of them."""
    from policy.train import main as train_main

    root = tmp_path_factory.mktemp("box")
    cfg = CollectConfig(episodes=3, objects=2, motion="linear", duration_s=1.5, cameras=BOX_CAMERAS, frame_gap_s=0.4,
                        expert_lead="velocity", seed=31)
    collect(cfg, root / "data", progress=False)
    s0 = train_main(["--data", str(root / "data"), "--stage", "0", "--out", str(root / "s0"), "--steps", "2",
                     "--batch-size", "4", "--strides", "2,2,3", "--no-progress"])
    return root, s0


TINY = ["--d-model", "32", "--layers", "1", "--heads", "2", "--eval-samples", "4", "--no-progress"]
LAYOUT = ["--ball-tokens", "1", "--aux-positions", "2", "--mm2a-image-frames", "1", "--max-text-len", "16"]


def _losses(bundle: PolicyBundle, data, idx) -> dict[str, float]:
    from policy.training.losses import task_loss

    bundle.model.eval()
    out = {}
    with torch.no_grad():
        for task in ("mm2a", "t2i", "mmu"):
            loss, aux = task_loss(bundle, data, task, idx, np.random.default_rng(0), 0.5, "cpu", 16.0, with_aux=True)
            out[task] = float(loss)
            if aux is not None:
                out["aux"] = float(aux)
    return out


def test_training_lowers_the_loss_of_each_task_token(box_data):
    """<|mm2a|> (its chunk and its aux ball positions), <|t2i|> and <|mmu|> all fit better after training."""
    from policy.train import main as train_main
    from policy.training.tokenize import load_tokenized

    root, s0 = box_data
    common = ["--data", str(root / "data"), "--stage", "2", "--w-text", "1", "--w-image", "1", "--w-aux", "1", *TINY]
    before = train_main([*common, "--init", str(s0), "--out", str(root / "a"), "--steps", "1", "--lr", "1e-9",
                         "--batch-size", "4", *LAYOUT])
    after = train_main([*common, "--init", str(before), "--out", str(root / "b"), "--steps", "40", "--lr", "3e-3",
                        "--batch-size", "8"])
    b0, b1 = PolicyBundle.load(before), PolicyBundle.load(after)
    assert b1.model_cfg.ball_views == 4 and b1.model_cfg.aux_positions == 2 and b1.mm2a_image_frames == 1
    data = load_tokenized(b0, [str(root / "data")], progress=False)
    idx = np.arange(len(data["img"]))
    l0, l1 = _losses(b0, data, idx), _losses(b1, data, idx)
    assert set(l0) == {"mm2a", "aux", "t2i", "mmu"}
    for task in l0:
        assert l1[task] < 0.9 * l0[task], (task, l0[task], l1[task])


def test_a_box_policy_gives_a_valid_chunk_from_the_four_views_of_the_loop(box_data):
    """The checkpoint's query through the control stack's source: four frames (two cameras, now and 0.4 s ago) in,
    one chunk of action tokens out, and the aux target's positions inside the workspace bounds."""
    from mmact_ctrl.chunk import Observation
    from mmact_ctrl.policy_source import PolicyChunkSource
    from policy.train import main as train_main
    from scenarios.world.factory import make_world, policy_scene

    root, s0 = box_data
    ck = train_main(["--data", str(root / "data"), "--stage", "2", "--init", str(s0), "--out", str(root / "c"),
                     "--steps", "2", "--batch-size", "4", *TINY, *LAYOUT])
    source = PolicyChunkSource(ck)
    assert source.camera_names == BOX_CAMERAS and source.prev_frame_gap_s == pytest.approx(0.4)
    world = make_world("linear", **policy_scene(source))
    try:
        world.reset(5)
        now = world.render()
        obs = Observation(t0_s=0.4, q_rad=world.state().q_rad, dq_rad_s=np.zeros(7), ee_pos_m=world.home_tcp_pos_m(),
                          ee_rotvec_rad=np.zeros(3), gripper_m=0.08, target_pos_m=world.target_pos_m(), image=now,
                          instruction=world.instruction, prev_image=now)
        chunk = source.plan(obs)
        lo, hi = source.action_token_range
        assert chunk.tokens.shape == (16, 7) and chunk.tokens.min() >= lo and chunk.tokens.max() < hi
        assert np.all(np.isfinite(chunk.waypoints))
        ball = source.policy.predict_ball_positions(source.views(obs), obs.instruction, obs.q_rad)
        tok = source.policy.action_tokenizer
        assert ball.shape == (2, 3) and np.all((ball >= tok.low[:3]) & (ball <= tok.high[:3]))
        with pytest.raises(ValueError, match="views"):
            source.policy.predict_chunk(now, obs.instruction, obs.q_rad)  # two views: the earlier frame is missing
    finally:
        world.close()


def test_token_caches_accumulate_and_one_of_another_detector_or_tokenizer_is_refused(box_data, tmp_path):
    """Two collections cached apart train together (each keeps its directory index); a cache whose ball tokens came
    from another detector, or whose codes from another VQ-VAE, is refused."""
    import dataclasses

    from policy.token_cache import TokenCacheError, load_token_cache, main as cache_main
    from policy.train import main as train_main
    from policy.training.data import training_tokens

    root, s0 = box_data
    ck = train_main(["--data", str(root / "data"), "--stage", "2", "--init", str(s0), "--out", str(tmp_path / "c"),
                     "--steps", "1", "--batch-size", "4", *TINY, *LAYOUT])
    a = cache_main(["--data", str(root / "data"), "--checkpoint", str(ck), "--out", str(tmp_path / "a.npz"), "--no-progress"])
    b = cache_main(["--data", str(root / "data"), "--checkpoint", str(ck), "--out", str(tmp_path / "b.npz"), "--no-progress"])
    bundle = PolicyBundle.load(ck)
    args = type("A", (), {"tokens_cache": [str(a), str(b)], "data": [], "no_progress": True})()
    both = training_tokens(bundle, args)
    one, header = load_token_cache(a, bundle)
    assert len(both["img"]) == 2 * len(one["img"]) and set(np.unique(both["source"])) == {0, 1}
    assert one["ball"].shape == (len(one["img"]), 4, 2, 2) and np.all(np.isfinite(one["target_prev_pos_m"]))
    out = train_main(["--tokens-cache", str(a), str(b), "--stage", "2", "--init", str(ck), "--out", str(tmp_path / "t"),
                      "--steps", "1", "--batch-size", "4", "--data-weights", "1", "3", *TINY])
    assert PolicyBundle.load(out).info["data"] == f"{root / 'data'} {root / 'data'}"
    other = dataclasses.replace(bundle.ball_detector, min_chroma=0.3)
    bundle.ball_detector = other
    with pytest.raises(TokenCacheError, match="other tokenizers"):
        load_token_cache(a, bundle)
    refreshed = train_main(["--data", str(root / "data"), "--stage", "0", "--init", str(ck), "--out", str(tmp_path / "r"),
                            "--steps", "1", "--batch-size", "4", "--no-progress"])
    with pytest.raises(SystemExit, match="other tokenizers"):
        train_main(["--tokens-cache", str(a), "--stage", "2", "--init", str(refreshed), "--out", str(tmp_path / "x"),
                    "--steps", "1", "--batch-size", "4", *TINY])


SHIPPED_BOX = Path(__file__).resolve().parents[1] / "policy" / "checkpoints" / "mmact_3d_box.pt"


def test_the_shipped_box_checkpoint_aims_from_its_views_at_the_instructed_ball(first_query_aims):
    """The shipped box-layout checkpoint (``policy/checkpoints/mmact_3d_box.pt``, issue 25): <= 20 MB, the box cameras
    now and 0.4 s ago; from the first query of real rendered scenes its chunk is valid, ends nearer the instructed ball
    than the arm starts and nearer it than the other ball, and its aux target puts the ball inside the workspace."""
    from mmact_ctrl.policy_source import PolicyChunkSource
    from scenarios.world.factory import policy_scene

    assert SHIPPED_BOX.is_file() and SHIPPED_BOX.stat().st_size <= 20e6
    source = PolicyChunkSource(SHIPPED_BOX)
    assert source.camera_names == BOX_CAMERAS and source.prev_frame_gap_s == pytest.approx(0.4)
    assert policy_scene(source)["cameras"] == BOX_CAMERAS
    tok = source.policy.action_tokenizer
    ball_err = []

    def aux_ball(source, obs, chunk, world):
        ball = source.policy.predict_ball_positions(source.views(obs), obs.instruction, obs.q_rad)
        assert ball.shape == (2, 3) and np.all((ball >= tok.low[:3]) & (ball <= tok.high[:3]))
        ball_err.append(np.linalg.norm(ball[0] - world.target_pos_m()))

    start, end, other = first_query_aims(source, range(9000, 9008), aux_ball)
    assert np.mean(end) < 0.5 * np.mean(start), (end, start)
    assert np.mean(end < other) >= 0.75, (end, other)
    assert np.median(ball_err) < 0.1, ball_err  # the aux target finds the instructed ball to within 10 cm
