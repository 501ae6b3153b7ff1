"""Dataset reader, synthetic generator and the training CLI end to end (a few steps, tiny sizes)."""

import json

import numpy as np
import pytest

from policy.dataset import DatasetError, PolicyDataset, read_shard, shard_paths, split_indices
from policy.inference import MMActPolicy
from policy.synthetic import make_samples, world_to_pixel, write_synthetic_dataset
from policy.train import main as train_main



@pytest.fixture(scope="module")
def syn(tmp_path_factory):
    return write_synthetic_dataset(tmp_path_factory.mktemp("syn"), n_samples=40, shard_size=25, seed=3)


def test_synthetic_dataset_reads_in_the_collect_format(syn):
    ds = PolicyDataset.load(syn)
    assert len(ds) == 40 and len(shard_paths(syn)) == 2
    d = ds.data
    assert d["images"].shape == (40, 1, 96, 96, 3) and d["images"].dtype == np.uint8
    assert d["actions"].shape == (40, 16, 7) and d["q_rad"].shape == (40, 7)
    assert set(np.unique(d["answers"])) <= {"left", "right", "center", "two", "three"}
    # the last waypoint is the named disc, and that disc is drawn where the camera model says
    np.testing.assert_allclose(d["actions"][:, -1, :3], d["target_pos_m"], atol=1e-6)
    for i in range(5):
        r, c = world_to_pixel(*d["target_pos_m"][i, :2], 96)
        colour = d["instructions"][i].split()[-2]
        px = d["images"][i, 0, int(r), int(c)].astype(int)
        from policy.synthetic import COLOURS

        assert np.abs(px - np.array(COLOURS[colour])).max() < 2
    tr, va = split_indices(40, 0.1, 1234)
    assert len(va) == 4 and len(np.intersect1d(tr, va)) == 0 and len(tr) + len(va) == 40
    assert make_samples(3, n_views=2)["images"].shape == (3, 2, 96, 96, 3)


def test_dataset_errors_name_the_problem(syn, tmp_path):
    with pytest.raises(DatasetError, match="no meta.json"):
        PolicyDataset.load(tmp_path)
    meta = json.loads((syn / "meta.json").read_text())
    shard = shard_paths(syn)[0]
    bad = dict(np.load(shard))
    bad["actions"] = bad["actions"][:, :8]
    np.savez(tmp_path / "shard_0000.npz", **bad)
    with pytest.raises(DatasetError, match="'actions' has shape"):
        read_shard(tmp_path / "shard_0000.npz", meta)
    (tmp_path / "shard_0001.npz").write_bytes(b"garbage")
    with pytest.raises(DatasetError, match="unreadable shard"):
        read_shard(tmp_path / "shard_0001.npz", meta)


def test_train_cli_stage0_then_stage2_resume_and_load(syn, tmp_path):
    common = ["--data", str(syn), "--no-progress", "--seed", "1"]
    s0 = train_main([*common, "--stage", "0", "--out", str(tmp_path / "s0"), "--steps", "2", "--batch-size", "4"])
    tiny = ["--d-model", "32", "--layers", "1", "--heads", "2", "--batch-size", "4", "--eval-samples", "4"]
    out = tmp_path / "s2"
    s2 = train_main([*common, "--stage", "2", "--out", str(out), "--init", str(s0), "--steps", "2", "--save-every", "1", *tiny])
    assert s2.is_file() and (out / "resume_stage2.pt").is_file()
    card = (out / "MODEL_CARD.md").read_text()
    for needle in ("python -m policy.train", "40 samples", "mm2a", "action_pos_err_m", "mmu_answer_acc",
                   "t2i_token_acc", "image_psnr_db_heldout", "wall time"):
        assert needle in card, needle
    s2b = train_main([*common, "--stage", "2", "--out", str(out), "--resume", "--steps", "4", *tiny])
    pol = MMActPolicy.load(s2b)
    assert pol.bundle.info["train_config"]["steps"] == 4
    ds = PolicyDataset.load(syn)
    tokens, actions = pol.predict_chunk(ds.data["images"][0], str(ds.data["instructions"][0]), ds.data["q_rad"][0])
    assert tokens.shape == (16, 7) and actions.shape == (16, 7)
    with pytest.raises(SystemExit, match="needs --init"):
        train_main([*common, "--stage", "1", "--out", str(tmp_path / "s1"), "--steps", "1"])


