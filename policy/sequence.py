"""Fixed token layouts of the three tasks, with the position ids the model embeds.

Every sequence is ``[task token | segments... | target segment]``, each segment framed by its
markers (``<|sot|> ... <|eot|>``, ``<|soi|> ... <|eoi|>``, ``<|sos|> ... <|eos|>``,
``<|soa|> ... <|eoa|>``)::

    mm2a: <|mm2a|> [text] [image]*V ([balls]) [state] ([AUX]) [ACTION CHUNK H*7]
    t2i:  <|t2i|>  [text] [image]*V [FUTURE IMAGE]*V
    mmu:  <|mmu|>  [image]*V [question text] [ANSWER TEXT]

Lengths are fixed per (task, V) (text is padded with ``<|pad|>``), so a batch is one array and a
layout's position ids are shared by the whole batch. Position ids are per segment type:
``a`` is the index within a text segment, the row of an image code, the dimension of a state
token, the step of an action token; ``b`` is the column of an image code or the dimension of an
action token; ``view`` is 1 + the camera index for image tokens (0 otherwise). The model adds a
learned embedding per ``(type, a)``, per ``(type, b)`` and per ``view``: 2D positions for images.

Two optional mm2a segments (issue 25; a model without them has exactly the layouts before it), both numeric tokens
of the state bins, so they share the state's segment type and markers (``<|sos|> ... <|eos|>``) and are told apart
by ``a``:

- ``balls`` (``ModelConfig.ball_views > 0``), an input: per view (the ``view`` id, as the images have) and per ball
  colour the ball's image position ``u, v`` (``policy.ball_detector``), ``a = BALL_A + 2 * colour + coordinate``;
  ``<|pad|>`` where the ball is not seen.
- ``aux`` (``ModelConfig.aux_positions > 0``), a second target: the instructed ball's 3-D position (x, y, z in the
  action bins) at t, then at the earlier frame, ``a = AUX_A + coordinate``, ``b = 1 + position``. It is masked in
  every query and predicted in the same pass as the chunk (``SeqLayout.aux_idx``), so the chunk's hidden states
  must carry where the ball is.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from policy.config import ModelConfig
from policy.vocab import VocabLayout

TASKS = ("mm2a", "t2i", "mmu")
TARGET_MODALITY = {"mm2a": "action", "t2i": "image", "mmu": "text"}
# segment types
T_TASK, T_MARK, T_TEXT, T_IMAGE, T_STATE, T_ACTION, T_ANSWER, T_FUTURE = range(8)
N_TYPES = 8
MAX_POS = 64  # per-type index range of a and b
AUX_A = 8  # a of the aux target's x (state dims are a = 0..6)
BALL_A = 16  # a of the first ball token of a view


@dataclass
class SeqLayout:
    """One task's token layout for ``n_views`` views."""

    task: str
    n_views: int
    template: np.ndarray  # (L,) int64: markers filled, content slots = pad
    pos_a: np.ndarray  # (L,) int64, already offset by type * MAX_POS
    pos_b: np.ndarray  # (L,)
    view: np.ndarray  # (L,)
    slots: dict[str, slice]
    _torch: dict = field(default_factory=dict, repr=False)

    @property
    def length(self) -> int:
        return len(self.template)

    @property
    def target(self) -> slice:
        return self.slots["target"]

    @property
    def target_idx(self) -> np.ndarray:
        """Absolute positions of the predicted tokens (t2i skips the markers between future views)."""
        if "target_idx" not in self._torch:
            if self.task == "t2i":
                idx = [np.arange(self.slots[f"future{i}"].start, self.slots[f"future{i}"].stop) for i in range(self.n_views)]
                self._torch["target_idx"] = np.concatenate(idx)
            else:
                self._torch["target_idx"] = np.arange(self.target.start, self.target.stop)
        return self._torch["target_idx"]

    @property
    def aux_idx(self) -> np.ndarray:
        """Absolute positions of the auxiliary target (the ball's 3-D positions; empty without one)."""
        aux = self.slots.get("aux")
        return np.arange(aux.start, aux.stop) if aux is not None else np.zeros(0, dtype=np.int64)

    @property
    def target_modality(self) -> str:
        return TARGET_MODALITY[self.task]

    def position_tensors(self, device: torch.device | str) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        key = str(device)
        if key not in self._torch:
            self._torch[key] = tuple(torch.as_tensor(x, device=device) for x in (self.pos_a, self.pos_b, self.view))
        return self._torch[key]


