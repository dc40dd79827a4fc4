"""
Whether the published Jump-Start RL package (`jsrl` on PyPI, an SB3 wrapper) runs on this package's envs as-is,
as the outside reference for the `jsrl` mode: DQN (JSRL's guide acts through `predict`, which SB3 calls only in
off-policy rollouts) on the state apartment with the zoo's shower prior as the guide, 2k steps.

    python -m venv /tmp/jsrlenv && /tmp/jsrlenv/bin/pip install --no-deps jsrl==0.0.3
    PYTHONPATH=.:/tmp/jsrlenv/lib/python3.11/site-packages .venv/bin/python benchmarks/jsrl_package.py

Prints "ran" with the guide horizon reached, or the error that stopped it.
"""

import traceback

import numpy as np
from stable_baselines3 import DQN
from stable_baselines3.common.env_util import make_vec_env

import sb3_disagree  # noqa: F401  (registers the envs)
from sb3_disagree.priors import Zoo
from sb3_disagree.loggers import silent_logger

ENV = "sb3_disagree/ApartmentState-v0"


def main() -> None:
    from jsrl import get_jsrl_algorithm

    env = make_vec_env(ENV, n_envs=1, env_kwargs=dict(goal="bathtub"))
    zoo = Zoo()
    guide = zoo.load(zoo.get("shower", ENV), env, device="cpu").policy
    horizons = np.arange(100, -1, -10)
    try:
        model = get_jsrl_algorithm(DQN)(
            "MlpPolicy", env, buffer_size=5_000, verbose=0,
            policy_kwargs=dict(guide_policy=guide, max_horizon=100, horizons=horizons, tolerance=0.05, window_size=1,
                               eval_freq=500, n_eval_episodes=2))
        model.set_logger(silent_logger())  # SB3's default logger leaves a folder in the temp dir
        model.learn(2_000)
        print(f"ran: guide horizon {model.policy.horizon} after 2k steps")
    except Exception as exc:  # what stops it is the finding
        print(f"failed: {type(exc).__name__}: {exc}")
        print("".join(traceback.format_exception(exc)[-3:]))


if __name__ == "__main__":
    main()