def test_several_dataset_directories_train_together(syn, tmp_path):
    """``--data A B`` trains on both (e.g. expert demos + DAgger relabels); their layouts must agree."""
    from policy.dataset import dataset_shards, read_metas

    syn2 = write_synthetic_dataset(tmp_path / "syn2", n_samples=10, shard_size=10, seed=4)
    meta = read_metas([syn, syn2])
    assert meta["n_samples"] == 50 and len(dataset_shards([syn, syn2])) == 3
    common = ["--data", str(syn), str(syn2), "--no-progress", "--seed", "1"]
    s0 = train_main([*common, "--stage", "0", "--out", str(tmp_path / "s0"), "--steps", "2", "--batch-size", "4"])
    tiny = ["--d-model", "32", "--layers", "1", "--heads", "2", "--batch-size", "4", "--aux-batch-size", "2",
            "--eval-samples", "4"]
    s2 = train_main([*common, "--stage", "2", "--out", str(tmp_path / "s2"), "--init", str(s0), "--steps", "2",
                     "--data-weights", "1", "3", *tiny])
    info = MMActPolicy.load(s2).bundle.info
    assert info["n_samples"] == 50 and info["train_config"]["aux_batch_size"] == 2
    assert "--data-weights 1 3" in info["command"]
    with pytest.raises(SystemExit, match="2 --data directories"):
        train_main([*common, "--stage", "2", "--out", str(tmp_path / "s2b"), "--init", str(s0), "--steps", "1",
                    "--data-weights", "1", *tiny])
    bad = json.loads((syn2 / "meta.json").read_text())
    bad["image_size_px"] = 64
    (syn2 / "meta.json").write_text(json.dumps(bad))
    with pytest.raises(DatasetError, match="image_size_px"):
        read_metas([syn, syn2])
    with pytest.raises(SystemExit, match="image_size_px"):
        train_main([*common, "--stage", "0", "--out", str(tmp_path / "s0b"), "--steps", "1"])


def test_data_weights_set_how_often_each_directory_is_drawn():
    from policy.training.data import sampling_probabilities

    source = np.array([0] * 30 + [1] * 10)
    assert sampling_probabilities(source, None, 2) is None
    p = sampling_probabilities(source, [1.0, 3.0], 2)
    assert p.sum() == pytest.approx(1.0)
    assert p[35] == pytest.approx(3 * p[0])  # a weight-3 sample is drawn three times as often
    assert p[source == 1].sum() == pytest.approx(0.5)  # 10 samples x 3 = 30 samples x 1
    draws = np.random.default_rng(0).choice(len(source), size=20000, p=p)
    assert np.mean(source[draws] == 1) == pytest.approx(0.5, abs=0.02)
    for bad, match in (([1.0], "1 weights for 2"), ([1.0, -1.0], ">= 0"), ([0.0, 0.0], "weight 0"),
                       ([1.0, float("nan")], "finite")):
        with pytest.raises(SystemExit, match=match):
            sampling_probabilities(source, bad, 2)


def test_eval_subset_represents_every_directory():
    """The held-out indices are sorted by directory: the evaluation subset must not be only the first one."""
    from policy.training.data import eval_subset

    _, val = split_indices(2000, 0.1, 1234)
    sub = eval_subset(val, 64, 1234)
    assert len(sub) == 64 and len(np.unique(sub)) == 64 and np.all(np.isin(sub, val))
    assert np.mean(sub >= 1000) == pytest.approx(0.5, abs=0.2)  # a second directory of the same size shows up
    assert np.array_equal(eval_subset(val, 64, 1234), sub)  # seeded
    assert np.array_equal(eval_subset(val[:10], 64, 1234), val[:10])
