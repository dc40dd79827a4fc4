"""Kickstarting (Schmitt et al. 2018): the new policy acts alone; the priors' mixture is its teacher."""

from typing import Any

import numpy as np
import torch as th

from sb3_disagree.behaviour import BehaviourPolicy, BehaviourStep
from sb3_disagree.options.base import EXPLORE
from sb3_disagree.options.priors import PriorSet


class PriorTeacher(BehaviourPolicy):
    """
    Sample from the current policy (``mu = pi``) and hand ACER the priors' mean distribution as the teacher
    of every step, for ACER's distillation term (``distill_coef``, ``distill_states="all"``). Once the model's
    distillation weight has annealed to zero (it never rises again), the priors are no longer asked: their
    forward passes cost about a tenth of a step, and the steps carry no teacher.

    :param priors: The teachers
    """

    def __init__(self, priors: PriorSet) -> None:
        self.priors = priors
        self.model: Any = None

    def setup(self, model: Any) -> None:
        self.model = model
        self.priors.to(model.device)

    def teaching(self) -> bool:
        """Whether the model still weighs a teacher (True for a model without a distillation schedule)."""
        weight = getattr(self.model, "distill_weight", None)
        return weight is None or weight() > 0

    def __call__(self, observations: Any, probs: th.Tensor, infos: list[dict[str, Any]],
                 episode_starts: np.ndarray) -> BehaviourStep:
        teacher = None
        if self.teaching():
            teacher = self.priors.probs(observations, episode_starts).to(probs.device).mean(0)
        actions = th.multinomial(probs, 1).squeeze(-1)
        return BehaviourStep(actions, probs, np.full(len(probs), EXPLORE), teacher=teacher,
                             followed=np.zeros(len(probs), np.float32))
