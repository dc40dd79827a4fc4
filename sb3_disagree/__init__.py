"""sb3-disagree: Disagreement Options on Stable-Baselines3."""

import importlib
from typing import Any

from sb3_disagree import envs  # registers the environments with Gymnasium (cheaply: no renderer is loaded)
from sb3_disagree.version import __version__

# What the package hands out, imported on first use: ``import sb3_disagree`` (as a Gymnasium plugin, or the command
# line starting) costs no torch.
_LAZY = {"ACER": "sb3_disagree.acer", "BehaviourPolicy": "sb3_disagree.behaviour",
         "BehaviourStep": "sb3_disagree.behaviour", "OnPolicyBehaviour": "sb3_disagree.behaviour",
         "load": "sb3_disagree.loading"}  # load: a saved model opened without unpickling what it carries


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'sb3_disagree' has no attribute {name!r}")


__all__ = ["ACER", "envs", "BehaviourPolicy", "BehaviourStep", "OnPolicyBehaviour", "load", "__version__"]
