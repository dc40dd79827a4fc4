"""Kickstarting (Schmitt et al. 2018): the new policy acts alone; the priors' mixture is its teacher."""

from typing import Any, Optional

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

    The teachers are computed once per rollout, over all its steps (``PriorSet.probs_sequence``: one forward pass
    per prior on 80 frames instead of 20 on 4; docs/benchmarks.md), and handed over by
    ``rollout_teacher``; the steps themselves carry none. ``per_rollout=False`` computes them at each step.

    :param priors: The teachers
    :param per_rollout: Compute the teachers once per rollout (else at each step, in ``BehaviourStep.teacher``)
    """

    def __init__(self, priors: PriorSet, per_rollout: bool = True) -> None:
        self.priors = priors
        self.per_rollout = per_rollout
        self.model: Any = None
        # Per step of the rollout under way: its observations and episode starts where it is taught, else None.
        self._steps: list[Optional[tuple[np.ndarray, np.ndarray]]] = []

    def setup(self, model: Any) -> None:
        self.model = model
        self.priors.to(model.device)

    def teaching(self) -> bool:
        """Whether the model still weighs a teacher (True for a model without a distillation schedule)."""
        weight = getattr(self.model, "distill_weight", None)
        return weight is None or weight() > 0

    def rollout_start(self) -> None:
        self._steps = []

    def __call__(self, observations: Any, probs: th.Tensor, infos: list[dict[str, Any]],
                 episode_starts: np.ndarray) -> BehaviourStep:
        teacher = None
        teaching = self.teaching()
        if self.per_rollout:
            self._steps.append((np.array(observations, copy=True), np.array(episode_starts, dtype=bool, copy=True))
                               if teaching else None)
        elif teaching:
            teacher = self.priors.probs(observations, episode_starts).to(probs.device).mean(0)
        actions = th.multinomial(probs, 1).squeeze(-1)
        return BehaviourStep(actions, probs, np.full(len(probs), EXPLORE), teacher=teacher,
                             followed=np.zeros(len(probs), np.float32))

    def rollout_teacher(self) -> Optional[np.ndarray]:
        steps, self._steps = self._steps, []
        taught = [t for t, step in enumerate(steps) if step is not None]
        if not taught:
            return None
        mixture = self.priors.probs_sequence([steps[t][0] for t in taught],
                                             [steps[t][1] for t in taught]).mean(0).cpu().numpy()
        out = np.zeros((len(steps), *mixture.shape[1:]), dtype=np.float32)
        out[taught] = mixture
        return out
