"""The greedy phase: the last steps of a run act by the new policy's argmax, so that the harvest walks where the
handed-over policy will."""

from typing import TYPE_CHECKING, Any, Optional

import numpy as np
import torch as th

from sb3_disagree.behaviour import BehaviourPolicy, BehaviourStep

if TYPE_CHECKING:
    from stable_baselines3.common.base_class import BaseAlgorithm
    from stable_baselines3.common.logger import Logger


class GreedyPhase(BehaviourPolicy):
    """
    A final greedy-consistency phase: the inner behaviour until the model has taken ``start`` env steps, then
    the new policy's own argmax, with probability ``epsilon`` a sample of the policy instead:
    ``mu = (1 - epsilon) * onehot(argmax pi) + epsilon * pi``. The phase visits the states where the greedy
    policy gets stuck (it walks into a wall whose picture never changes), so that the updates see them; mu
    covers every action the policy does, so ACER's importance weights stay exact. The inner behaviour's
    teacher is kept (distillation goes on where it is still weighted).

    :param inner: The behaviour before the phase (and the source of the teacher during it)
    :param start: Env steps (the model's ``num_timesteps``) at which the phase begins
    :param epsilon: Weight of the policy's own distribution in ``mu`` during the phase, in (0, 1]
    """

    def __init__(self, inner: BehaviourPolicy, start: int, epsilon: float = 0.2) -> None:
        if not 0 < epsilon <= 1:
            raise ValueError(f"epsilon must be in (0, 1], got {epsilon}")
        self.inner, self.start, self.epsilon = inner, start, epsilon
        self.model: Optional["BaseAlgorithm"] = None
        self._greedy: list[float] = []

    def setup(self, model: "BaseAlgorithm") -> None:
        self.model = model
        self.inner.setup(model)

    def __call__(self, observations: Any, probs: th.Tensor, infos: list[dict[str, Any]],
                 episode_starts: np.ndarray) -> BehaviourStep:
        step = self.inner(observations, probs, infos, episode_starts)
        if self.model is None or self.model.num_timesteps < self.start:
            self._greedy.append(0.0)
            return step
        onehot = th.nn.functional.one_hot(probs.argmax(-1), probs.shape[-1]).to(probs.dtype)
        mu = (1 - self.epsilon) * onehot + self.epsilon * probs
        actions = th.multinomial(mu, 1).squeeze(-1)
        self._greedy.append(1.0)
        return BehaviourStep(actions, mu, np.full(len(probs), "greedy"), teacher=step.teacher,
                             followed=None if step.followed is None else np.zeros(len(probs), np.float32))

    def rollout_start(self) -> None:
        self.inner.rollout_start()

    def rollout_teacher(self) -> Optional[np.ndarray]:
        return self.inner.rollout_teacher()

    def record(self, logger: "Logger") -> None:
        share = float(np.mean(self._greedy)) if self._greedy else 0.0
        self.inner.record(logger)
        # The inner behaviour counts the priors it would have followed; in the phase none were.
        if "prior/usage" in logger.name_to_value:
            logger.record("prior/usage", logger.name_to_value["prior/usage"] * (1 - share))
        logger.record("behaviour/greedy_phase", share)
        self._greedy = []