class LayoutBuilder:
    """Builds (and caches) the layouts of a model config."""

    def __init__(self, vocab: VocabLayout, cfg: ModelConfig) -> None:
        self.vocab, self.cfg = vocab, cfg
        self._cache: dict[tuple[str, int], SeqLayout] = {}

    def get(self, task: str, n_views: int) -> SeqLayout:
        if task not in TASKS:
            raise KeyError(f"unknown task {task!r}; expected one of {TASKS}")
        if not 1 <= n_views <= self.cfg.max_views:
            raise ValueError(f"n_views must be in [1, {self.cfg.max_views}], got {n_views}")
        key = (task, n_views)
        if key not in self._cache:
            self._cache[key] = self._build(task, n_views)
        return self._cache[key]

    def _build(self, task: str, n_views: int) -> SeqLayout:
        v, c = self.vocab, self.cfg
        tok: list[int] = []
        pa: list[int] = []
        pb: list[int] = []
        vw: list[int] = []
        slots: dict[str, slice] = {}

        def put(ids, typ, a, b=0, view=0):
            tok.append(ids)
            pa.append(typ * MAX_POS + a)
            pb.append(typ * MAX_POS + b)
            vw.append(view)

        def mark(name):
            put(v.token_id(name), T_MARK, 0)

        def segment(name, start, stop, typ, n, grid=None, view=0, cols=None):
            mark(start)
            s = len(tok)
            for i in range(n):
                if grid is not None:
                    put(v.pad_id, typ, i // grid, i % grid, view)
                elif cols is not None:
                    put(v.pad_id, typ, i // cols, i % cols)
                else:
                    put(v.pad_id, typ, i)
            slots[name] = slice(s, len(tok))
            mark(stop)

        put(v.token_id(f"<|{task}|>"), T_TASK, 0)
        g2 = c.grid * c.grid
        if task in ("mm2a", "t2i"):
            segment("text", "<|sot|>", "<|eot|>", T_TEXT, c.max_text_len)
        for i in range(n_views):
            segment(f"image{i}", "<|soi|>", "<|eoi|>", T_IMAGE, g2, grid=c.grid, view=i + 1)
        if task == "mm2a":
            if c.ball_views:
                mark("<|sos|>")
                s = len(tok)
                for view in range(c.ball_views):
                    for k in range(2 * c.ball_colors):
                        put(v.pad_id, T_STATE, BALL_A + k, 0, view + 1)
                slots["balls"] = slice(s, len(tok))
                mark("<|eos|>")
            segment("state", "<|sos|>", "<|eos|>", T_STATE, c.state_dim)
            if c.aux_positions:
                mark("<|sos|>")
                s = len(tok)
                for pos in range(c.aux_positions):
                    for k in range(3):
                        put(v.pad_id, T_STATE, AUX_A + k, 1 + pos)
                slots["aux"] = slice(s, len(tok))
                mark("<|eos|>")
            segment("target", "<|soa|>", "<|eoa|>", T_ACTION, c.horizon * c.action_dim, cols=c.action_dim)
        elif task == "t2i":
            start = len(tok)
            for i in range(n_views):
                segment(f"future{i}", "<|soi|>", "<|eoi|>", T_FUTURE, g2, grid=c.grid, view=i + 1)
            # the target spans all future views (with their markers inside, which stay fixed)
            slots["target"] = slice(start + 1, len(tok) - 1)
        else:
            segment("text", "<|sot|>", "<|eot|>", T_TEXT, c.max_text_len)
            segment("target", "<|sot|>", "<|eot|>", T_ANSWER, c.max_answer_len)
        arr = lambda x: np.asarray(x, dtype=np.int64)  # noqa: E731
        return SeqLayout(task, n_views, arr(tok), arr(pa), arr(pb), arr(vw), slots)

    # ---- filling a batch ---------------------------------------------
    def fill(
        self,
        task: str,
        text_ids: np.ndarray | None,
        image_codes: np.ndarray,
        state_tokens: np.ndarray | None = None,
        target_tokens: np.ndarray | None = None,
        ball_tokens: np.ndarray | None = None,
        aux_tokens: np.ndarray | None = None,
    ) -> tuple[np.ndarray, SeqLayout]:
        """Batch ``(B, L)`` of shared-vocabulary ids.

        Args:
            text_ids: ``(B, max_text_len)`` raw text ids, -1 = pad (instruction or question).
            image_codes: ``(B, V, grid, grid)`` raw codes in ``[0, codebook_size)``.
            state_tokens: ``(B, 7)`` shared-vocabulary ids (mm2a).
            target_tokens: shared-vocabulary ids of the target, flat ``(B, T)`` (or shaped);
                ``None`` fills the target with ``<|mask|>``. For t2i the target is the future
                codes of all views in order (markers between views are kept from the template).
            ball_tokens: ``(B, ball_views * ball_colors * 2)`` shared-vocabulary ids (mm2a with ball tokens).
            aux_tokens: ``(B, aux_positions * 3)`` ids of the auxiliary target; ``None`` masks it (every query).
        """
        v = self.vocab
        image_codes = np.asarray(image_codes)
        b, n_views = image_codes.shape[:2]
        lay = self.get(task, n_views)
        out = np.repeat(lay.template[None], b, axis=0)
        if text_ids is not None:
            t = np.asarray(text_ids, dtype=np.int64)
            out[:, lay.slots["text"]] = np.where(t >= 0, t + v.text_offset, v.pad_id)
        for i in range(n_views):
            out[:, lay.slots[f"image{i}"]] = image_codes[:, i].reshape(b, -1) + v.image_offset
        if task == "mm2a":
            if state_tokens is None:
                raise ValueError("mm2a needs state tokens")
            out[:, lay.slots["state"]] = np.asarray(state_tokens).reshape(b, -1)
            if "balls" in lay.slots:
                if ball_tokens is None:
                    raise ValueError("this model's mm2a query needs ball tokens (policy.ball_detector)")
                out[:, lay.slots["balls"]] = np.asarray(ball_tokens).reshape(b, -1)
            if "aux" in lay.slots:
                out[:, lay.slots["aux"]] = v.mask_id if aux_tokens is None else np.asarray(aux_tokens).reshape(b, -1)
        out[:, lay.target_idx] = v.mask_id if target_tokens is None else np.asarray(target_tokens).reshape(b, -1)
        return out, lay
