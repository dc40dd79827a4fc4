"""The one VecEnv factory of runs and evaluations."""

from pathlib import Path
from typing import Optional

from stable_baselines3.common.env_util import make_vec_env

from sb3_disagree.run.config import RunConfig

def build_env(config: RunConfig, run_dir: Optional[Path], n_envs: Optional[int] = None, seed: Optional[int] = None,
              vec_env: Optional[str] = None, append: bool = False):
    """The VecEnv of a run (Monitor files under ``run_dir/monitor`` when given, appended to with ``append``);
    ``n_envs``, ``seed`` and ``vec_env`` override the config's."""
    import functools

    from gymnasium.envs.registration import registry
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    from sb3_disagree.envs import make

    if config.env_id not in registry:
        ours = ", ".join(k for k in registry if k.startswith("sb3_disagree/"))
        raise ValueError(f"unknown environment {config.env_id!r}; this package registers {ours}")
    subproc = (vec_env or config.vec_env) == "subproc"
    return make_vec_env(functools.partial(make, config.env_id), n_envs=n_envs or config.n_envs,
                        seed=config.seed if seed is None else seed,
                        monitor_dir=str(run_dir / "monitor") if run_dir else None,
                        env_kwargs=dict(goal=config.goal, **config.env_kwargs),
                        monitor_kwargs=dict(info_keywords=("is_success",), override_existing=not append),
                        vec_env_cls=SubprocVecEnv if subproc else DummyVecEnv,
                        vec_env_kwargs=dict(start_method="forkserver") if subproc else None)


