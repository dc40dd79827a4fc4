"""The one place environments are built: a task (one env, to read its spaces) and a VecEnv of it."""

import functools
from typing import Any, Optional

import gymnasium as gym
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv

from sb3_disagree.envs import make


def check_env_id(env_id: str) -> None:
    """A ValueError naming the registered envs if ``env_id`` is not one of them."""
    if env_id not in gym.registry:
        ours = ", ".join(k for k in gym.registry if k.startswith("sb3_disagree/"))
        raise ValueError(f"unknown environment {env_id!r}; this package registers {ours}")


def make_task(env_id: str, goal: str, env_kwargs: Optional[dict[str, Any]] = None) -> gym.Env:
    """
    One env of the task ``goal`` in ``env_id``, closed at once (nothing is rendered): its spaces tell what
    a policy for it must act on.

    :raises ValueError: An unknown env id, or a goal or keyword the env refuses
    """
    check_env_id(env_id)
    try:
        env = gym.make(env_id, goal=goal, **(env_kwargs or {}))
    except (TypeError, ValueError, KeyError) as exc:
        raise ValueError(f"{env_id} has no task {goal!r} with {env_kwargs or {}}: {exc}") from None
    env.close()
    return env


def make_vec(env_id: str, goal: str, env_kwargs: Optional[dict[str, Any]] = None, n_envs: int = 1, seed: int = 0,
             monitor_dir: Optional[str] = None, append: bool = False, vec_env: str = "dummy") -> VecEnv:
    """
    A VecEnv of the task ``goal`` in ``env_id``, each env in a Monitor that records ``is_success``.

    :param env_id: Gymnasium id
    :param goal: The task's goal
    :param env_kwargs: The env's other keyword arguments
    :param n_envs: Number of envs
    :param seed: Seed of the first env (the others follow)
    :param monitor_dir: Where the Monitor files go (None: not written)
    :param append: Append to existing Monitor files instead of replacing them (a resumed run)
    :param vec_env: "dummy" (envs in this process) or "subproc" (one process per env)
    """
    check_env_id(env_id)
    if vec_env not in ("dummy", "subproc"):
        raise ValueError(f"vec_env must be dummy or subproc, got {vec_env!r}")
    subproc = vec_env == "subproc"
    return make_vec_env(functools.partial(make, env_id), n_envs=n_envs, seed=seed, monitor_dir=monitor_dir,
                        env_kwargs=dict(goal=goal, **(env_kwargs or {})),
                        monitor_kwargs=dict(info_keywords=("is_success",), override_existing=not append),
                        vec_env_cls=SubprocVecEnv if subproc else DummyVecEnv,
                        vec_env_kwargs=dict(start_method="forkserver") if subproc else None)
