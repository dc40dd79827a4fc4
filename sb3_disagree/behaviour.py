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
