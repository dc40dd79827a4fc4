"""
The behaviour-policy hook: what ACER asks before each rollout step.

A behaviour chooses the actions that the environments execute and reports the distribution ``mu`` it
drew them from. ACER stores ``mu`` and corrects for it by importance sampling, so any behaviour that
puts positive mass on the actions it takes keeps the learning off-policy correct.
"""

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, Any, NamedTuple, Optional, Union

import numpy as np
import torch as th

if TYPE_CHECKING:
    from stable_baselines3.common.base_class import BaseAlgorithm
    from stable_baselines3.common.logger import Logger


class BehaviourStep(NamedTuple):
    """
    What a behaviour returns for one vectorised step.

    :param actions: The action to execute in each env, shape (n_envs,)
    :param mu: The behaviour distribution each action was drawn from, shape (n_envs, n_actions)
    :param tags: Optional per-env labels of the step (e.g. "prior" / "explore"), shape (n_envs,)
    :param teacher: Optional distribution the new policy may be distilled toward at this step (the priors'
        mixture), shape (n_envs, n_actions); stored with the segment for ACER's ``distill_coef``
    :param followed: Optional 1.0 where the teacher chose this step's action, shape (n_envs,)
    """

    actions: Union[np.ndarray, th.Tensor]
    mu: Union[np.ndarray, th.Tensor]
    tags: Optional[np.ndarray] = None
    teacher: Optional[Union[np.ndarray, th.Tensor]] = None
    followed: Optional[Union[np.ndarray, th.Tensor]] = None


class BehaviourPolicy(ABC):
    """
    Base class of behaviours. Subclasses work on the whole batch of envs at once.
    """

    def setup(self, model: "BaseAlgorithm") -> None:
        """
        Called by the algorithm when learning starts, and whenever its env changes.

        :param model: The algorithm that consults this behaviour
        """

    @abstractmethod
    def __call__(
        self,
        observations: Any,
        probs: th.Tensor,
        infos: list[dict[str, Any]],
        episode_starts: np.ndarray,
    ) -> BehaviourStep:
        """
        :param observations: The batch of observations, as the VecEnv returned them
        :param probs: The current policy's action probabilities pi(.|s), shape (n_envs, n_actions)
        :param infos: The infos of the step that produced these observations (empty dicts at the start)
        :param episode_starts: True where an observation is the first of an episode
        :return: The actions, the distribution mu they were drawn from, and optional tags
        """

    def record(self, logger: "Logger") -> None:
        """
        Record this behaviour's statistics for the rollout that just ended (keys such as ``prior/usage``).

        :param logger: The algorithm's logger
        """

    def rollout_start(self) -> None:
        """Called by the algorithm before the first step of each rollout."""

    def rollout_teacher(self) -> Optional[np.ndarray]:
        """
        The teachers of the rollout's steps, for a behaviour that computes them once per rollout instead of with
        each step (``BehaviourStep.teacher``); called by the algorithm after the rollout's last step.

        :return: One row per step of the rollout, shape (steps, n_envs, n_actions), zeros where a step has no
            teacher; None where the steps carried their own
        """
        return None


class OnPolicyBehaviour(BehaviourPolicy):
    """Sample from the current policy: ``mu = pi``. The default, which makes ACER plain ACER."""

    def __call__(
        self,
        observations: Any,
        probs: th.Tensor,
        infos: list[dict[str, Any]],
        episode_starts: np.ndarray,
    ) -> BehaviourStep:
        actions = th.multinomial(probs, 1).squeeze(-1)
        return BehaviourStep(actions=actions, mu=probs)


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
