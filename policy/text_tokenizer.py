"""Byte-level BPE text tokenizer (HuggingFace ``tokenizers``), saved inside the checkpoint as a JSON string.

Byte-level means every string round-trips exactly (all 256 bytes are in the base alphabet).
Ids are ``[0, vocab_size)``; the shared vocabulary places them at ``VocabLayout.text_offset``.
``<|endoftext|>`` is a text-range id: it ends mmu answers, so answer decoding never needs a
token outside the text range.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from tokenizers import Tokenizer, decoders, models, pre_tokenizers, trainers

END_OF_TEXT = "<|endoftext|>"


class TextTokenizer:
    """Wraps a byte-level BPE ``tokenizers.Tokenizer``; ``vocab_size`` <= the layout's ``text_size``."""

    def __init__(self, tokenizer: Tokenizer) -> None:
        self._tok = tokenizer
        eot = tokenizer.token_to_id(END_OF_TEXT)
        if eot is None:
            raise ValueError(f"text tokenizer has no {END_OF_TEXT} token")
        self.eot_id = int(eot)

    # ---- construction / persistence -----------------------------------
    @classmethod
    def train(cls, corpus: Iterable[str], vocab_size: int = 512, min_frequency: int = 2) -> "TextTokenizer":
        """Train byte-level BPE on ``corpus`` (instructions, questions, answers)."""
        if vocab_size < 257 + 1:
            raise ValueError(f"byte-level BPE needs vocab_size >= 258 (256 bytes + {END_OF_TEXT} + merges), got {vocab_size}")
        tok = Tokenizer(models.BPE())
        tok.pre_tokenizer = pre_tokenizers.ByteLevel(add_prefix_space=False)
        tok.decoder = decoders.ByteLevel()
        trainer = trainers.BpeTrainer(
            vocab_size=vocab_size,
            min_frequency=min_frequency,
            special_tokens=[END_OF_TEXT],
            initial_alphabet=pre_tokenizers.ByteLevel.alphabet(),
            show_progress=False,
        )
        tok.train_from_iterator(list(corpus), trainer=trainer)
        return cls(tok)

    def to_json(self) -> str:
        return self._tok.to_str()

    @classmethod
    def from_json(cls, text: str) -> "TextTokenizer":
        return cls(Tokenizer.from_str(text))

    @property
    def vocab_size(self) -> int:
        return int(self._tok.get_vocab_size())

    # ---- encode / decode ----------------------------------------------
    def encode(self, text: str) -> list[int]:
        """String -> ids in ``[0, vocab_size)`` (no special tokens added)."""
        return list(self._tok.encode(text, add_special_tokens=False).ids)

    def decode(self, ids: Iterable[int]) -> str:
        """Ids -> string; stops at the first ``<|endoftext|>``."""
        out: list[int] = []
        for i in ids:
            i = int(i)
            if i == self.eot_id:
                break
            if not 0 <= i < self.vocab_size:
                raise ValueError(f"text id {i} outside [0, {self.vocab_size})")
            out.append(i)
        return self._tok.decode(out, skip_special_tokens=False)

    def encode_fixed(self, text: str, length: int, end_with_eot: bool = False) -> tuple[np.ndarray, bool]:
        """Ids padded with -1 or truncated to ``length``: (ids int64 (length,), truncated).

        With ``end_with_eot`` the text is followed by ``<|endoftext|>`` and padded with it instead
        of -1 (mmu answer targets: every position stays in the text range).
        """
        ids = self.encode(text)
        pad = -1
        if end_with_eot:
            ids = ids + [self.eot_id]
            pad = self.eot_id
        truncated = len(ids) > length
        ids = ids[:length]
        arr = np.full(length, pad, dtype=np.int64)
        arr[: len(ids)] = ids
        return arr, truncated
