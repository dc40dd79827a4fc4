"""The new policy alone: along a run (greedy and sampled), after it, and on its model card."""

from collections.abc import Sequence
from pathlib import Path
from typing import Any, Optional

import numpy as np
import torch as th
import yaml
from stable_baselines3.common.callbacks import BaseCallback

from sb3_disagree.defaults import EVAL_SEED_OFFSET, FINAL_EVAL_SEED_OFFSET
from sb3_disagree.envs.vec import make_vec
from sb3_disagree.evaluation import evaluate
from sb3_disagree.priors.zoo import space_fits, space_to_dict
from sb3_disagree.run.config import RunConfig
from sb3_disagree.run.envs import build_env
from sb3_disagree.run.models import algorithm_of, load_model

class EvaluateAlone(BaseCallback):
    """
    Every ``every`` env steps, the new policy alone (no priors) on envs of its own seeds, greedy and sampled,
    with SB3's ``evaluate_policy``: logged as ``eval/success_rate_greedy`` and ``eval/success_rate`` (sampled)
    and kept in ``evaluations.npz`` (``timesteps``; per evaluation and episode ``successes`` sampled,
    ``successes_greedy``, and the sampled episodes' ``results`` and ``ep_lengths``, as SB3's ``EvalCallback``). With ``append`` the evaluations already in the file stay ahead of the new ones.

    :param config: The run's configuration: env, goal, seed, episodes per evaluation
    :param run_dir: Where ``evaluations.npz`` goes
    :param append: Keep the evaluations of the run this one resumes
    :param upto: With ``append``, keep only those made at or before this many env steps
    """

    KEYS = ("timesteps", "successes", "successes_greedy", "results", "ep_lengths")

    def __init__(self, config: RunConfig, run_dir: Path, append: bool = False, upto: Optional[int] = None) -> None:
        super().__init__()
        self.config, self.path = config, run_dir / "evaluations.npz"
        self.every = max(config.eval_every // config.n_envs, 1)  # in calls, one per vectorised step
        self.history: dict[str, list] = {key: [] for key in self.KEYS}
        if append and self.path.exists():
            with np.load(self.path) as data:
                keep = [upto is None or t <= upto for t in data["timesteps"]]  # none after the checkpoint resumed
                self.history = {key: [v for v, k in zip(data[key], keep) if k] for key in self.KEYS if key in data}
                self.history.setdefault("successes_greedy", [])
        self.env = None

    def _on_step(self) -> bool:
        if self.n_calls % self.every:
            return True

        if self.env is None:
            self.env = build_env(self.config, None, n_envs=min(self.config.n_envs, 4),
                                 seed=self.config.seed + EVAL_SEED_OFFSET, vec_env="dummy")
        # On a forked random stream: the sampled episodes' draws would otherwise shift training's, so that runs
        # differing only in what they evaluate (an average to act with, say) would drift apart.
        device = self.model.device
        with th.random.fork_rng(devices=[device.index or 0] if device.type == "cuda" else []):
            sampled = evaluate(self.model, self.env, self.config.eval_episodes, deterministic=False)
            greedy = evaluate(self.model, self.env, self.config.eval_episodes, deterministic=True)
        per = sampled.per_episode
        for key, value in zip(self.KEYS, (self.num_timesteps, per["successes"], greedy.per_episode["successes"],
                                          per["returns"], per["lengths"])):
            self.history[key].append(value)
        np.savez(self.path, **{key: np.asarray(values) for key, values in self.history.items()})
        self.logger.record("eval/success_rate", sampled.success_rate)
        self.logger.record("eval/success_rate_greedy", greedy.success_rate)
        self.logger.record("eval/mean_ep_length", sampled.mean_length)
        self.logger.record("time/total_timesteps", self.num_timesteps, exclude="tensorboard")
        self.logger.dump(self.num_timesteps)  # as SB3's EvalCallback: the evaluation gets its own row
        return True

    def _on_training_end(self) -> None:
        if self.env is not None:
            self.env.close()


def write_card(run_dir: Path, model, episodes: int, command: str = "") -> dict[str, Any]:
    """
    Evaluate a run's policy alone greedy and sampled (``episodes`` each, env seeds the run never trained on;
    none when 0) and write its model card (``README.md``) beside ``model.zip``.

    :return: The evaluations by label ("greedy", "sampled")
    """
    from sb3_disagree.model_card import write_model_card

    config = yaml.safe_load((Path(run_dir) / "config.yaml").read_text())
    evaluations = evaluate_both(model, config, episodes) if episodes > 0 else {}
    write_model_card(run_dir, config, type(model).__name__, evaluations, command)
    return evaluations


def evaluate_both(model: Any, config: dict[str, Any], episodes: int, seed: Optional[int] = None,
                  labels: tuple[str, ...] = ("greedy", "sampled")) -> dict[str, Any]:
    """
    The new policy alone greedy (SB3's default) and sampled, side by side, from the same env seeds.

    :param model: The trained model
    :param config: The run's configuration: env, goal, seed
    :param episodes: Episodes each way
    :param seed: Env seed of the first env; default the run's seed + ``FINAL_EVAL_SEED_OFFSET`` (never trained on)
    :param labels: Which of "greedy" and "sampled"
    :return: The :class:`~sb3_disagree.evaluation.Evaluation` by label
    """
    first = config.get("seed", 0) + FINAL_EVAL_SEED_OFFSET if seed is None else seed
    return {label: evaluate_alone(model, config, episodes, label == "greedy", first) for label in labels}


def evaluate_alone(model: Any, config: dict[str, Any], episodes: int, deterministic: bool, seed: int):
    """
    The new policy alone (no priors) in its run's task, on 4 envs seeded from ``seed``.

    :param model: The trained model
    :param config: The run's configuration (a saved ``config.yaml`` or ``asdict(RunConfig)``): env and goal
    :param episodes: Number of episodes
    :param deterministic: Greedy actions if True, sampled otherwise
    :param seed: Seed of the first env
    :return: The :class:`~sb3_disagree.evaluation.Evaluation`
    """
    env = make_vec(config["env_id"], config["goal"], config.get("env_kwargs") or {}, n_envs=4, seed=seed)
    try:
        for kind in ("observation", "action"):
            theirs = getattr(model, f"{kind}_space")
            if not space_fits(space_to_dict(theirs), getattr(env, f"{kind}_space")):
                raise ValueError(f"the model acts on {kind}s {space_to_dict(theirs)}, but {config['env_id']} gives "
                                 f"{space_to_dict(getattr(env, f'{kind}_space'))}: it was trained elsewhere")
        return evaluate(model, env, episodes, deterministic=deterministic)
    finally:
        env.close()


def evaluate_run(path: Path, episodes: int = 100, seed: Optional[int] = None,
                 labels: Sequence[str] = ("greedy", "sampled"), trust: bool = False) -> tuple[dict[str, Any], dict[str, Any]]:
    """
    A trained run's policy alone, loaded from its folder (or its ``model.zip``) as a user would load it.

    :param path: A run folder, or a ``model.zip`` with the run's ``config.yaml`` beside it
    :param episodes: Episodes each way
    :param seed: Env seed of the first env (default: the run's seed + ``FINAL_EVAL_SEED_OFFSET``)
    :param labels: "greedy" and/or "sampled"
    :param trust: Unpickle the model file as SB3 does (``load_run``)
    :return: The run's configuration and the :class:`~sb3_disagree.evaluation.Evaluation` by label
    """
    config, model = load_run(path, trust)
    return config, evaluate_both(model, config, episodes, seed, tuple(labels))


def load_run(path: Path, trust: bool = False) -> tuple[dict[str, Any], Any]:
    """
    A trained run's configuration and model, as a user would load it, without unpickling what the model file
    carries unless trusted (``sb3_disagree.loading``).

    :param path: A run folder, or a ``model.zip`` with the run's ``config.yaml`` beside it
    :param trust: Unpickle the model file as SB3 does (a file you made or whose source you trust)
    :return: The configuration (``config.yaml``) and the model, loaded on the CPU
    """
    from sb3_disagree.loading import ModelFileError

    path = Path(path)
    run_dir = path if path.is_dir() else path.parent
    model_path = path / "model.zip" if path.is_dir() else path
    if not model_path.is_file():
        raise FileNotFoundError(f"no model at {model_path}")
    config = read_config(run_dir)
    try:
        return config, load_model(config, model_path, device="cpu", trust=trust)
    except ModelFileError:
        raise
    except Exception as exc:  # a damaged file, or another algorithm's
        raise ValueError(f"{model_path} could not be loaded as {algorithm_of(config['mode']).__name__}: "
                         f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None


def read_config(run_dir: Path) -> dict[str, Any]:
    """
    A run's saved configuration (``config.yaml``), checked to be a mapping that names a registered env, a goal and a
    mode: a ValueError in one line for anything else.
    """
    from sb3_disagree.options import MODES

    path = Path(run_dir) / "config.yaml"
    if not path.is_file():
        raise FileNotFoundError(f"{Path(run_dir)} is not a run folder: it has no config.yaml (the run's environment, "
                                "goal and settings)")
    try:
        config = yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path} is not readable YAML ({str(exc).splitlines()[0]})") from None
    if not isinstance(config, dict):
        raise ValueError(f"{path} does not hold a run's settings (a mapping)")
    for key in ("env_id", "goal"):
        if not isinstance(config.get(key), str):
            raise ValueError(f"{path} names no {key} (a word): it is not a run's config.yaml")
    config.setdefault("mode", "disagreement")
    if config["mode"] not in MODES:
        raise ValueError(f"{path} names the mode {config['mode']!r}, not one of {', '.join(MODES)}")
    if not isinstance(config.get("env_kwargs") or {}, dict):
        raise ValueError(f"{path}: env_kwargs must be a mapping")
    from sb3_disagree.envs.vec import check_env_id

    check_env_id(config["env_id"])
    return config
