"""Frozen prior policies queried together: one forward pass per prior for the whole batch of envs."""

from collections.abc import Sequence
from typing import Any

import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm


class PriorSet:
    """
    The action distributions of k frozen priors for a batch of observations.

    :param priors: SB3 models whose policies have ``get_distribution`` (ACER, PPO, A2C, ...)
    """

    def __init__(self, priors: Sequence[BaseAlgorithm]) -> None:
        if len(priors) < 2:
            raise ValueError(f"disagreement needs at least two priors, got {len(priors)}")
        self.priors = list(priors)
        for prior in self.priors:
            prior.policy.set_training_mode(False)
            prior.policy.requires_grad_(False)
        # Priors with equal observation spaces share one conversion of each batch: per prior, the first
        # prior whose space equals its own (decided once here, not per step).
        spaces = [p.policy.observation_space for p in self.priors]
        self._converter = [next(j for j in range(i + 1) if spaces[j] == spaces[i]) for i in range(len(spaces))]

    def __len__(self) -> int:
        return len(self.priors)

    def to(self, device: th.device) -> "PriorSet":
        """Run the priors on the device of the policy they serve."""
        for prior in self.priors:
            prior.policy.to(device)
            prior.device = device
        return self

    @th.no_grad()
    def probs(self, observations: Any) -> th.Tensor:
        """
        :param observations: A batch of observations as the VecEnv gives them
        :return: pi_i(.|s) for every prior, shape (k, n_envs, n_actions)
        """
        out, converted = [], {}
        for prior, j in zip(self.priors, self._converter):
            if j not in converted:
                converted[j] = prior.policy.obs_to_tensor(observations)[0]
            obs = converted[j].to(prior.policy.device)
            out.append(prior.policy.get_distribution(obs).distribution.probs)
        return th.stack(out)
