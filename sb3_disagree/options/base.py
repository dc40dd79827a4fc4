"""What both prior-following behaviours share: the entropy branch, the exact mixture mu, the statistics."""

from typing import Any, Optional

import numpy as np
import torch as th

from sb3_disagree.behaviour import BehaviourPolicy, BehaviourStep
from sb3_disagree.options.priors import PriorSet

EPS = 1e-8
PRIOR, EXPLORE = "prior", "explore"


def entropy(probs: th.Tensor) -> th.Tensor:
    """H(p) in nats over the last axis."""
    return -(probs * th.log(probs + EPS)).sum(-1)


class OptionsBehaviour(BehaviourPolicy):
    """
    Enter the prior branch when ``x ~ U(0, 1) < H(pi(s)) - entropy_offset``; there, follow the priors
    where a gate (defined by subclasses) passes, and act with the new policy elsewhere. ``mu`` is the
    exact marginal ``q * mean_i p_i + (1 - q) * pi`` with ``q = clip(H - entropy_offset, 0, 1) * gate``.

    :param priors: The priors
    :param entropy_offset: Subtracted from the entropy (in nats) in the branch test
    :param seed: Seed of the branch draws
    """

    def __init__(self, priors: PriorSet, entropy_offset: float = 0.1, seed: Optional[int] = None) -> None:
        self.priors = priors
        self.entropy_offset = entropy_offset
        self.rng = np.random.default_rng(seed)
        self.n_envs = 0
        self._stats: dict[str, list[float]] = {}
        self.last: dict[str, float] = {}  # the statistics of the last rollout

    def setup(self, model: Any) -> None:
        self.n_envs = model.n_envs
        self.priors.to(model.device)

    def _gate(self, observations: Any, prior_probs: th.Tensor, infos: list[dict], episode_starts: np.ndarray,
              branch: np.ndarray) -> np.ndarray:
        """Whether the priors would be followed in each env if the branch is entered."""
        raise NotImplementedError

    def __call__(self, observations: Any, probs: th.Tensor, infos: list[dict[str, Any]],
                 episode_starts: np.ndarray) -> BehaviourStep:
        h = entropy(probs)
        h_np = h.cpu().numpy()
        branch = self.rng.random(len(h_np)) < h_np - self.entropy_offset
        prior_probs = self.priors.probs(observations, episode_starts).to(probs.device)
        gate = self._gate(observations, prior_probs, infos, np.asarray(episode_starts, dtype=bool), branch)
        follow = branch & gate
        mix = prior_probs.mean(0)
        q = th.as_tensor(np.clip(h_np - self.entropy_offset, 0.0, 1.0) * gate, dtype=probs.dtype, device=probs.device)
        mu = q.unsqueeze(-1) * mix + (1 - q.unsqueeze(-1)) * probs
        follow_t = th.as_tensor(follow, device=probs.device).unsqueeze(-1)
        # A uniformly chosen prior's action is a draw from the priors' mean distribution.
        actions = th.multinomial(th.where(follow_t, mix, probs), 1).squeeze(-1)
        self._record("prior/usage", follow.mean())
        self._record("prior/branch", branch.mean())
        self._record("prior/entropy", float(h.mean()))
        return BehaviourStep(actions, mu, np.where(follow, PRIOR, EXPLORE), teacher=mix,
                             followed=follow.astype(np.float32))

    def _record(self, key: str, value: float) -> None:
        self._stats.setdefault(key, []).append(float(value))

    def record(self, logger) -> None:
        self.last = {key: float(np.mean(values)) for key, values in self._stats.items()}
        for key, value in self.last.items():
            logger.record(key, value)
        self._stats = {}
