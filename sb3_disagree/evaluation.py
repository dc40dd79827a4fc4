"""A policy alone: success rate, episode length and return over episodes with SB3's ``evaluate_policy``."""

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Optional

import numpy as np
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.vec_env import VecEnv


@dataclass
class Evaluation:
    """Success rate, episode length and return of a policy acting alone."""

    success_rate: float
    mean_length: float
    mean_return: float
    episodes: int
    deterministic: bool
    per_episode: dict[str, list] = field(default_factory=dict)  # successes, returns, lengths; not in as_dict

    def as_dict(self) -> dict[str, Any]:
        return {"success_rate": self.success_rate, "mean_length": self.mean_length, "mean_return": self.mean_return,
                "episodes": self.episodes, "deterministic": self.deterministic}


def evaluate(model: BaseAlgorithm, env: VecEnv, episodes: int = 100, deterministic: bool = True,
             progress: Optional[Callable[[int], None]] = None) -> Evaluation:
    """
    Run the policy alone for a number of episodes from the env's start distribution, with SB3's own
    ``evaluate_policy`` (which carries a policy's state, such as a frame stack, between steps).

    :param model: The policy
    :param env: The environment (a VecEnv of Monitor-wrapped envs that report ``is_success``)
    :param episodes: Number of episodes
    :param deterministic: Greedy actions if True, sampled otherwise
    :param progress: Called with the number of finished episodes
    """
    from stable_baselines3.common.evaluation import evaluate_policy

    successes: list[bool] = []

    def on_step(local: dict[str, Any], _: dict[str, Any]) -> None:
        if local["done"]:
            successes.append(bool(local["info"].get("is_success", False)))
            if progress:
                progress(len(successes))

    returns, lengths = evaluate_policy(model, env, n_eval_episodes=episodes, deterministic=deterministic,
                                       return_episode_rewards=True, callback=on_step)
    return Evaluation(float(np.mean(successes)), float(np.mean(lengths)), float(np.mean(returns)), len(lengths),
                      deterministic, dict(successes=successes, returns=list(returns), lengths=list(lengths)))
