"""A run's VecEnv, from its configuration."""

from pathlib import Path
from typing import Optional

from sb3_disagree.envs.vec import make_vec
from sb3_disagree.run.config import RunConfig


def build_env(config: RunConfig, run_dir: Optional[Path], n_envs: Optional[int] = None, seed: Optional[int] = None,
              vec_env: Optional[str] = None, append: bool = False):
    """The VecEnv of a run (Monitor files under ``run_dir/monitor`` when given, appended to with ``append``);
    ``n_envs``, ``seed`` and ``vec_env`` override the config's."""
    return make_vec(config.env_id, config.goal, config.env_kwargs, n_envs=n_envs or config.n_envs,
                    seed=config.seed if seed is None else seed,
                    monitor_dir=str(run_dir / "monitor") if run_dir else None, append=append,
                    vec_env=vec_env or config.vec_env)
