"""Demonstration collection in the MuJoCo scene, plain and DAgger-style (a policy drives, the expert labels)."""

from __future__ import annotations

import numpy as np
import pytest

from policy.dataset import PolicyDataset
from policy.inference import DEFAULT_CHECKPOINT
from scenarios.collect import CollectConfig, collect


def test_collect_writes_expert_labels_also_when_the_policy_drives(tmp_path):
    cfg = CollectConfig(episodes=2, duration_s=1.0, plane_z_m=0.1, seed=11, driver_checkpoint=str(DEFAULT_CHECKPOINT),
                        driver_prob=1.0)
    n = collect(cfg, tmp_path, progress=False)
    ds = PolicyDataset.load(tmp_path)
    assert n == len(ds) == 4  # samples at 0 and 0.5 s of each 1 s episode
    d = ds.data
    assert d["images"].shape == (4, 1, 96, 96, 3) and d["actions"].shape == (4, 16, 7)
    # every label is the expert's chunk for the recorded frame: it ends on the instructed ball
    np.testing.assert_allclose(d["actions"][:, -1, :3], d["target_pos_m"], atol=1e-3)
    assert np.all(np.abs(d["target_pos_m"][:, 2] - 0.11) <= 0.011)  # the planar scenes
    assert not np.array_equal(d["images"], d["future_images"])  # the arm moved in between


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"driver_prob": 0.5}, "needs a driver_checkpoint"),
        ({"driver_prob": 1.5, "driver_checkpoint": "x.pt"}, "driver_prob must be in"),
        ({"driver_prob": 0.5, "driver_checkpoint": "/nonexistent.pt"}, "does not exist"),
        ({"sample_every_s": 2.0}, "sample_every_s"),
        ({"motion": "teleport"}, "motion must be one of"),
        ({"expert_lead": "velocity"}, "needs frame_gap_s > 0"),
        ({"frame_gap_s": 0.6}, "frame_gap_s must be in"),
        ({"holdout_box_m": (0.6, 0.5, 0.0, 0.3)}, "holdout_box_m must be"),
    ],
)
def test_collect_config_names_bad_values(kwargs, message):
    with pytest.raises(ValueError, match=message):
        CollectConfig(**kwargs)
