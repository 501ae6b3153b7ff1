"""A chunk source over a policy server, and a source of ours served: what our stack does over openpi's protocol
(``mmact_ctrl.sources.openpi``).

- :mod:`.mapping`: which observation keys carry images, state and prompt (``KeyMapping``, our ``MmactMapping``, a
  JSON file);
- :mod:`.remote_source`: :class:`RemoteSource`, a chunk source over a server, its convention settled at connect
  (``mmact_ctrl.sources.presets``);
- :mod:`.connect`: the connect check (one observation before the first episode) and the block that says what was
  configured;
- :mod:`.serving`: :class:`SourcePolicy`, a chunk source of ours as an openpi policy in our convention;
- :mod:`.preset_serving`: :class:`ConventionPolicy`, a chunk source of ours speaking a foreign convention.
"""

from mmact_ctrl.sources.remote.mapping import (PRESETS, SCENE_CAMERAS, ImageKey, KeyMapping, MmactMapping, StateKey,
                                               load_mapping)
from mmact_ctrl.sources.remote.remote_source import RemoteSource
from mmact_ctrl.sources.remote.serving import SourcePolicy, source_metadata

__all__ = ["PRESETS", "SCENE_CAMERAS", "ImageKey", "KeyMapping", "MmactMapping", "StateKey", "load_mapping",
           "RemoteSource", "SourcePolicy", "source_metadata"]
