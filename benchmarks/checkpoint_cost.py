"""
What a checkpoint of `dopt train` costs: `save_checkpoint` of a full replay buffer with the apartment's
defaults, one frame and four frames per observation (docs/survival.md).

    python benchmarks/checkpoint_cost.py
"""

import pathlib
import tempfile
import time

import torch as th
from stable_baselines3.common.env_util import make_vec_env

import sb3_disagree  # noqa: F401  (registers the envs)
from sb3_disagree import ACER
from sb3_disagree.checkpoints import save_checkpoint
from sb3_disagree.run import ACER_KWARGS

th.set_num_threads(1)
pathlib.Path("runs").mkdir(exist_ok=True)
for k in (1, 4):
    env = make_vec_env("sb3_disagree/Apartment-v0", n_envs=4, env_kwargs=dict(goal="bathtub"))
    model = ACER("CnnPolicy", env, policy_kwargs=dict(frame_stack=k), **ACER_KWARGS)
    model.replay_buffer.full = True  # a full buffer: the largest checkpoint a run writes
    with tempfile.TemporaryDirectory(dir="runs") as folder:
        start = time.perf_counter()
        checkpoint = save_checkpoint(model, pathlib.Path(folder))
        seconds = time.perf_counter() - start
        size = sum(p.stat().st_size for p in checkpoint.iterdir())
    print(f"frame_stack {k}: checkpoint {size / 1e9:.2f} GB in {seconds:.1f} s")
