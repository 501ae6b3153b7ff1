"""Training from a token cache (no frames needed) and the wall-clock budget of the training loop."""

import json

import numpy as np
import pytest

from policy.bundle import PolicyBundle
from policy.inference import MMActPolicy
from policy.synthetic import write_synthetic_dataset
from policy.token_cache import TokenCacheError, load_token_cache, main as cache_main, read_header
from policy.train import main as train_main
from policy.training.stage12 import budget_steps
from policy.training.tokenize import load_tokenized

TINY = ["--d-model", "32", "--layers", "1", "--heads", "2", "--batch-size", "4", "--eval-samples", "4", "--no-progress"]


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A synthetic dataset, a stage-0 checkpoint, and a stage-2 run that wrote the token cache."""
    root = tmp_path_factory.mktemp("cache")
    syn = write_synthetic_dataset(root / "syn", n_samples=30, shard_size=16, seed=5)
    s0 = train_main(["--data", str(syn), "--stage", "0", "--out", str(root / "s0"), "--steps", "2", "--batch-size", "4",
                     "--no-progress"])
    cache = root / "tokens.npz"
    s2 = train_main(["--data", str(syn), "--tokens-cache", str(cache), "--stage", "2", "--init", str(s0),
                     "--out", str(root / "s2"), "--steps", "3", *TINY])
    return syn, s0, s2, cache, root


def test_the_cache_holds_exactly_the_tokens_of_the_frames(trained):
    syn, _, s2, cache, _ = trained
    assert cache.is_file()
    bundle = PolicyBundle.load(s2)
    data, header = load_token_cache(cache, bundle)
    fresh = load_tokenized(bundle, [str(syn)], progress=False)
    assert header["n_samples"] == 30 and header["data_paths"] == [str(syn)]
    assert header["meta"]["camera_names"] == json.loads((syn / "meta.json").read_text())["camera_names"]
    for k, v in fresh.items():
        np.testing.assert_array_equal(data[k], v, err_msg=k)


def test_stage2_trains_from_the_cache_alone_and_its_chunk_is_valid(trained, tmp_path):
    syn, _, s2, cache, _ = trained
    out = train_main(["--tokens-cache", str(cache), "--stage", "2", "--init", str(s2), "--out", str(tmp_path / "s2c"),
                      "--steps", "2", *TINY])
    pol = MMActPolicy.load(out)
    assert pol.bundle.info["data"] == str(syn)  # the card names the dataset the cache was made from
    card = (tmp_path / "s2c" / "MODEL_CARD.md").read_text()
    assert "--tokens-cache" in card and "30 samples" in card
    from policy.dataset import PolicyDataset

    ds = PolicyDataset.load(syn)
    tokens, actions = pol.predict_chunk(ds.data["images"][0], str(ds.data["instructions"][0]), ds.data["q_rad"][0])
    lo, hi = pol.bundle.model.vocab.range_of("action")
    assert tokens.shape == (16, 7) and np.all((tokens >= lo) & (tokens < hi)) and np.all(np.isfinite(actions))


def test_a_cache_of_other_tokenizers_or_other_data_is_refused(trained, tmp_path):
    syn, _, s2, cache, root = trained
    other0 = train_main(["--data", str(syn), "--stage", "0", "--out", str(tmp_path / "o0"), "--steps", "2",
                         "--batch-size", "4", "--seed", "9", "--no-progress"])
    other2 = train_main(["--data", str(syn), "--stage", "2", "--init", str(other0), "--out", str(tmp_path / "o2"),
                         "--steps", "1", *TINY])
    with pytest.raises(TokenCacheError, match="other tokenizers"):
        load_token_cache(cache, PolicyBundle.load(other2))
    with pytest.raises(SystemExit, match="other tokenizers"):
        train_main(["--tokens-cache", str(cache), "--stage", "2", "--init", str(other2), "--out", str(tmp_path / "x"),
                    "--steps", "1", *TINY])
    with pytest.raises(SystemExit, match="not of --data"):
        train_main(["--data", str(tmp_path), "--tokens-cache", str(cache), "--stage", "2", "--init", str(s2),
                    "--out", str(tmp_path / "y"), "--steps", "1", *TINY])
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(TokenCacheError, match="not a token cache"):
        read_header(tmp_path / "junk.npz")
    with pytest.raises(SystemExit, match="stages 1/2"):
        train_main(["--data", str(syn), "--tokens-cache", str(cache), "--stage", "0", "--out", str(tmp_path / "z")])
    with pytest.raises(SystemExit):
        train_main(["--stage", "2", "--init", str(s2), "--out", str(tmp_path / "w")])  # neither --data nor a cache


def test_the_cache_command_writes_what_training_reads(trained, tmp_path):
    syn, _, s2, cache, _ = trained
    out = cache_main(["--data", str(syn), "--checkpoint", str(s2), "--out", str(tmp_path / "t.npz"), "--no-progress"])
    a, _ = load_token_cache(out, PolicyBundle.load(s2))
    b, _ = load_token_cache(cache, PolicyBundle.load(s2))
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


def test_budget_steps_fits_the_time_left():
    # 0.5 s/step, 10 s left at step 30: 20 more steps
    assert budget_steps(30, 1, 0.5, 10.0, 1000) == 50
    assert budget_steps(30, 1, 0.5, 10.0, 40) == 40  # never more than planned
    assert budget_steps(30, 1, 0.5, -3.0, 1000) == 30  # over budget already: stop now
    assert budget_steps(30, 0, 0.0, 10.0, 1000) == 1000  # nothing measured: the plan stands


def test_the_time_budget_stops_training_and_the_checkpoint_is_complete(trained, tmp_path):
    _, _, s2, cache, _ = trained
    out = train_main(["--tokens-cache", str(cache), "--stage", "2", "--init", str(s2), "--out", str(tmp_path / "tb"),
                      "--steps", "1000000", "--time-budget-s", "3", *TINY])
    info = MMActPolicy.load(out).bundle.info
    steps = info["train_config"]["steps"]
    assert 1 <= steps < 1000000
    assert info["train_wall_s"] < 60.0  # stopped by the budget, not by a million steps
    assert "--time-budget-s" in (tmp_path / "tb" / "MODEL_CARD.md").read_text()
    with pytest.raises(SystemExit):
        train_main(["--tokens-cache", str(cache), "--stage", "2", "--init", str(s2), "--out", str(tmp_path / "tb2"),
                    "--time-budget-s", "nan", *TINY])
