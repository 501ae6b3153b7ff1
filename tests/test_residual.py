"""The learned residual (``policy.residual``) and its training (``policy.residual_training``,
``scenarios.train_residual``), tiny sizes."""

import numpy as np
import pytest
import torch

from policy.residual import FEATURE_DIM, FEATURE_NAMES, ResidualConfig, ResidualPolicy, residual_features
from policy.residual_training import clip_norm, split_episodes, train
from scenarios.train_residual import TRAIN_SEED0, collect_samples, plan_episodes


def _synthetic(n_episodes=8, per=150, seed=0):
    """Feature rows whose label is a smooth function of them (meas - base plus a velocity lead), in episodes."""
    rng = np.random.default_rng(seed)
    n = n_episodes * per
    base = rng.uniform([0.35, -0.3, 0.15], [0.65, 0.3, 0.45], (n, 3))
    meas = base + rng.normal(0, 0.05, (n, 3))
    vel = rng.normal(0, 0.2, (n, 3))
    feats = residual_features(base, rng.uniform(0, 1.2, n), 1.6, meas, meas - 0.1 * vel, np.full(n, 0.1),
                              base + rng.normal(0, 0.005, (n, 3)), rng.normal(0, 0.1, (n, 3)))
    label = clip_norm(meas - base + 0.05 * vel, 0.15)
    return {"features": feats.astype(np.float32), "label": label.astype(np.float32), "base": base,
            "target": base + label, "target_lead": base + label, "episode": np.repeat(np.arange(n_episodes), per)}


def test_training_lowers_the_loss_on_synthetic_features():
    data = _synthetic()
    torch.manual_seed(0)
    policy, info = train(data, ResidualConfig(hidden=32, layers=2), epochs=6, batch_size=64, progress=False)
    hist = info["history"]
    assert hist[-1]["train_loss"] < 0.5 * hist[0]["train_loss"]
    assert hist[-1]["val_loss"] < hist[0]["val_loss"]
    assert info["n_episodes_val"] >= 1 and info["n_train"] + info["n_val"] == len(data["label"])
    v = info["val"]
    assert v["corrected_err_now_mm"] < v["base_err_now_mm"]


def test_collect_and_train_on_two_short_episodes():
    """Two 2 s open-loop expert rollouts: the samples are sane and a few epochs lower the loss."""
    specs = plan_episodes(2, kinds=("linear",), static_fraction=0.0, speeds=(0.3,), replan_hz=(2.0,))
    assert [s.seed for s in specs] == [TRAIN_SEED0, TRAIN_SEED0 + 1]
    data = collect_samples(specs, duration_s=2.0, workers=1, progress=False)
    n = len(data["label"])
    assert 250 < n <= 2 * 200  # 100 Hz while a chunk runs (the first from 0.2 s on)
    assert data["features"].shape == (n, FEATURE_DIM) and np.isfinite(data["features"]).all()
    assert np.all(np.linalg.norm(data["label"], axis=1) <= 0.15 + 1e-6)
    np.testing.assert_allclose(data["label"], clip_norm(data["target_lead"] - data["base"], 0.15), atol=1e-6)
    assert np.all(data["t"] >= 0.2 - 1e-6)
    policy, info = train(data, ResidualConfig(hidden=32, layers=2), epochs=8, batch_size=32, lr=3e-3, progress=False)
    assert info["history"][-1]["train_loss"] < info["history"][0]["train_loss"]


def test_plan_episodes_keeps_training_seeds_away_from_evaluation():
    specs = plan_episodes(20, static_fraction=0.1)
    assert min(s.seed for s in specs) >= TRAIN_SEED0
    assert sum(s.kind == "static" for s in specs) == 2
    assert {s.speed_m_s for s in specs} <= {0.1, 0.2, 0.3, 0.4} and {s.replan_hz for s in specs} <= {1.0, 2.0, 5.0}
    with pytest.raises(ValueError, match="seed0=5"):
        plan_episodes(2, seed0=5)
    tr, va = split_episodes(np.repeat(np.arange(10), 3), 0.2)
    assert len(va) == 6 and not set(np.repeat(np.arange(10), 3)[tr]) & set(np.repeat(np.arange(10), 3)[va])


def test_correction_is_bounded_finite_and_batched_equals_per_sample():
    policy = ResidualPolicy(ResidualConfig(max_correction_m=0.05), seed=3)
    net = policy.torch_module()
    with torch.no_grad():  # large weights so the raw output is far beyond the bound
        for p in net.parameters():
            p.mul_(20.0)
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.normal(0, 3, (200, FEATURE_DIM)), np.full((1, FEATURE_DIM), 1e6),
                        np.full((1, FEATURE_DIM), -1e6), rng.choice([1e6, -1e6], (20, FEATURE_DIM)),
                        np.full((1, FEATURE_DIM), np.inf), np.full((1, FEATURE_DIM), np.nan), np.zeros((1, FEATURE_DIM))])
    out = policy.correction_m(x)
    assert out.shape == (len(x), 3) and np.isfinite(out).all()
    assert np.all(np.linalg.norm(out, axis=1) <= 0.05)
    assert np.linalg.norm(out, axis=1).max() > 0.04  # the bound is reached, not a vanishing output
    single = np.stack([policy.correction_m(row) for row in x])
    np.testing.assert_allclose(single, out, rtol=1e-12, atol=1e-15)
    with torch.no_grad():
        t_out = net(torch.as_tensor(x, dtype=torch.float32)).numpy()
    np.testing.assert_allclose(t_out, out, atol=1e-6)  # the torch module is the same function
    with pytest.raises(ValueError, match="features must have shape"):
        policy.correction_m(np.zeros(FEATURE_DIM + 1))


