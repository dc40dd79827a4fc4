"""
One training run: choose priors, build the behaviour, train, write the run folder.

A run folder (``runs/<env>/<goal>/<mode>-<seed>/``) holds ``config.yaml``, ``model.zip``,
``progress.csv``, TensorBoard events, ``monitor/`` files, ``checkpoints/``, the model card ``README.md`` and,
when asked (``record_trajectories``), ``trajectories.jsonl`` (the recorded episodes with their per-step
tags). A run survives what stops it (``sb3_disagree.checkpoints``); a resumed run continues the step count
and its history (monitor files, ``progress.csv``, ``evaluations.npz``), so its curves read as one run.
"""

import pickle
import shutil
import time
import zipfile
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any, Optional

import yaml
from stable_baselines3.common.callbacks import BaseCallback, CallbackList

from sb3_disagree.acer import ACER
from sb3_disagree.behaviour import OnPolicyBehaviour
from sb3_disagree.finish.greedy_phase import GreedyPhase
from sb3_disagree.finish.ready import StartWhenReady
from sb3_disagree.finish.consistency import HarvestLabels, RoundStats, greedy_consistency
from sb3_disagree.run.allocator import keep_freed_memory
from sb3_disagree.checkpoints import (BUFFER, Checkpoint, replace_model, resume_point, save_checkpoint,
                                      sigterm_as_interrupt, truncate_logs)
from sb3_disagree.files import write_atomic
from sb3_disagree.options import PriorSet, make_options
from sb3_disagree.priors.select import choose_priors, guide_horizon
from sb3_disagree.run.config import RunConfig
from sb3_disagree.run.envs import build_env
from sb3_disagree.run.evaluation import EvaluateAlone, read_config
from sb3_disagree.run.logs import run_logger
from sb3_disagree.run.models import load_model, new_model
from sb3_disagree.run.trajectories import RecordTrajectories

