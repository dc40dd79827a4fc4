"""
ACER in rl-zoo3 (optional extra ``pip install sb3-disagree[zoo]``). rl-zoo3 has no plugin API; its way for an
outside algorithm is an entry in ``rl_zoo3.ALGOS`` (and, for ``--optimize``, a sampler in
``rl_zoo3.hyperparams_opt.HYPERPARAMS_SAMPLER``) before its ``train`` runs. This module does both, then hands
over to rl-zoo3's own command line, with the package's own ``hyperparams/acer.yml`` unless ``--conf-file`` names
another::

    python -m sb3_disagree.rl_zoo --algo acer --env CartPole-v1
    python -m sb3_disagree.rl_zoo --algo acer --env CartPole-v1 --optimize --n-trials 20 --n-timesteps 20000
"""

import sys
from pathlib import Path
from typing import Any

from torch import nn

from sb3_disagree.acer import ACER

HYPERPARAMS = Path(__file__).resolve().parent / "hyperparams"  # rl-zoo3's format: env id -> settings
NET_ARCH = {"small": dict(pi=[64, 64], qf=[64, 64]), "medium": dict(pi=[256, 256], qf=[256, 256])}
ACTIVATION = {"tanh": nn.Tanh, "relu": nn.ReLU}


def sample_acer_params(trial: Any, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """
    ACER's hyperparameters for an Optuna trial, in the style of rl-zoo3's ``hyperparams_opt.py``.

    :param trial: The Optuna trial
    :param n_actions: Number of actions (unused: ACER's heads follow the action space)
    :param n_envs: Number of envs (unused)
    :param additional_args: rl-zoo3's extra arguments (unused)
    :return: ACER's keyword arguments
    """
    one_minus_gamma = trial.suggest_float("one_minus_gamma", 0.0001, 0.03, log=True)
    learning_rate = trial.suggest_float("learning_rate", 1e-5, 3e-3, log=True)
    n_steps = trial.suggest_categorical("n_steps", [5, 10, 20, 40])
    replay_ratio = trial.suggest_categorical("replay_ratio", [0, 1, 2, 4, 8])
    ent_coef = trial.suggest_float("ent_coef", 1e-8, 0.1, log=True)
    q_coef = trial.suggest_float("q_coef", 0.1, 1.0)
    c = trial.suggest_categorical("c", [1.0, 5.0, 10.0])
    trust_region = trial.suggest_categorical("trust_region", [True, False])
    reward_scale = trial.suggest_categorical("reward_scale", [0.1, 1.0])
    net_arch = trial.suggest_categorical("net_arch", list(NET_ARCH))
    activation_fn = trial.suggest_categorical("activation_fn", list(ACTIVATION))
    trial.set_user_attr("gamma", 1 - one_minus_gamma)
    return {
        "gamma": 1 - one_minus_gamma,
        "learning_rate": learning_rate,
        "n_steps": n_steps,
        "replay_ratio": replay_ratio,
        "ent_coef": ent_coef,
        "q_coef": q_coef,
        "c": c,
        "trust_region": trust_region,
        "reward_scale": reward_scale,
        "policy_kwargs": {"net_arch": NET_ARCH[net_arch], "activation_fn": ACTIVATION[activation_fn]},
    }


def register() -> None:
    """Make ``--algo acer`` known to rl-zoo3's ``train`` (training and ``--optimize``) and ``enjoy``."""
    from rl_zoo3 import ALGOS, hyperparams_opt

    ALGOS["acer"] = ACER
    hyperparams_opt.HYPERPARAMS_SAMPLER["acer"] = sample_acer_params
    hyperparams_opt.HYPERPARAMS_CONVERTER["acer"] = lambda params: params  # the sampler returns ACER's kwargs


def main() -> None:
    """rl-zoo3's ``train`` command line, with ACER registered and this package's envs importable."""
    import sb3_disagree  # noqa: F401  (registers the envs)

    register()
    from rl_zoo3.train import train

    if "--conf-file" not in sys.argv and "-conf" not in sys.argv:
        sys.argv += ["--conf-file", str(HYPERPARAMS / "acer.yml")]

    train()


if __name__ == "__main__":
    main()
