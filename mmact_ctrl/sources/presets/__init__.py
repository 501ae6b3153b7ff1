"""Conventions as named presets: what a policy reads and answers, in one switch (``--preset``).

- :mod:`.convention`: :class:`Convention` (observation keys, action space, chunk length) and its JSON form;
- :mod:`.libero`, :mod:`.droid`, :mod:`.mmact`: the built-in presets, one file each, their sources cited;
- :mod:`.resolve`: how the client settles a convention from the user's switches and the server's metadata.
"""

from __future__ import annotations

from pathlib import Path

from mmact_ctrl.sources.presets.convention import Convention, convention_from_dict, read_convention_file
from mmact_ctrl.sources.presets.droid import DROID
from mmact_ctrl.sources.presets.libero import LIBERO
from mmact_ctrl.sources.presets.mmact import MMACT

#: the built-in presets by name
PRESETS: dict[str, Convention] = {"libero": LIBERO, "droid": DROID, "mmact": MMACT}


def load_preset(spec: "str | Path | Convention") -> Convention:
    """A built-in preset by name, a user preset by JSON file path, or ``spec`` itself (raises ``ValueError`` naming
    the bad name, file or field)."""
    if isinstance(spec, Convention):
        return spec
    text = str(spec)
    if text in PRESETS:
        return PRESETS[text]
    if not Path(text).is_file():
        raise ValueError(f"unknown preset {text!r}: give one of {', '.join(PRESETS)} or the path of a JSON preset file")
    return read_convention_file(Path(text), PRESETS)


__all__ = ["Convention", "DROID", "LIBERO", "MMACT", "PRESETS", "convention_from_dict", "load_preset"]
