"""The one shared vocabulary of the unified-token policy.

Layout, in order (DESIGN.md)::

    [special | task tokens + segment markers | text | image codebook | action bins]

Every modality owns one contiguous id range, so decoding can restrict logits to
the range of the modality it is filling in.
"""

from __future__ import annotations

from dataclasses import dataclass

SPECIAL_TOKENS: tuple[str, ...] = ("<|pad|>", "<|mask|>")
TASK_TOKENS: tuple[str, ...] = ("<|mm2a|>", "<|t2i|>", "<|mmu|>")
SEGMENT_TOKENS: tuple[str, ...] = (
    "<|soi|>",  # start of image
    "<|eoi|>",  # end of image
    "<|sot|>",  # start of text
    "<|eot|>",  # end of text
    "<|sos|>",  # start of robot state
    "<|eos|>",  # end of robot state
    "<|soa|>",  # start of action chunk
    "<|eoa|>",  # end of action chunk
)
NAMED_TOKENS: tuple[str, ...] = SPECIAL_TOKENS + TASK_TOKENS + SEGMENT_TOKENS


@dataclass(frozen=True)
class VocabLayout:
    """Sizes of each modality; offsets follow from them.

    Attributes:
        text_size: number of text token ids (the text tokenizer's vocabulary).
        image_codebook_size: number of image codes of the image quantizer.
        action_bins: number of uniform bins per action dimension (0 = no action range).
    """

    text_size: int = 512
    image_codebook_size: int = 512
    action_bins: int = 2048

    def __post_init__(self) -> None:
        for name in ("text_size", "image_codebook_size", "action_bins"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 0:
                raise ValueError(f"VocabLayout.{name} must be a non-negative int, got {value!r}")

    # ---- named tokens -------------------------------------------------
    def token_id(self, name: str) -> int:
        """Id of a named special / task / segment token such as ``"<|mm2a|>"``."""
        try:
            return NAMED_TOKENS.index(name)
        except ValueError:
            raise KeyError(f"unknown named token {name!r}; known: {', '.join(NAMED_TOKENS)}") from None

    @property
    def pad_id(self) -> int:
        return self.token_id("<|pad|>")

    @property
    def mask_id(self) -> int:
        return self.token_id("<|mask|>")

    # ---- modality ranges [start, stop) --------------------------------
    @property
    def text_offset(self) -> int:
        return len(NAMED_TOKENS)

    @property
    def image_offset(self) -> int:
        return self.text_offset + self.text_size

    @property
    def action_offset(self) -> int:
        return self.image_offset + self.image_codebook_size

    @property
    def size(self) -> int:
        """Total vocabulary size (one embedding table, one output head)."""
        return self.action_offset + self.action_bins

    def range_of(self, modality: str) -> tuple[int, int]:
        """``[start, stop)`` id range of ``"text"``, ``"image"`` or ``"action"``."""
        ranges = {
            "text": (self.text_offset, self.image_offset),
            "image": (self.image_offset, self.action_offset),
            "action": (self.action_offset, self.size),
        }
        if modality not in ranges:
            raise KeyError(f"unknown modality {modality!r}; expected one of {sorted(ranges)}")
        return ranges[modality]
