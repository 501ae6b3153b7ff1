"""A chunk source over any object with LeRobot's policy interface, in the user's own process.

LeRobot itself is not a dependency (it needs Python >= 3.12 and torch < 2.12, ``../shared/FACTS.md``): the adapter
speaks the interface of ``lerobot.policies.pretrained.PreTrainedPolicy``, duck-typed:

- ``reset()``: called at the start of every episode (clears the policy's action queue);
- ``predict_action_chunk(batch) -> (B, H, D)`` tensor, with ``batch`` holding
  ``observation.images.<cam>`` (B, 3, H, W) float in [0, 1], ``observation.state`` (B, D) float, and
  ``task`` (list of str, the instruction).

Recent LeRobot versions normalize outside the policy (a pre- and a post-processor pipeline): pass them as
``preprocess(batch) -> batch`` and ``postprocess(actions) -> actions``. The actions are read in the declared
:class:`~mmact_ctrl.sources.action_space.ActionSpace` and turned into our task-space chunk.
"""

from __future__ import annotations

from typing import Callable, Mapping

import numpy as np

from mmact_ctrl.chunk import ActionChunk, Observation
from mmact_ctrl.sources.action_space import ActionAdapter, ActionSpace

#: the robot-state fields an ``observation.state`` vector may be built from, and their sizes
STATE_FIELDS: dict[str, int] = {"q_rad": 7, "dq_rad_s": 7, "ee_pos_m": 3, "ee_rotvec_rad": 3, "gripper_m": 1}


def state_vector(observation: Observation, fields: tuple[str, ...]) -> np.ndarray:
    """The concatenation of ``fields`` (names of :data:`STATE_FIELDS`) of ``observation``, float32."""
    parts = [np.atleast_1d(np.asarray(getattr(observation, f), dtype=np.float32)) for f in fields]
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.float32)


class LeRobotSource:
    """Any LeRobot-interface policy as a chunk source.

    Args:
        policy: the object with ``reset()`` and ``predict_action_chunk(batch)``.
        action_space: what its actions are (e.g. ``ActionSpace("joint_pos", gripper="open_1", dt_s=0.05)``).
        cameras: batch image key suffix -> scene camera (``{"front": "front"}`` gives
            ``observation.images.front`` from the scene's ``front`` camera); empty: no images.
        state_fields: the fields of ``observation.state``, in order (:data:`STATE_FIELDS`).
        preprocess, postprocess: the policy's own normalization pipelines, when it keeps them outside.
        device: the torch device the batch is put on.
        name: how reports name it (default: the policy's class).
        image_size_px: the side of the square frames it reads (None: the scene's default, 96 px); a policy trained
            on one of our LeRobot exports takes it, with the rest, from ``mmact_ctrl.datasets.conventions``.
    """

    declared_capabilities = frozenset()

    def __init__(self, policy, action_space: ActionSpace, cameras: Mapping[str, str] | None = None,
                 state_fields: tuple[str, ...] = ("q_rad", "gripper_m"),
                 preprocess: Callable[[dict], dict] | None = None, postprocess: Callable | None = None,
                 device: str = "cpu", name: str | None = None, image_size_px: int | None = None) -> None:
        if not callable(getattr(policy, "predict_action_chunk", None)):
            raise ValueError(f"{type(policy).__name__} has no predict_action_chunk(batch): not a LeRobot-interface policy")
        bad = [f for f in state_fields if f not in STATE_FIELDS]
        if bad:
            raise ValueError(f"unknown state field(s) {bad}; expected some of {tuple(STATE_FIELDS)}")
        self.policy = policy
        self.space = action_space
        self.adapter = ActionAdapter(action_space)
        self.cameras = dict(cameras or {})
        self.state_fields = tuple(state_fields)
        self.preprocess = preprocess
        self.postprocess = postprocess
        self.device = device
        self.name = name or type(policy).__name__
        self.needs_image = bool(self.cameras)
        if image_size_px is not None:  # the frames' size it was trained on (the scene renders them so)
            self.image_size_px = int(image_size_px)

    @property
    def camera_names(self) -> tuple[str, ...]:
        return tuple(self.cameras.values())

    @property
    def chunk_dt_s(self) -> float:
        return float(self.space.dt_s)

    @property
    def state_dim(self) -> int:
        return sum(STATE_FIELDS[f] for f in self.state_fields)

    def reset(self) -> None:
        fn = getattr(self.policy, "reset", None)
        if callable(fn):
            fn()

    def batch(self, observation: Observation) -> dict:
        """The LeRobot batch (batch size 1) of ``observation``."""
        import torch

        batch: dict = {}
        if self.cameras:
            if observation.image is None:
                raise ValueError(f"{self.name} needs camera frames but Observation.image is None")
            img = np.asarray(observation.image)
            if len(img) != len(self.cameras):
                raise ValueError(f"{self.name} reads cameras {list(self.cameras.values())} but the observation has "
                                 f"{len(img)} view(s)")
            for i, key in enumerate(self.cameras):
                chw = torch.from_numpy(np.ascontiguousarray(img[i].transpose(2, 0, 1))).to(torch.float32) / 255.0
                batch[f"observation.images.{key}"] = chw.unsqueeze(0).to(self.device)
        state = state_vector(observation, self.state_fields)
        batch["observation.state"] = torch.from_numpy(state).unsqueeze(0).to(self.device)
        batch["task"] = [observation.instruction]
        return batch

    def plan(self, observation: Observation) -> ActionChunk:
        import torch

        batch = self.batch(observation)
        if self.preprocess is not None:
            batch = self.preprocess(batch)
        with torch.inference_mode():
            actions = self.policy.predict_action_chunk(batch)
            if self.postprocess is not None:
                actions = self.postprocess(actions)
        a = actions.detach().to("cpu", torch.float64).numpy() if isinstance(actions, torch.Tensor) else np.asarray(actions)
        if a.ndim != 3 or a.shape[0] != 1:
            raise ValueError(f"{self.name}.predict_action_chunk returned shape {tuple(a.shape)}; expected (1, H, D)")
        return self.adapter.to_chunk(a[0], observation, info={"source": self.name})
