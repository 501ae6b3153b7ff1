"""A dataset's frames and strings as token arrays, and the checks that a dataset fits a checkpoint.

Shared by the training stages 1/2 and ``policy.token_cache`` (which stores these arrays in one file); this module
imports neither of them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from policy.bundle import PolicyBundle
from policy.checkpoint import CheckpointError
from policy.dataset import DatasetError, dataset_shards, read_metas, read_shard


def load_tokenized(bundle: PolicyBundle, data_path: str | list[str], progress: bool = True) -> dict[str, np.ndarray]:
    """Read every shard (of one or several dataset directories) and keep only tokens: codes of images /
    future images, text ids, state and action tokens; ``source`` is each sample's directory index."""
    from tqdm import tqdm

    read_metas(data_path)  # the directories must agree on the token layout
    cfg = bundle.model_cfg
    parts: dict[str, list[np.ndarray]] = {k: [] for k in ("img", "fut", "instr", "quest", "answer", "answer_str", "state",
                                                           "action", "actions_f", "target_pos_m", "source", "ball",
                                                           "target_prev_pos_m")}
    for k, shard, meta in tqdm(dataset_shards(data_path), desc="tokenizing shards", disable=not progress):
        views, future = check_views(bundle, meta, shard)
        d = read_shard(shard, meta)
        images = d["images"][:, views]
        parts["source"].append(np.full(len(d["q_rad"]), k, dtype=np.int16))
        parts["img"].append(bundle.image_codes(images).astype(np.int16))
        parts["fut"].append(bundle.image_codes(d["future_images"][:, future]).astype(np.int16))
        parts["ball"].append(bundle.ball_tokens(images).astype(np.int16))
        prev = d.get("target_prev_pos_m")
        parts["target_prev_pos_m"].append(np.full((len(d["q_rad"]), 3), np.nan, np.float32) if prev is None
                                          else prev.astype(np.float32))
        parts["instr"].append(bundle.text_batch(d["instructions"], cfg.max_text_len))
        parts["quest"].append(bundle.text_batch(d["questions"], cfg.max_text_len))
        parts["answer"].append(bundle.text_batch(d["answers"], cfg.max_answer_len, end_with_eot=True))
        parts["answer_str"].append(d["answers"])
        parts["state"].append(bundle.state_tokens(d["q_rad"]))
        parts["action"].append(bundle.action_tokens(d["actions"]))
        parts["actions_f"].append(d["actions"].astype(np.float32))
        parts["target_pos_m"].append(d["target_pos_m"].astype(np.float32))
    return {k: np.concatenate(v) for k, v in parts.items()}


def check_views(bundle: PolicyBundle, meta: dict[str, Any], where) -> tuple[list[int], list[int]]:
    """The data's frame offsets must be the bundle's and its cameras must include the bundle's (a dataset rendered
    with more cameras serves a policy of some of them). Returns the indices of the bundle's views among the data's
    ``images`` (frame-major) and among its ``future_images``."""
    offsets = [float(x) for x in meta.get("frame_offsets_s", [0.0])]
    cams = list(meta["camera_names"])
    if (not set(bundle.camera_names) <= set(cams) or len(offsets) != len(bundle.frame_offsets_s)
            or not np.allclose(offsets, bundle.frame_offsets_s)):
        raise DatasetError(f"{where}: cameras {meta['camera_names']} / frame offsets {offsets} differ from the "
                           f"checkpoint's {bundle.camera_names} / {bundle.frame_offsets_s}")
    future = [cams.index(c) for c in bundle.camera_names]
    return [f * len(cams) + c for f in range(len(offsets)) for c in future], future


def check_data_matches(bundle: PolicyBundle, meta: dict[str, Any], src, cameras: list[str] | None = None) -> None:
    """The dataset's ``meta`` must fit the checkpoint ``src``: its action tokenizer, the cameras (among the data's),
    the number of views (<= the model's ``max_views``) and the chunk horizon. Raises ``CheckpointError``."""
    b = meta["action_bounds"]
    at = bundle.action_tokenizer
    if at.bins != int(meta["action_bins"]) or not np.allclose(at.bounds.low, b["low"]) or not np.allclose(at.bounds.high, b["high"]):
        raise CheckpointError(f"{src}: its action tokenizer (bins {at.bins}, bounds {at.bounds}) does not match the "
                              f"dataset's meta.json (bins {meta['action_bins']}, bounds {b})")
    unknown = [c for c in cameras or [] if c not in meta["camera_names"]]
    if unknown:
        raise CheckpointError(f"{src}: cameras {unknown} are not among the data's {meta['camera_names']}")
    n_views = len(cameras or meta["camera_names"]) * len(meta.get("frame_offsets_s", [0.0]))
    if bundle.model_cfg and n_views > bundle.model_cfg.max_views:
        raise CheckpointError(f"{src}: dataset has {n_views} views (cameras x frames) > max_views {bundle.model_cfg.max_views}")
    if bundle.model_cfg and int(meta["chunk_horizon"]) != bundle.model_cfg.horizon:
        raise CheckpointError(f"{src}: model horizon {bundle.model_cfg.horizon} != dataset chunk_horizon {meta['chunk_horizon']}")
