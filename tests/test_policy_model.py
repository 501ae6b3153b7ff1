"""Model, decoding and checkpoints of the unified-token policy (tiny sizes, CPU, seconds)."""

from pathlib import Path

import numpy as np
import pytest
import torch

from policy.bundle import PolicyBundle, untrained_bundle
from policy.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from policy.config import ImageTokenizerConfig, ModelConfig
from policy.decoding import (
    cosine_masked_count,
    decode_autoregressive,
    decode_parallel,
    decode_parallel_logits,
    expected_bins,
    target_tokens,
)
from policy.inference import DEFAULT_CHECKPOINT, MMActPolicy
from policy.train import TASK_WEIGHT, task_loss

TINY_IMG = ImageTokenizerConfig(image_size_px=32, strides=(2, 2), channels=(8, 16), codebook_size=32, code_dim=8)
TINY_MODEL = ModelConfig(d_model=64, n_layers=2, n_heads=4, max_text_len=8, max_answer_len=4, max_views=2)


@pytest.fixture(scope="module")
def bundle():
    return untrained_bundle(TINY_MODEL, TINY_IMG, seed=0)


def tiny_data(b: PolicyBundle, n: int = 4, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    g, k = b.image_cfg.grid, b.image_cfg.codebook_size
    at = b.action_tokenizer
    actions = rng.uniform(at.low, at.high, size=(n, 16, 7))
    texts = ["reach the red ball", "touch the blue sphere", "move to the green ball", "reach the yellow sphere"]
    return {
        "img": rng.integers(0, k, size=(n, 1, g, g)), "fut": rng.integers(0, k, size=(n, 1, g, g)),
        "instr": b.text_batch(texts[:n]), "quest": b.text_batch(["where is the red ball?"] * n),
        "answer": b.text_batch(["left", "right", "center", "left"][:n], b.model_cfg.max_answer_len, end_with_eot=True),
        "answer_str": np.array(["left", "right", "center", "left"][:n]),
        "state": b.state_tokens(rng.uniform(-1, 1, size=(n, 7))), "action": b.action_tokens(actions),
        "actions_f": actions, "target_pos_m": actions[:, -1, :3],
    }


@pytest.mark.parametrize("task", ["mm2a", "t2i", "mmu"])
def test_tiny_model_overfits_tiny_batch(task):
    """Fully masked target, fixed batch of 4: the loss falls by at least 10x within 150 Adam steps.

    Measured at seed 0: mm2a 7.4 -> 0.03, t2i 3.5 -> 0.13, mmu 5.3 -> 0.24.
    """
    torch.manual_seed(0)
    b = untrained_bundle(TINY_MODEL, TINY_IMG, seed=0)
    data = tiny_data(b)
    idx = np.arange(4)
    opt = torch.optim.Adam(b.model.parameters(), lr=5e-3)
    b.model.train()
    losses = []
    for step in range(150):
        rng = np.random.default_rng(step)
        loss = task_loss(b, data, task, idx, rng, 1.0, "cpu")
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
    first, last = np.mean(losses[:3]), np.mean(losses[-5:])
    assert last < first / 10, f"{task} ({TASK_WEIGHT[task]}): loss {first:.3f} -> {last:.3f}"


@pytest.mark.parametrize("task", ["mm2a", "t2i", "mmu"])
@pytest.mark.parametrize("steps", [1, 3, "ar"])
def test_decoding_emits_only_the_target_modality(bundle, task, steps):
    data = tiny_data(bundle, 2)
    m = bundle.model.eval()
    b = bundle.builder
    img = np.concatenate([data["img"], data["fut"]], axis=1)  # 2 views
    text = data["quest"] if task == "mmu" else data["instr"]
    toks, lay = b.fill(task, text, img, data["state"] if task == "mm2a" else None, None)
    t = torch.as_tensor(toks)
    # bias the head hard towards a wrong-modality token: the restriction must still hold
    with torch.no_grad():
        m.head_bias[m.vocab.mask_id] += 100.0
        m.head_bias[m.vocab.text_offset if task != "mmu" else m.vocab.image_offset] += 100.0
    try:
        out = decode_autoregressive(m, t, lay) if steps == "ar" else decode_parallel(m, t, lay, steps)
    finally:
        with torch.no_grad():
            m.head_bias.zero_()
    tgt = target_tokens(out, lay).numpy()
    lo, hi = m.vocab.range_of(lay.target_modality)
    expect = {"mm2a": 16 * 7, "t2i": 2 * bundle.image_cfg.grid ** 2, "mmu": TINY_MODEL.max_answer_len}[task]
    assert tgt.shape == (2, expect)
    assert tgt.min() >= lo and tgt.max() < hi
    # everything outside the target is untouched
    keep = np.ones(lay.length, bool)
    keep[lay.target_idx] = False
    assert np.array_equal(out.numpy()[:, keep], toks[:, keep])


def test_cosine_schedule_ends_unmasked():
    assert [cosine_masked_count(112, s, 4) for s in range(1, 5)] == [103, 79, 42, 0]
    assert cosine_masked_count(10, 1, 1) == 0


def test_expected_bins_is_the_local_mean_around_the_chosen_peak():
    n = 2048
    bins = torch.arange(n, dtype=torch.float32)
    # a Gaussian at 100.3 bins plus a second, weaker peak at 900: the local mean recovers 100.3, not the global mean
    logp = torch.logaddexp(-0.5 * ((bins - 100.3) / 8) ** 2, -0.5 * ((bins - 900) / 8) ** 2 + np.log(0.6))
    logits = logp[None, None]  # (1, 1, n)
    chosen = logits.argmax(-1)
    assert int(chosen) == 100
    assert float(expected_bins(logits, chosen, 64)) == pytest.approx(100.3, abs=0.05)
    full = float(expected_bins(logits, chosen, n))
    assert 350 < full < 450  # the unwindowed mean lands between the two peaks: why the window exists
    assert float(expected_bins(logits, chosen, 0)) == 100.0
    with pytest.raises(ValueError, match="window"):
        expected_bins(logits, chosen, -1)


def test_decode_fractional_matches_decode_on_integers_and_checks_range():
    from policy.action_tokenizer import ActionTokenizer

    tok = ActionTokenizer(bins=256, token_offset=10)
    idx = np.random.default_rng(1).integers(0, 256, size=(5, 7))
    assert np.allclose(tok.decode_fractional(idx.astype(float)), tok.decode(idx + 10))
    half = tok.decode_fractional(np.full((1, 7), 3.5))
    assert np.allclose(half, (tok.decode(np.full((1, 7), 13)) + tok.decode(np.full((1, 7), 14))) / 2)
    for bad in (np.full((1, 7), -0.5), np.full((1, 7), 255.5), np.full((1, 7), np.nan)):
        with pytest.raises(ValueError, match="bin indices"):
            tok.decode_fractional(bad)


def test_predict_chunk_refine_bins(bundle):
    pol = MMActPolicy(bundle)
    assert pol.default_refine_bins == 0  # no recorded training labels: bin centres by default
    imgs = np.random.default_rng(0).integers(0, 256, size=(1, 32, 32, 3), dtype=np.uint8)
    q = np.zeros(7)
    t0, a0 = pol.predict_chunk(imgs, "reach the red ball", q)
    assert np.allclose(a0, pol.action_tokenizer.decode(t0))
    tw, aw = pol.predict_chunk(imgs, "reach the red ball", q, refine_bins=16)
    assert np.array_equal(t0, tw)  # the tokens are the greedy ones either way
    # refined values stay within the window (+- 16 bins) of the greedy bin centre, and differ from it
    assert np.all(np.abs(aw - a0) <= 16 * pol.action_tokenizer.bin_width + 1e-12)
    assert not np.allclose(aw, a0)
    toks, lay = pol.mm2a_batch(imgs, "reach the red ball", q)
    filled, logits = decode_parallel_logits(bundle.model, toks, lay)
    lo, _ = bundle.model.vocab.range_of("action")
    assert torch.equal(filled, decode_parallel(bundle.model, toks, lay))
    assert torch.equal(logits.argmax(-1) + lo, target_tokens(filled, lay))
    # with re-masking, each position's logits are those of the pass that filled it: their argmax is its token
    filled4, logits4 = decode_parallel_logits(bundle.model, toks, lay, steps=4)
    assert torch.equal(logits4.argmax(-1) + lo, target_tokens(filled4, lay))
    known = np.full((16, 7), -1, np.int64)
    known[:4] = lo + 7
    tk, ak = pol.predict_chunk(imgs, "reach the red ball", q, known_actions=known, refine_bins=16)
    assert np.allclose(ak[:4], pol.action_tokenizer.decode(tk[:4]))  # known tokens stay at their bin centres
    with pytest.raises(ValueError, match="refine_bins"):
        pol.predict_chunk(imgs, "x", q, refine_bins=-1)


def test_predict_chunk_shapes_and_inpainting(bundle):
    pol = MMActPolicy(bundle)
    imgs = np.random.default_rng(0).integers(0, 256, size=(1, 32, 32, 3), dtype=np.uint8)
    q = np.zeros(7)
    tokens, actions = pol.predict_chunk(imgs, "reach the red ball", q)
    assert tokens.shape == (16, 7) and tokens.dtype == np.int64 and actions.shape == (16, 7)
    lo, hi = bundle.model.vocab.range_of("action")
    assert tokens.min() >= lo and tokens.max() < hi
    assert np.allclose(actions, pol.action_tokenizer.decode(tokens))
    t4, _ = pol.predict_chunk(imgs, "reach the red ball", q, action_steps=4)
    assert t4.shape == (16, 7)
    known = np.full((16, 7), -1, np.int64)
    known[:4] = lo + 7
    tk, _ = pol.predict_chunk(imgs, "reach the red ball", q, known_actions=known)
    assert np.all(tk[:4] == lo + 7)
    with pytest.raises(ValueError):
        pol.predict_chunk(imgs, "x", q, known_actions=np.full((16, 7), 5, np.int64))
    ta, aa = pol.predict_chunk_autoregressive(imgs, "reach the red ball", q)
    assert ta.shape == (16, 7)
    assert isinstance(pol.answer(imgs, "where is the red ball?"), str)
    codes = pol.predict_future_codes(np.concatenate([imgs, imgs]), "reach the red ball")
    assert codes.shape == (2, 8, 8) and codes.min() >= 0 and codes.max() < 32
    assert pol.horizon == 16 and pol.chunk_dt_s == pytest.approx(0.1)


def test_checkpoint_saves_and_loads_bit_identically(bundle, tmp_path):
    p = bundle.save(tmp_path / "a.pt", {"note": "test"})
    b2 = PolicyBundle.load(p)
    for mod_a, mod_b in ((bundle.model, b2.model), (bundle.image_tokenizer, b2.image_tokenizer)):
        sa, sb = mod_a.state_dict(), mod_b.state_dict()
        assert sa.keys() == sb.keys()
        for k in sa:
            assert sa[k].dtype == sb[k].dtype and torch.equal(sa[k], sb[k]), k
    assert b2.text_tokenizer.to_json() == bundle.text_tokenizer.to_json()
    assert b2.action_tokenizer == bundle.action_tokenizer and b2.state_tokenizer == bundle.state_tokenizer
    assert b2.model_cfg == bundle.model_cfg and b2.image_cfg == bundle.image_cfg
    # re-saving the loaded checkpoint gives the same bytes
    p2 = b2.save(tmp_path / "b.pt", {"note": "test"})
    assert p.read_bytes() == p2.read_bytes()
    imgs = np.random.default_rng(0).integers(0, 256, size=(1, 32, 32, 3), dtype=np.uint8)
    ta, aa = MMActPolicy(bundle).predict_chunk(imgs, "reach the red ball", np.zeros(7))
    tb, ab = MMActPolicy(b2).predict_chunk(imgs, "reach the red ball", np.zeros(7))
    assert np.array_equal(ta, tb) and np.array_equal(aa, ab)


def test_corrupt_or_mismatched_checkpoint_gives_clear_error(bundle, tmp_path):
    p = bundle.save(tmp_path / "good.pt")
    raw = p.read_bytes()
    with pytest.raises(CheckpointError, match="does not exist"):
        MMActPolicy.load(tmp_path / "missing.pt")
    (tmp_path / "trunc.pt").write_bytes(raw[: len(raw) // 2])
    with pytest.raises(CheckpointError, match="corrupt or truncated"):
        MMActPolicy.load(tmp_path / "trunc.pt")
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint at all")
    with pytest.raises(CheckpointError, match="corrupt or truncated"):
        MMActPolicy.load(tmp_path / "junk.pt")
    # flip bytes inside the largest tensor's data: the checksum catches it
    payload = load_checkpoint(p)
    w = payload["model_state"]["tok.weight"]
    needle = w[5, :8].numpy().tobytes()
    at = raw.find(needle)
    assert at > 0
    bad = bytearray(raw)
    bad[at : at + 4] = bytes(b ^ 0xFF for b in bad[at : at + 4])
    (tmp_path / "flip.pt").write_bytes(bytes(bad))
    with pytest.raises(CheckpointError, match="checksum mismatch|corrupt"):
        MMActPolicy.load(tmp_path / "flip.pt")
    # weights that do not fit the stored config
    payload = load_checkpoint(p)
    payload["model_config"] = {**payload["model_config"], "d_model": 32, "n_heads": 2}
    save_checkpoint(tmp_path / "mismatch.pt", payload)
    with pytest.raises(CheckpointError, match="model weights do not match its config.*shape mismatch"):
        MMActPolicy.load(tmp_path / "mismatch.pt")
    # another file format / a newer version
    torch.save({"format": "something-else"}, tmp_path / "other.pt")
    with pytest.raises(CheckpointError, match="not an mmact-ctrl policy checkpoint"):
        MMActPolicy.load(tmp_path / "other.pt")
    payload = load_checkpoint(p)
    payload["format_version"] = 99
    torch.save(payload, tmp_path / "v99.pt")
    with pytest.raises(CheckpointError, match="format version 99"):
        MMActPolicy.load(tmp_path / "v99.pt")
    # a stage-0 file (tokenizers only) is not a policy
    payload = load_checkpoint(p)
    payload["model_state"] = None
    save_checkpoint(tmp_path / "stage0.pt", payload)
    with pytest.raises(CheckpointError, match="no model weights"):
        MMActPolicy.load(tmp_path / "stage0.pt")


def test_shipped_checkpoint_loads_and_predicts():
    if not Path(DEFAULT_CHECKPOINT).is_file():
        pytest.skip(f"{DEFAULT_CHECKPOINT} not shipped yet")
    assert Path(DEFAULT_CHECKPOINT).stat().st_size <= 20e6
    pol = MMActPolicy.load(DEFAULT_CHECKPOINT)
    assert pol.default_refine_bins == 64  # trained on Gaussian labels of std 16 bins: +-4 std
    s = pol.bundle.image_cfg.image_size_px
    imgs = np.full((1, s, s, 3), 128, np.uint8)
    tokens, actions = pol.predict_chunk(imgs, "reach the red ball", np.array([0, -0.3, 0, -2.2, 0, 1.9, 0.8]))
    lo, hi = pol.model.vocab.range_of("action")
    assert tokens.shape == (pol.horizon, 7) and tokens.min() >= lo and tokens.max() < hi
    assert np.all(np.isfinite(actions)) and np.all(actions >= pol.action_tokenizer.low) and np.all(actions <= pol.action_tokenizer.high)