def test_features_are_translation_invariant_but_the_absolute_columns():
    rng = np.random.default_rng(1)
    args = [rng.normal(size=3), 0.3, 1.6, rng.normal(size=3), rng.normal(size=3), 0.1, rng.normal(size=3),
            rng.normal(size=3)]
    f = residual_features(*args)
    shift = np.array([0.1, -0.2, 0.05])
    moved = list(args)
    for i in (0, 3, 4, 6):
        moved[i] = args[i] + shift
    g = residual_features(*moved)
    assert f.shape == (FEATURE_DIM,) == (len(FEATURE_NAMES),)
    absolute = [i for i, name in enumerate(FEATURE_NAMES) if name.startswith("meas_abs")]
    relative = [i for i in range(FEATURE_DIM) if i not in absolute]
    np.testing.assert_allclose(f[relative], g[relative], atol=1e-12)
    # batched over leading dims, a zero time gap gives a zero velocity estimate
    batch = residual_features(np.zeros((4, 2, 3)), np.zeros((4, 2)), 1.6, np.ones((4, 2, 3)), np.zeros((4, 2, 3)),
                              np.zeros((4, 2)), np.zeros((4, 2, 3)), np.zeros((4, 2, 3)))
    assert batch.shape == (4, 2, FEATURE_DIM) and np.all(batch[..., 6:9] == 0)


def test_the_executors_one_sample_features_equal_the_batched_ones_bit_for_bit():
    """The residual executor's 100 Hz call (one sample, scalar times) gives the training features (batched) exactly."""
    rng = np.random.default_rng(2)
    rows = [[rng.normal(size=3), rng.uniform(0, 2), rng.choice([0.0, 1.6, rng.uniform(0, 2)]),
             rng.normal(size=3), rng.normal(size=3), rng.choice([0.0, 5e-4, 1e-3, rng.uniform(0, 0.2)]),
             rng.normal(size=3), rng.normal(size=3)] for _ in range(300)]
    batched = residual_features(*[np.stack([np.asarray(r[i], dtype=float) for r in rows]) for i in range(8)])
    for i, args in enumerate(rows):
        assert np.array_equal(residual_features(*args), batched[i])
    with pytest.raises(ValueError, match="tcp_pos_m must have shape"):
        residual_features(np.zeros(3), 0.1, 1.6, np.zeros(3), np.zeros(3), 0.1, np.zeros(2), np.zeros(3))


def test_save_load_round_trip_and_missing_path(tmp_path):
    policy = ResidualPolicy(ResidualConfig(hidden=16, layers=2, max_correction_m=0.1, history_s=0.05), seed=7)
    path = tmp_path / "r.pt"
    policy.save(path, {"steps": 3, "val": {"err_mm": np.float64(1.5)}})
    loaded = ResidualPolicy.load(path)
    assert loaded.config == policy.config and loaded.meta["steps"] == 3 and loaded.meta["val"]["err_mm"] == 1.5
    x = np.random.default_rng(2).normal(0, 2, (50, FEATURE_DIM))
    np.testing.assert_array_equal(loaded.correction_m(x), policy.correction_m(x))
    missing = tmp_path / "nope" / "residual.pt"
    with pytest.raises(FileNotFoundError, match=str(missing)):
        ResidualPolicy.load(missing)
    (tmp_path / "bad.pt").write_bytes(b"garbage")
    with pytest.raises(ValueError, match="bad.pt"):
        ResidualPolicy.load(tmp_path / "bad.pt")


@pytest.mark.parametrize("kwargs, match", [
    ({"hidden": 0}, "hidden"), ({"layers": -1}, "layers"), ({"hidden": 2.5}, "hidden"),
    ({"max_correction_m": 0.0}, "max_correction_m"), ({"max_correction_m": float("nan")}, "max_correction_m"),
    ({"max_correction_m": float("inf")}, "max_correction_m"), ({"history_s": -0.1}, "history_s"),
    ({"layers": True}, "layers"),
])
def test_bad_config_values_raise_one_line_value_errors(kwargs, match):
    with pytest.raises(ValueError, match=match) as info:
        ResidualConfig(**kwargs)
    assert "\n" not in str(info.value) and repr(next(iter(kwargs.values()))) in str(info.value)
