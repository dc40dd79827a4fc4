"""
Jump-Start RL (Uchendu et al. 2023), its curriculum variant, as a behaviour for ACER: a guide (the
priors' mixture) acts for the first ``h`` steps of every episode, the new policy after; ``h`` steps down
as the new policy keeps up the training success.
"""

from typing import Any

import numpy as np
import torch as th

from sb3_disagree.behaviour import BehaviourPolicy, BehaviourStep
from sb3_disagree.options.base import EXPLORE, PRIOR
from sb3_disagree.options.priors import PriorSet


class JumpStart(BehaviourPolicy):
    """
    The guide (an action drawn from the priors' mean distribution, ``mu = mean_i p_i``) for an episode's
    first ``h`` steps, the new policy (``mu = pi``) after. The guide horizon follows a curriculum of
    ``stages`` equal steps from ``horizon`` down to 0: once ``window`` episodes have ended at the current
    stage, the stage advances if their training success is within ``tolerance`` of the best success seen
    at an earlier advance (JSRL's rule). The guide's distribution is the step's teacher for ACER's
    distillation term.

    :param priors: The guide's policies
    :param horizon: The guide horizon at the start, in steps (the priors' typical episode length)
    :param stages: Number of curriculum steps from ``horizon`` to 0
    :param tolerance: Advance while the recent success is at least the best so far minus this
    :param window: Episodes ended at a stage before its success is judged (at most 100: SB3 keeps the last 100)
    """

    def __init__(self, priors: PriorSet, horizon: int, stages: int = 10, tolerance: float = 0.05,
                 window: int = 50) -> None:
        if horizon < 1 or stages < 1 or not 0 < window <= 100 or tolerance < 0:
            raise ValueError("JumpStart needs horizon >= 1, stages >= 1, 0 < window <= 100 and tolerance >= 0")
        self.priors, self.horizon, self.stages, self.tolerance, self.window = priors, horizon, stages, tolerance, window
        self.stage, self.best, self.ended = 0, 0.0, 0
        self.t = np.zeros(0, dtype=int)
        self.model: Any = None
        self._usage: list[float] = []

    @property
    def h(self) -> int:
        """The guide horizon of the current stage."""
        return int(round(self.horizon * (1 - self.stage / self.stages)))

    def setup(self, model: Any) -> None:
        self.model = model
        self.priors.to(model.device)
        if len(self.t) != model.n_envs:
            self.t = np.zeros(model.n_envs, dtype=int)

    def _advance(self) -> None:
        successes = list(self.model.ep_success_buffer)[-self.window:]
        if self.stage >= self.stages or self.ended < self.window or len(successes) < self.window:
            return
        rate = float(np.mean(successes))
        self.ended = 0
        if rate >= self.best - self.tolerance:
            self.best = max(self.best, rate)
            self.stage += 1

    def __call__(self, observations: Any, probs: th.Tensor, infos: list[dict[str, Any]],
                 episode_starts: np.ndarray) -> BehaviourStep:
        starts = np.asarray(episode_starts, dtype=bool)
        self.ended += int(starts[self.t > 0].sum())  # an episode that ran ended here (not the first reset)
        self._advance()
        self.t[starts] = 0
        guide = self.t < self.h
        mix = self.priors.probs(observations, episode_starts).to(probs.device).mean(0)
        mu = th.where(th.as_tensor(guide, device=probs.device).unsqueeze(-1), mix, probs)
        actions = th.multinomial(mu, 1).squeeze(-1)
        self.t += 1
        self._usage.append(float(guide.mean()))
        return BehaviourStep(actions, mu, np.where(guide, PRIOR, EXPLORE), teacher=mix,
                             followed=guide.astype(np.float32))

    def record(self, logger: Any) -> None:
        logger.record("prior/usage", float(np.mean(self._usage)) if self._usage else 0.0)
        logger.record("jsrl/horizon", self.h)
        logger.record("jsrl/stage", self.stage)
        self._usage = []
