"""
One run of the method or a peer, in parts whose names say what they hold: ``config`` (RunConfig), ``presets``
(each mode's settings, from ``hyperparams/modes.yml``), ``models`` (what trains), ``envs`` (the VecEnv factory),
``train`` (the loop and the run folder), ``evaluation`` (the policy alone, the model card), ``logs`` and
``trajectories``.
"""

from sb3_disagree.defaults import DEFAULT_ENV, EVAL_SEED_OFFSET, FINAL_EVAL_SEED_OFFSET
from sb3_disagree.run.config import ACER_KWARGS, KICKSTART, PPO_KWARGS, RunConfig, check_navigation_env
from sb3_disagree.run.presets import acer_defaults, resolve
from sb3_disagree.run.envs import build_env
from sb3_disagree.run.evaluation import EvaluateAlone, evaluate_alone, evaluate_both, evaluate_run, load_run, write_card
from sb3_disagree.run.logs import AppendingCSVOutputFormat, run_logger
from sb3_disagree.run.models import algorithm_of, new_model
from sb3_disagree.run.train import check_resume, train
from sb3_disagree.run.trajectories import RecordTrajectories, draw_episode, read_episodes

__all__ = ["ACER_KWARGS", "DEFAULT_ENV", "EVAL_SEED_OFFSET", "FINAL_EVAL_SEED_OFFSET", "KICKSTART", "PPO_KWARGS",
           "AppendingCSVOutputFormat", "EvaluateAlone", "RecordTrajectories", "RunConfig", "acer_defaults", "algorithm_of", "build_env",
           "check_navigation_env", "check_resume", "draw_episode", "evaluate_alone", "evaluate_both", "evaluate_run", "load_run", "new_model", "read_episodes", "resolve", "run_logger",
           "train", "write_card"]
