"""Behaviours built on priors: disagreement options (Algorithm 1), the room-sensor oracle, and the peers a
user would try instead (kickstarting's teacher; fine-tuning has no behaviour)."""

from typing import Optional

from sb3_disagree.behaviour import BehaviourPolicy
from sb3_disagree.options.base import EXPLORE, PRIOR, OptionsBehaviour, entropy
from sb3_disagree.options.disagreement import DisagreementOptions, disagreement, kl
from sb3_disagree.options.jump_start import JumpStart
from sb3_disagree.options.priors import PriorSet
from sb3_disagree.options.room_sensor import RoomSensorOptions
from sb3_disagree.options.teacher import PriorTeacher

MODES = ("disagreement", "disagreement-distill", "room-sensor", "scratch", "finetune", "kickstart", "jsrl", "ppo")
# Modes whose new policy acts alone while it learns (no priors in the behaviour).
ALONE = ("scratch", "finetune", "ppo")


def make_options(mode: str, priors: PriorSet, alpha: int = 10, beta: float = 0.1, entropy_offset: float = 0.1,
                 seed: Optional[int] = None, horizon: int = 100) -> Optional[BehaviourPolicy]:
    """The behaviour of a training mode: "disagreement" and "disagreement-distill" (the same behaviour; ACER distils
    toward its teacher), "room-sensor", "kickstart" (the priors as teachers of a
    policy that acts alone), "jsrl" (the priors guide each episode's first ``horizon`` steps, a curriculum
    shortens it), or None for "scratch" and "finetune"."""
    if mode in ALONE:
        return None
    if mode == "kickstart":
        return PriorTeacher(priors)
    if mode == "jsrl":
        return JumpStart(priors, horizon=horizon)
    if mode in ("disagreement", "disagreement-distill"):
        return DisagreementOptions(priors, alpha=alpha, beta=beta, entropy_offset=entropy_offset, seed=seed)
    if mode == "room-sensor":
        return RoomSensorOptions(priors, entropy_offset=entropy_offset, seed=seed)
    raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")


__all__ = ["ALONE", "EXPLORE", "MODES", "PRIOR", "JumpStart", "PriorTeacher", "DisagreementOptions", "OptionsBehaviour",
           "PriorSet", "RoomSensorOptions", "disagreement", "entropy", "kl", "make_options"]
