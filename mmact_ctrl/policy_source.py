"""The learned unified-token policy behind the ``ChunkSource`` contract."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mmact_ctrl.chunk import ActionChunk, Observation


class PolicyChunkSource:
    """``ChunkSource`` over ``policy.inference.MMActPolicy``: one ``<|mm2a|>`` call per chunk.

    Args:
        checkpoint: path of the trained checkpoint (``policy.inference.DEFAULT_CHECKPOINT`` if None).
        action_steps: 1 = the whole chunk in one forward pass; k > 1 = k-step confidence re-masking.
        refine_bins: 0 = bin centres of the greedy tokens; W > 0 = probability-weighted mean bin within
            +-W bins of each greedy token; None = the checkpoint's matched window
            (``MMActPolicy.default_refine_bins``, 64 for the shipped one).
        torch_threads: intra-op threads for torch (process-wide; measured here: 1 thread 25 ms, 2 threads
            on the busy 2-core machine 79 ms per call); None leaves torch's setting alone.
    """

    needs_image = True
    #: ``plan`` reads only its observation (the network in eval mode, no sampling): simulated time runs it ahead
    #: in a worker while the arm is simulated (``mmact_ctrl.lookahead``)
    answers_concurrently = True

    def __init__(self, checkpoint: str | Path | None = None, action_steps: int = 1, device: str = "cpu",
                 refine_bins: int | None = None, torch_threads: int | None = 1) -> None:
        import torch

        from policy.inference import DEFAULT_CHECKPOINT, MMActPolicy

        if torch_threads:  # a small model on a 2-core machine: one thread is fastest and leaves a core to physics
            torch.set_num_threads(int(torch_threads))

        path = Path(checkpoint) if checkpoint is not None else DEFAULT_CHECKPOINT
        if not path.is_file():
            raise ValueError(f"policy checkpoint {str(path)!r} does not exist (train one with python -m policy.train)")
        if action_steps < 1:
            raise ValueError(f"action_steps must be >= 1, got {action_steps}")
        if refine_bins is not None and refine_bins < 0:
            raise ValueError(f"refine_bins must be >= 0, got {refine_bins}")
        self.policy = MMActPolicy.load(path, device=device)
        self.refine_bins = self.policy.default_refine_bins if refine_bins is None else int(refine_bins)
        self.action_steps = int(action_steps)
        self.checkpoint = path
        offsets = list(self.policy.bundle.frame_offsets_s)
        if len(offsets) > 2:
            raise ValueError(f"policy checkpoint {str(path)!r} takes {len(offsets)} frames {offsets}; the loop provides "
                             "the current frame and one earlier frame")

    @property
    def camera_names(self) -> tuple[str, ...]:
        """The cameras the checkpoint was trained on (the world must render these, in this order)."""
        return tuple(self.policy.bundle.camera_names)

    @property
    def prev_frame_gap_s(self) -> float:
        """How long before each query the earlier frame is taken (0: the checkpoint sees one frame)."""
        offsets = self.policy.bundle.frame_offsets_s
        return float(-offsets[1]) if len(offsets) > 1 else 0.0

    def views(self, observation: Observation) -> np.ndarray:
        """The frames of one query in the checkpoint's order: the current frame of each camera, then (two-frame
        checkpoints) the earlier one; without an earlier frame (the first query) the current one stands in."""
        if observation.image is None:
            raise ValueError("the policy needs the camera frame: Observation.image is None")
        img = np.asarray(observation.image)
        if len(img) != len(self.camera_names):
            raise ValueError(f"the policy was trained on cameras {list(self.camera_names)} but the observation has "
                             f"{len(img)} view(s)")
        if self.prev_frame_gap_s <= 0:
            return img
        prev = img if observation.prev_image is None else np.asarray(observation.prev_image)
        return np.concatenate([img, prev])

    @property
    def chunk_dt_s(self) -> float:
        return float(self.policy.chunk_dt_s)

    @property
    def action_token_range(self) -> tuple[int, int]:
        """Half-open range of the action tokens in the shared vocabulary."""
        tok = self.policy.action_tokenizer
        return int(tok.token_offset), int(tok.token_offset) + int(tok.bins)

    def _chunk(self, tokens: np.ndarray, actions: np.ndarray, observation: Observation) -> ActionChunk:
        return ActionChunk(waypoints=actions, dt_s=self.chunk_dt_s, t0_s=observation.t0_s, tokens=tokens)

    def plan(self, observation: Observation) -> ActionChunk:
        tokens, actions = self.policy.predict_chunk(self.views(observation), observation.instruction, observation.q_rad,
                                                    action_steps=self.action_steps, refine_bins=self.refine_bins)
        return self._chunk(tokens, actions, observation)

    def plan_inpaint(self, observation: Observation, known: np.ndarray) -> ActionChunk:
        """Real-time chunking: the waypoints that run during inference enter as known (unmasked) action
        tokens, the model fills in the rest in the same forward pass."""
        known = np.asarray(known, dtype=np.float64).reshape(-1, 7)
        n = min(len(known), self.policy.horizon)
        if n == 0:
            return self.plan(observation)
        known_tokens = np.full((self.policy.horizon, 7), -1, dtype=np.int64)
        known_tokens[:n] = self.policy.action_tokenizer.encode(known[:n])[0]
        tokens, actions = self.policy.predict_chunk(self.views(observation), observation.instruction, observation.q_rad,
                                                    action_steps=self.action_steps, known_actions=known_tokens,
                                                    refine_bins=self.refine_bins)
        return self._chunk(tokens, actions, observation)