def train(config: RunConfig, out: Path = Path("runs"), resume: Optional[Path] = None,
          callbacks: Optional[list[BaseCallback]] = None, on_priors: Optional[Callable[[list, list], None]] = None,
          run_dir: Optional[Path] = None, steps: Optional[int] = None, force: bool = False,
          on_round: Optional[Callable[[RoundStats], None]] = None, trust: bool = False) -> tuple[Path, ACER, bool]:
    """
    Train a new policy with the method (or from scratch, or a peer method), writing the run folder.

    A run survives what stops it (``sb3_disagree.checkpoints``): a checkpoint every ``config.checkpoint_every``
    env steps and at the end, SIGTERM saved like Ctrl-C; ``resume`` continues from the newest complete
    checkpoint, with the logs cut back to it.

    :param config: The run's configuration (ignored in favour of the saved one when resuming)
    :param out: Root of the runs
    :param resume: A run folder to continue
    :param callbacks: Extra SB3 callbacks (the CLI's live display)
    :param on_priors: Called with the chosen priors and their similarities
    :param run_dir: Write the run here instead of under ``out`` (experiments choose their own layout)
    :param steps: With ``resume``, the run's new total of env steps (default: the saved one)
    :param force: Replace an existing run in the folder (without it, an existing run is an error)
    :param on_round: Called with the statistics of the harvest's fit (``config.consistency_harvest``), which follows a
        finished training; ``model.zip`` is then the fitted policy
    :param trust: Open a resumed run's saved model, or an embedding saved as a pickle, as SB3 and gensim do,
        unpickling what they carry (files you made); otherwise models are opened without (``sb3_disagree.loading``)
        and pickled embeddings refused
    :return: The run folder, the model, and whether training (and the phase) finished (False when interrupted)
    """
    keep_freed_memory()  # 14% more env steps/s here: no page faults for each step's few-MB blocks
    checkpoint, saved = None, {}
    if resume is not None:
        run_dir = Path(resume)
        if not (run_dir / "model.zip").is_file():
            raise FileNotFoundError(f"{run_dir} is not a run folder with config.yaml and model.zip to resume")
        saved = read_config(run_dir)
        config = RunConfig.of_saved(saved)
        checkpoint = resume_point(run_dir)
        done = int(checkpoint[1]["num_timesteps"])
        if steps is not None:  # a finished run continues to a larger budget
            if steps < done:
                raise ValueError(f"--steps {steps} is below the {done:,} steps {run_dir} has already trained")
            config.steps = steps
            # The greedy phase is the budget's last steps: a budget cut below it is greedy throughout, as a new run
            # with a harvest longer than its budget is.
            config.greedy_phase = min(config.greedy_phase, steps)
        phase = saved.get("consistency") or {}
        if saved.get("finished") and done >= config.steps and phase.get("num_timesteps") == done:
            # Trained and refined to this budget already: model.zip is the refined policy, nothing to redo.
            return run_dir, _load(config, run_dir / "model.zip", run_dir, trust=trust), True
        truncate_logs(run_dir, checkpoint[1]["logs"])  # the history continues from the checkpoint
    config.validate()
    run_dir = Path(resume or run_dir or config.run_dir(Path(out)))
    if resume is None and run_dir.exists() and any(run_dir.iterdir()):
        if not force:
            raise ValueError(f"{run_dir} already holds a run: continue it with --resume {run_dir}, or replace it "
                             "with --force")
        shutil.rmtree(run_dir)
    created = run_dir  # the outermost folder this run creates, removed again if the start fails
    while not created.parent.exists():
        created = created.parent
    created = created if not run_dir.exists() else None
    run_dir.mkdir(parents=True, exist_ok=True)
    try:
        env = build_env(config, run_dir, append=resume is not None)
        behaviour, prior_names, sims, priors = None, [], [], None
        if config.mode not in ("scratch", "ppo"):
            prior_names, sims, models = choose_priors(config.goal, config.env_id, env, config.priors, config.zoo,
                                                      config.embedding, trust=trust)
            priors = PriorSet(models)
            if on_priors:
                on_priors(prior_names, sims)
            horizon = (config.jsrl_horizon or guide_horizon(config.env_id, prior_names, config.zoo)
                       if config.mode == "jsrl" else 0)
            behaviour = make_options(config.mode, priors, config.alpha, config.beta, config.entropy_offset,
                                     seed=config.seed, horizon=horizon)
        if config.greedy_phase:
            behaviour = GreedyPhase(behaviour or OnPolicyBehaviour(), config.steps - config.greedy_phase,
                                    config.greedy_epsilon)
        saved_config = dict(asdict(config), chosen_priors=prior_names, similarities=sims)
        # A run whose greedy phase waits for it to be ready may train up to its budget times `extend`.
        budget = int(config.steps * config.extend) if config.ready else config.steps
        if resume is not None:
            model = _resumed_model(config, run_dir, env, behaviour, checkpoint, trust)
            remaining = max(budget - model.num_timesteps, 0)
        else:
            model = new_model(config, env, behaviour, priors)
            remaining = budget
            (run_dir / "config.yaml").write_text(yaml.safe_dump(saved_config, sort_keys=False))
    except BaseException:
        if created is not None:  # a failed start leaves nothing behind
            shutil.rmtree(created, ignore_errors=True)
        raise
    model.set_logger(run_logger(run_dir, append=resume is not None))
    harvest = None
    if config.consistency_harvest:  # a resumed run keeps what it trains from here on
        harvest = HarvestLabels(config.steps - config.consistency_harvest)
    when_ready = None
    if config.ready:
        # A resumed run keeps the phase's start; one whose phase had not begun looks at its training success afresh,
        # as does one continued to a larger budget (its phase moves to the new budget's end).
        started = checkpoint[1].get("greedy_start") if checkpoint and steps is None else None
        when_ready = StartWhenReady(behaviour, harvest, config.steps - config.greedy_phase, budget - config.greedy_phase,
                                    config.greedy_phase, config.consistency_harvest, config.ready, started=started)
    # First: it moves the phase's and the harvest's start before they act on a step.
    own: list[BaseCallback] = [when_ready] if when_ready else []
    if config.record_trajectories:
        own.append(RecordTrajectories(run_dir / "trajectories.jsonl"))
    if config.eval_every:
        own.append(EvaluateAlone(config, run_dir, append=resume is not None, upto=model.num_timesteps))
    if config.checkpoint_every:
        own.append(Checkpoint(run_dir, config.checkpoint_every, when_ready.state if when_ready else None))
    if harvest is not None:
        own.append(harvest)
    finished = True
    try:
        with sigterm_as_interrupt():
            model.learn(remaining, callback=CallbackList([*own, *(callbacks or [])]), log_interval=10,
                        reset_num_timesteps=resume is None)
    except KeyboardInterrupt:
        finished = False
    # A finished run keeps no replay buffer (a continuation starts with an empty one); an interrupted one does.
    with sigterm_as_interrupt():
        save_checkpoint(model, run_dir, with_buffer=not finished, extra=when_ready.state() if when_ready else None)
        saved_config.update(num_timesteps=int(model.num_timesteps), finished=finished)
        if when_ready is not None:
            saved_config.update(when_ready.state())  # greedy_start, as the checkpoint keeps it
        write_atomic(run_dir / "config.yaml", yaml.safe_dump(saved_config, sort_keys=False))
    env.close()
    if finished and harvest is not None:
        model, finished = _refine(config, run_dir, model, saved_config, on_round, harvest)
    return run_dir, model, finished


