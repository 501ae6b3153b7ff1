"""Chunk sources from anywhere: the contract and its capability check, action-space adapters, the plugin loader,
the openpi-protocol client and server, and the LeRobot-interface adapter. Nothing here imports MuJoCo."""

from mmact_ctrl.sources.action_space import GRIPPERS, KINDS, NATIVE, ActionAdapter, ActionSpace, adapt_actions
from mmact_ctrl.sources.adapted import AdaptedSource
from mmact_ctrl.sources.contract import (CAPABILITIES, SourceError, capabilities, check_source, require_capabilities,
                                         source_name)

__all__ = ["GRIPPERS", "KINDS", "NATIVE", "ActionAdapter", "ActionSpace", "adapt_actions", "AdaptedSource",
           "CAPABILITIES", "SourceError", "capabilities", "check_source", "require_capabilities", "source_name"]
