"""Behaviours built on priors: disagreement options (Algorithm 1) and the room-sensor oracle."""

from typing import Optional

from sb3_disagree.behaviour import BehaviourPolicy
from sb3_disagree.options.base import EXPLORE, PRIOR, OptionsBehaviour, entropy
from sb3_disagree.options.disagreement import DisagreementOptions, disagreement, kl
from sb3_disagree.options.priors import PriorSet
from sb3_disagree.options.room_sensor import RoomSensorOptions

MODES = ("disagreement", "room-sensor", "scratch")


def make_options(mode: str, priors: PriorSet, alpha: int = 10, beta: float = 0.1, entropy_offset: float = 0.1,
                 seed: Optional[int] = None) -> Optional[BehaviourPolicy]:
    """The behaviour of a training mode: "disagreement", "room-sensor", or None for "scratch"."""
    if mode == "scratch":
        return None
    if mode == "disagreement":
        return DisagreementOptions(priors, alpha=alpha, beta=beta, entropy_offset=entropy_offset, seed=seed)
    if mode == "room-sensor":
        return RoomSensorOptions(priors, entropy_offset=entropy_offset, seed=seed)
    raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")


__all__ = ["EXPLORE", "MODES", "PRIOR", "DisagreementOptions", "OptionsBehaviour", "PriorSet", "RoomSensorOptions",
           "disagreement", "entropy", "kl", "make_options"]