def _refine(config: RunConfig, run_dir: Path, model: ACER, saved_config: dict,
            on_round: Optional[Callable[[RoundStats], None]], harvest: Optional[HarvestLabels]) -> tuple[ACER, bool]:
    """
    The fit to the labels harvested from the training's last episodes, after a finished training: the fitted policy
    replaces ``model.zip`` (the trained one stays in the last checkpoint, which a resumed run continues from) and
    ``config.yaml`` records it. An interrupted fit leaves the trained ``model.zip``.
    """
    from sb3_disagree.run.consistency import greedy_validation

    validate = (greedy_validation(model, saved_config, config.consistency_validation)
                if config.consistency_validation else None)
    start = time.perf_counter()
    try:
        with sigterm_as_interrupt():
            history = greedy_consistency(model, None, 0, 0, config.consistency_epochs, seed=config.seed,
                                         on_round=on_round, harvest=harvest, validate=validate)
    except KeyboardInterrupt:  # the weights are half fitted: hand back the trained policy that model.zip holds
        return _load(config, run_dir / "model.zip", run_dir, trust=True), False  # the file this run just wrote
    with sigterm_as_interrupt():
        replace_model(model, run_dir)
        saved_config["consistency"] = {"num_timesteps": int(model.num_timesteps),
                                       "env_steps": sum(r.env_steps for r in history),
                                       "seconds": round(time.perf_counter() - start, 1),
                                       "per_round": [r.as_dict() for r in history],
                                       **({"harvest": {"labels": len(harvest.trails.labels.actions),
                                                       "episodes": harvest.trails.episodes,
                                                       "successes": harvest.trails.successes}} if harvest else {})}
        write_atomic(run_dir / "config.yaml", yaml.safe_dump(saved_config, sort_keys=False))
    return model, True


def check_resume(resume: Path, given: dict[str, Any], force: bool = False) -> None:
    """
    A resumed run keeps its saved settings: a ValueError if ``given`` names one besides the goal, the budget and the
    loop, rather than dropping it silently.

    :param resume: The run folder to continue
    :param given: The settings asked for (RunConfig's fields; ``acer_kwargs`` and ``env_kwargs`` by their keys)
    :param force: Whether replacing the run was asked for too (a contradiction)
    """
    if force:
        raise ValueError("--force replaces a run and --resume continues one: choose one")
    saved = read_config(Path(resume))
    if given.get("goal", saved["goal"]) != saved["goal"]:
        raise ValueError(f"{resume} trains the goal {saved['goal']!r}, not {given['goal']!r}")
    # The loop (overlap) is the saved one whatever is asked; steps is the new budget.
    names = [k for name, value in given.items() if name not in ("goal", "steps", "overlap")
             for k in (value if name in ("acer_kwargs", "env_kwargs") else [name])]
    if names:
        flags = ", ".join("--env" if name == "env_id" else "--" + name.replace("_", "-") for name in names)
        raise ValueError(f"--resume continues {resume} with its saved settings; drop {flags}")


def _load(config: RunConfig, path: Path, run_dir: Path, env=None, behaviour=None, trust: bool = False):
    """A run's saved model (with its envs and behaviour, to continue training), or a one-line error if damaged."""
    from sb3_disagree.loading import ModelFileError

    try:
        return load_model(asdict(config), path, env=env, behaviour=behaviour, trust=trust)
    except ModelFileError:
        raise
    except (EOFError, OSError, ValueError, KeyError, zipfile.BadZipFile, pickle.UnpicklingError) as exc:
        raise ValueError(f"{run_dir} cannot be resumed: its saved model is damaged ({exc})") from None


def _resumed_model(config: RunConfig, run_dir: Path, env, behaviour, checkpoint, trust: bool = False):
    """The model a resumed run continues: from its newest intact checkpoint, with the replay buffer it kept."""
    folder = checkpoint[0]
    model = _load(config, folder / "model.zip", run_dir, env, behaviour, trust)
    if (folder / BUFFER).exists() and isinstance(model, ACER):
        try:
            model.load_replay_buffer(folder / BUFFER)
        except (OSError, ValueError) as exc:
            raise ValueError(f"{run_dir} cannot be resumed: its replay buffer is damaged ({exc})") from None
    return model
