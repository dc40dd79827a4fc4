"""sb3-disagree: Disagreement Options on Stable-Baselines3."""

from sb3_disagree import envs  # registers the environments with Gymnasium (cheaply: no renderer is loaded)
from sb3_disagree.acer import ACER
from sb3_disagree.behaviour import BehaviourPolicy, BehaviourStep, OnPolicyBehaviour
from sb3_disagree.version import __version__

__all__ = ["ACER", "envs", "BehaviourPolicy", "BehaviourStep", "OnPolicyBehaviour", "__version__"]
