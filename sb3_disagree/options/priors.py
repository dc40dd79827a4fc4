"""Frozen prior policies queried together: one forward pass per prior for the whole batch of envs."""

from collections.abc import Sequence
from typing import Any, Optional

import numpy as np
import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm

from sb3_disagree.acer.memory import push_frames


class PriorSet:
    """
    The action distributions of k frozen priors for a batch of observations. A prior with memory (an ACER
    policy with ``frame_stack > 1``) gets the stack of its own recent observations, kept here between calls,
    whatever the new policy sees; the others get the current observation.

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
        self._memory = [getattr(p.policy, "frame_stack", 1) for p in self.priors]
        self._stacks: list[Optional[np.ndarray]] = [None] * len(self.priors)

    def __len__(self) -> int:
        return len(self.priors)

    def to(self, device: th.device) -> "PriorSet":
        """Run the priors on the device of the policy they serve."""
        for prior in self.priors:
            prior.policy.to(device)
            prior.device = device
        return self

    @th.no_grad()
    def probs(self, observations: Any, episode_starts: Optional[np.ndarray] = None) -> th.Tensor:
        """
        :param observations: A batch of observations as the VecEnv gives them, one call per env step
        :param episode_starts: True where the observation is the first of an episode (clears the stacks of the
            priors with memory); None: only the first call starts them
        :return: pi_i(.|s) for every prior, shape (k, n_envs, n_actions)
        """
        return self.probs_sequence([observations], [episode_starts])[:, 0]

    @th.no_grad()
    def probs_sequence(self, observations: Sequence[np.ndarray], episode_starts: Sequence[np.ndarray]) -> th.Tensor:
        """
        ``probs`` for consecutive env steps at once: one forward pass per prior over all of them (a rollout's
        teachers: one large batch instead of many small ones). The stacks of the priors with memory
        advance step by step as ``probs`` would advance them.

        :param observations: Per step, the batch of observations as the VecEnv gave them, each of shape (n_envs, ...)
        :param episode_starts: Per step, True where the observation is the first of an episode
        :return: pi_i(.|s) for every prior and step, shape (k, steps, n_envs, n_actions)
        """
        steps, n = len(observations), len(observations[0])
        batch = observations[0] if steps == 1 else np.concatenate(observations)  # probs' single step: no copy
        out, converted = [], {}
        for i, (prior, j) in enumerate(zip(self.priors, self._converter)):
            if j not in converted:
                converted[j] = prior.policy.obs_to_tensor(batch)[0]
            obs = converted[j]
            if self._memory[i] > 1:
                frames = obs.cpu().numpy().reshape(steps, n, *obs.shape[1:])
                stacks = []
                for t in range(steps):
                    stack = self._stacks[i]
                    fresh = stack is None or stack.shape[0] != n
                    self._stacks[i] = push_frames(None if fresh else stack, frames[t],
                                                  None if fresh else episode_starts[t], self._memory[i])
                    stacks.append(self._stacks[i])
                obs = th.as_tensor(stacks[0] if steps == 1 else np.concatenate(stacks))
            probs = prior.policy.get_distribution(obs.to(prior.policy.device)).distribution.probs
            out.append(probs.reshape(steps, n, -1))
        return th.stack(out)
