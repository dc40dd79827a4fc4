"""
Disagreement options (paper section 3.2, Algorithm 1) as a behaviour for ACER.

Per env and step: enter the prior branch when ``x ~ U(0, 1) < H(pi(s)) - entropy_offset``; there,
score the priors' disagreement ``d``, push it into that env's window of the last ``alpha`` scores, and
follow the priors (an action from one of them, chosen uniformly) while the window's mean is **below**
``beta``; otherwise act with the new policy. Algorithm 1 line 8 and Eq. 5 print ">", which contradicts
the paper's text, its Figure 6 caption (beta = 0 never uses the priors, beta = 1 never explores) and
its discussion; "below" is what they describe.

The behaviour distribution handed to ACER is the exact marginal given the window's history:
``mu = q * mean_i p_i + (1 - q) * pi`` with ``q = clip(H - entropy_offset, 0, 1) * [gate passes]``, the
gate evaluated with this step's score included.
"""

from typing import Any, Optional

import numpy as np
import torch as th

from sb3_disagree.options.base import EPS, OptionsBehaviour
from sb3_disagree.options.priors import PriorSet


def kl(p: th.Tensor, q: th.Tensor) -> th.Tensor:
    """KL(p || q) over the last axis."""
    return (p * (th.log(p + EPS) - th.log(q + EPS))).sum(-1)


def disagreement(prior_probs: th.Tensor) -> th.Tensor:
    """
    The disagreement score of k priors per env (paper Eq. 4): ``min(KL(p1||p2), KL(p2||p1))`` for two;
    for k > 2 the mean of that score over all pairs.

    :param prior_probs: Shape (k, n_envs, n_actions)
    :return: Shape (n_envs,)
    """
    k = prior_probs.shape[0]
    scores = [th.minimum(kl(prior_probs[i], prior_probs[j]), kl(prior_probs[j], prior_probs[i]))
              for i in range(k) for j in range(i + 1, k)]
    return th.stack(scores).mean(0)


class DisagreementOptions(OptionsBehaviour):
    """
    Follow the priors while they agree (Algorithm 1, with the gate as the paper's text describes it).

    :param priors: The priors (at least two), e.g. a :class:`PriorSet` of zoo models
    :param alpha: Length of each env's window of disagreement scores
    :param beta: Follow the priors while the window's mean score is below this (>= 0)
    :param entropy_offset: Enter the prior branch when ``U(0, 1) < H(pi) - entropy_offset``
    :param reset_window: Clear an env's window when its episode starts (default), so that the last
        episode's disagreement at its goal does not stop the priors at the next start
    :param seed: Seed of the branch draws
    """

    def __init__(self, priors: PriorSet, alpha: int = 10, beta: float = 0.1, entropy_offset: float = 0.1,
                 reset_window: bool = True, seed: Optional[int] = None) -> None:
        if alpha < 1:
            raise ValueError(f"alpha (the window length) must be >= 1, got {alpha}")
        if not beta >= 0:
            raise ValueError(f"beta (the disagreement threshold) must be >= 0, got {beta}")
        super().__init__(priors, entropy_offset, seed)
        self.alpha, self.beta, self.reset_window = alpha, beta, reset_window
        self.window = np.zeros((0, alpha))
        self.count = np.zeros(0, dtype=int)

    def setup(self, model: Any) -> None:
        super().setup(model)
        if self.window.shape[0] != self.n_envs:
            self.window = np.zeros((self.n_envs, self.alpha))
            self.count = np.zeros(self.n_envs, dtype=int)

    def window_mean(self) -> np.ndarray:
        """Mean of each env's window over the entries present (nan where empty)."""
        n = np.minimum(self.count, self.alpha)
        with np.errstate(invalid="ignore"):
            return np.where(n > 0, self.window.sum(1) / np.maximum(n, 1), np.nan)

    def _gate(self, observations, prior_probs, infos, episode_starts, branch):
        if self.reset_window:
            self.window[episode_starts] = 0.0
            self.count[episode_starts] = 0
        d = disagreement(prior_probs).cpu().numpy()
        # The gate if this step's score joins the window (the window itself changes only where the branch is entered).
        slot = self.count % self.alpha
        rows = np.arange(len(d))
        trial = self.window.copy()
        trial[rows, slot] = d
        n = np.minimum(self.count + 1, self.alpha)
        gate = trial.sum(1) / n < self.beta
        self.window[branch] = trial[branch]
        self.count[branch] += 1
        self._record("prior/disagreement", d.mean())
        return gate
