"""
One training run of the method: choose priors, build the behaviour, train ACER, write the run folder.

A run folder (``runs/<env>/<goal>/<mode>-<seed>/``) holds ``config.yaml``, ``model.zip``,
``progress.csv``, TensorBoard events, ``monitor/`` files, ``checkpoints/``, the model card ``README.md`` and,
when asked (``record_trajectories``), ``trajectories.jsonl`` (the recorded episodes with their per-step tags). An interrupted run saves the model and the replay buffer; a
resumed run continues the step count and appends to the run's history (monitor files, ``progress.csv``,
``evaluations.npz``), so its curves read as one run.
"""

import json
import os
import pickle
import shutil
import zipfile
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Optional

import numpy as np
import yaml
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.logger import CSVOutputFormat, Logger, make_output_format

from sb3_disagree.acer import ACER
from sb3_disagree.acer.transfer import load_prior_weights, transfer_kwargs
from sb3_disagree.checkpoints import Checkpoint, latest_checkpoint, save_checkpoint, sigterm_as_interrupt, truncate_logs
from sb3_disagree.files import safe_name, write_atomic
from sb3_disagree.options import MODES, PriorSet, make_options

from sb3_disagree.defaults import DEFAULT_ENV, EVAL_SEED_OFFSET, FINAL_EVAL_SEED_OFFSET  # noqa: F401  (re-exported)
# Kickstarting's distillation: weight 1 on every state, falling linearly to 0 at 50k env steps.
KICKSTART: dict[str, Any] = dict(distill_coef=1.0, distill_steps=50_000, distill_states="all")
# SB3's PPO for the "ppo" mode: rl-zoo3's Atari settings with the runs' 4 envs (benchmarks/hyperparams/ppo.yml);
# learning rate and clip range fall linearly to 0 over the budget, as rl-zoo3's "lin_" values.
PPO_KWARGS: dict[str, Any] = dict(n_steps=128, n_epochs=4, batch_size=256, learning_rate=2.5e-4, clip_range=0.1,
                                  ent_coef=0.01, vf_coef=0.5)
# ACER on the apartment: images through NatureCNN; a buffer of 50k frames is 0.7 GB of uint8. Rewards scaled
# by 0.1 (Q in units of the +10 goal / 10): at scale 1 the policy's entropy collapsed by 20k steps and the
# new policy alone fell back to ~0 success; at 0.1 it trains stably (docs/results.md, "Choosing ACER's scale").
ACER_KWARGS: dict[str, Any] = dict(n_steps=20, buffer_size=50_000, replay_start=2_000, replay_ratio=4, ent_coef=0.01,
                                   learning_rate=7e-4, reward_scale=0.1)


@dataclass
class RunConfig:
    """
    Everything that defines a run; saved as the run's ``config.yaml``.

    :param goal: The new goal word
    :param env_id: Gymnasium id of the environment
    :param mode: "disagreement", "room-sensor", "scratch", "finetune" (ACER from the most similar prior's weights,
        no behaviour), "kickstart" (the new policy acts alone, distilled toward the priors' mixture on every
        state with a weight annealed to zero: ``KICKSTART`` unless ``acer_kwargs`` say otherwise), "jsrl"
        (Jump-Start RL: the priors guide each episode's first steps, fewer as the new policy succeeds) or
        "ppo" (SB3's PPO from scratch, ``PPO_KWARGS``)
    :param priors: "auto" (by similarity) or the goal labels of the priors
    :param alpha: Disagreement window
    :param beta: Disagreement threshold (>= 0)
    :param entropy_offset: Entropy offset of the prior branch
    :param steps: Env steps to train
    :param seed: Seed
    :param n_envs: Parallel envs
    :param embedding: Word vectors file; None for the default
    :param zoo: Zoo folder; None for the shipped one
    :param acer_kwargs: ACER's hyperparameters
    :param env_kwargs: The environment's keyword arguments besides the goal
    :param eval_every: Evaluate the new policy alone (no priors, sampled actions) every this many env
        steps, logged as ``eval/success_rate`` and kept in ``evaluations.npz``; 0 never
    :param eval_episodes: Episodes per evaluation
    :param vec_env: "dummy" (envs stepped in this process) or "subproc" (one process per env: their
        rendering runs in parallel on several cores)
    :param overlap: ACER's replay updates in a second thread while the next segment is collected (faster
        on two cores; see ``ACER``'s ``overlap``). ``dopt train`` turns it on; off here, so that the
        experiments keep the sequential loop their figures were made with unless a cell asks for it
    :param frame_stack: The new policy sees its last this many observations (its memory; 1: the current one);
        the priors keep their single observation
    :param jsrl_horizon: Mode "jsrl": the guide's horizon at the start, in steps; 0 for the priors' mean
        episode length on their zoo cards
    :param init: "scratch" (a fresh network) or "prior" (the most similar prior's architecture and weights, as
        "finetune" does, for any mode: e.g. disagreement options with a new policy that starts as the prior)
    :param record_trajectories: Write env 0's episodes (positions and per-step tags) to ``trajectories.jsonl``, for
        the trajectory pictures (``dopt eval --trajectory``, Figure 5)
    :param checkpoint_every: Write a checkpoint (model, replay buffer, log positions) every this many env steps;
        0 only at the end
    """

    goal: str
    env_id: str = DEFAULT_ENV
    mode: str = "disagreement"
    priors: Any = "auto"
    alpha: int = 10
    beta: float = 0.1
    entropy_offset: float = 0.1
    steps: int = 100_000
    seed: int = 0
    n_envs: int = 4
    embedding: Optional[str] = None
    zoo: Optional[str] = None
    acer_kwargs: dict[str, Any] = field(default_factory=lambda: dict(ACER_KWARGS))
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    eval_every: int = 0
    eval_episodes: int = 20
    vec_env: str = "dummy"
    overlap: bool = False
    frame_stack: int = 1
    jsrl_horizon: int = 0
    checkpoint_every: int = 25_000
    init: str = "scratch"
    record_trajectories: bool = False

    def validate(self) -> None:
        self._check_types()
        safe_name(self.goal, "--goal")
        check_navigation_env(self.env_id)
        safe_name(self.env_id.replace("/", "__"), "--env")
        if self.mode not in MODES:
            raise ValueError(f"--mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        if not self.beta >= 0:
            raise ValueError(f"--beta must be >= 0 (the priors are followed while disagreement is below it), got {self.beta}")
        if self.alpha < 1:
            raise ValueError(f"--alpha must be >= 1, got {self.alpha}")
        if self.steps < 1 or self.n_envs < 1:
            raise ValueError("--steps and --n-envs must be positive")
        if self.vec_env not in ("dummy", "subproc"):
            raise ValueError(f"--vec-env must be dummy or subproc, got {self.vec_env!r}")
        if self.init not in ("scratch", "prior"):
            raise ValueError(f"--init must be scratch or prior, got {self.init!r}")
        if self.init == "prior" and self.mode in ("scratch", "ppo"):
            raise ValueError(f"--init prior starts from a prior's weights: mode {self.mode} has no priors")
        if self.checkpoint_every < 0:
            raise ValueError(f"--checkpoint-every must be >= 0, got {self.checkpoint_every}")
        if self.jsrl_horizon < 0:
            raise ValueError(f"--jsrl-horizon must be >= 0, got {self.jsrl_horizon}")
        if self.frame_stack < 1:
            raise ValueError(f"--frame-stack must be >= 1, got {self.frame_stack}")
        if self.frame_stack > 1 and self.mode == "ppo":
            raise ValueError("--frame-stack is an ACER policy's memory; --mode ppo trains SB3's PPO without it")
        if self.eval_every < 0 or self.eval_episodes < 1:
            raise ValueError("--eval-every must be >= 0 and --eval-episodes positive")

    def _check_types(self) -> None:
        """Every field of the type it is declared with (a YAML grid or a saved config can hold anything)."""
        kinds = {int: ((int,), "an integer"), float: ((int, float), "a number"), str: ((str,), "a word"),
                 bool: ((bool,), "true or false")}
        for name, spec in self.__dataclass_fields__.items():
            value = getattr(self, name)
            if str(spec.type).startswith("dict") and not isinstance(value, dict):
                raise ValueError(f"{name} must be a mapping, got {value!r}")
            if spec.type not in kinds or (name in ("embedding", "zoo") and value is None):
                continue
            allowed, what = kinds[spec.type]
            if (isinstance(value, bool) and bool not in allowed) or not isinstance(value, allowed):
                raise ValueError(f"{name} must be {what}, got {value!r}")
        if not (self.priors == "auto" or (isinstance(self.priors, (list, tuple))
                                          and all(isinstance(p, str) for p in self.priors))):
            raise ValueError(f"priors must be 'auto' or a list of goal words, got {self.priors!r}")

    def run_dir(self, out: Path) -> Path:
        return out / self.env_id.replace("/", "__") / self.goal / f"{self.mode}-{self.seed}"


def check_navigation_env(env_id: str) -> None:
    """A ValueError unless ``env_id`` is a registered goal-navigation env (one that takes ``goal=``)."""
    import gymnasium as gym

    from sb3_disagree.envs.navigation import NavigationEnv

    if env_id not in gym.registry:
        ours = ", ".join(k for k in gym.registry if k.startswith("sb3_disagree/"))
        raise ValueError(f"unknown environment {env_id!r}; this package registers {ours}")
    entry = gym.spec(env_id).entry_point
    cls = gym.envs.registration.load_env_creator(entry) if isinstance(entry, str) else entry
    if not (isinstance(cls, type) and issubclass(cls, NavigationEnv)):
        raise ValueError(f"{env_id} is not a goal-navigation environment of this package (it takes no goal); "
                         "use one of the sb3_disagree/ environments")


def choose_priors(config: RunConfig, env) -> tuple[list[str], list[float], PriorSet]:
    """The priors of a run: by similarity from the zoo, or as named; loaded and checked against the env."""
    from sb3_disagree.language import load_embedding, rank_by_similarity, select_priors
    from sb3_disagree.zoo import Zoo, ZooError

    zoo = Zoo(config.zoo)
    labels = zoo.labels(config.env_id)
    embedding = load_embedding(config.embedding)
    if config.priors == "auto":
        chosen = select_priors(config.goal, labels, embedding, k=2)
    else:
        names = list(config.priors)
        if len(names) < 2:
            raise ValueError(f"--priors needs at least two goals, got {names}")
        if len(set(names)) < len(names):
            raise ValueError(f"--priors names a goal twice: {', '.join(names)}")
        if config.goal in names:
            raise ValueError(f"--priors names the new goal {config.goal!r} itself: the priors are other goals' policies")
        missing = [n for n in names if n not in labels]
        if missing:
            raise ZooError(f"the zoo has no usable prior for {', '.join(missing)} in {config.env_id}")
        sims = dict(rank_by_similarity(config.goal, names, embedding))
        chosen = [(n, sims.get(n, 1.0)) for n in names]
    models = [zoo.load(zoo.get(name, config.env_id), env) for name, _ in chosen]
    return [n for n, _ in chosen], [s for _, s in chosen], PriorSet(models)


def algorithm_of(mode: str) -> type:
    """The SB3 algorithm class a mode trains: PPO for "ppo", ACER for every other."""
    if mode == "ppo":
        from stable_baselines3 import PPO

        return PPO
    return ACER


def new_model(config: RunConfig, env, behaviour, priors: Optional[PriorSet]):
    """The model a new run trains: ACER with the run's settings (from a prior's weights for "finetune", with
    kickstarting's distillation for "kickstart"), or SB3's PPO with ``PPO_KWARGS`` for "ppo"."""
    policy = "CnnPolicy" if len(env.observation_space.shape) == 3 else "MlpPolicy"
    if config.mode == "ppo":
        from stable_baselines3 import PPO

        kwargs = dict(PPO_KWARGS)
        lr, clip = kwargs.pop("learning_rate"), kwargs.pop("clip_range")
        return PPO(policy, env, seed=config.seed, learning_rate=lambda p: p * lr, clip_range=lambda p: p * clip,
                   **kwargs)
    acer_kwargs = dict(config.acer_kwargs)
    if config.mode == "kickstart":
        acer_kwargs = {**KICKSTART, **acer_kwargs}
    policy_kwargs = dict(acer_kwargs.pop("policy_kwargs", {}))
    from_prior = config.mode == "finetune" or config.init == "prior"
    if from_prior:  # the most similar prior's architecture, and below its weights
        policy_kwargs.update(transfer_kwargs(priors.priors[0].policy))
    if config.frame_stack > 1:
        policy_kwargs["frame_stack"] = config.frame_stack
    model = ACER(policy, env, seed=config.seed, behaviour=behaviour, overlap=config.overlap,
                 policy_kwargs=policy_kwargs, **acer_kwargs)
    if from_prior:
        load_prior_weights(model.policy, priors.priors[0].policy)
    return model


def guide_horizon(config: RunConfig, prior_names: list[str]) -> int:
    """The priors' mean episode length on their own goals (their cards' sampled evaluation): where JSRL's guide
    horizon starts."""
    from sb3_disagree.zoo import Zoo

    zoo = Zoo(config.zoo)
    lengths = [zoo.get(name, config.env_id).card.evaluation.get("mean_length") for name in prior_names]
    lengths = [x for x in lengths if x]
    if not lengths:
        raise ValueError("the priors' cards record no evaluation to take JSRL's horizon from; give jsrl_horizon")
    return max(1, int(round(float(np.mean(lengths)))))


class RecordTrajectories(BaseCallback):
    """Write each episode of env 0 as a JSON line: positions after each step, their tags, success."""

    def __init__(self, path: Path, every: int = 1) -> None:
        super().__init__()
        self.path, self.every = path, every
        self.positions: list = []
        self.tags: list = []
        self.episodes = 0

    def _on_step(self) -> bool:
        infos, dones = self.locals["infos"], self.locals["dones"]
        tags = self.locals.get("tags")
        info = infos[0]
        if "position" in info:
            self.positions.append(list(info["position"]))
            self.tags.append(str(tags[0]) if tags is not None else "explore")
        if dones[0]:
            self.episodes += 1
            if self.episodes % self.every == 0:
                self._write(complete=True, success=bool(info.get("is_success", False)))
            self.positions, self.tags = [], []
        return True

    def _on_training_end(self) -> None:
        self._write(complete=False, success=False)  # the episode under way, so a short run still shows its path

    def _write(self, complete: bool, success: bool) -> None:
        if not self.positions:
            return
        record = {"timesteps": self.num_timesteps, "complete": complete, "success": success,
                  "positions": self.positions, "tags": self.tags}
        with open(self.path, "a") as f:
            f.write(json.dumps(record) + "\n")


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


class AppendingCSVOutputFormat(CSVOutputFormat):
    """``progress.csv`` of a resumed run: the earlier rows stay, new rows follow (SB3's format truncates)."""

    def __init__(self, filename: str):
        self.file = open(filename, "r+")
        header = self.file.readline().rstrip("\n")
        self.keys = header.split(",") if header else []
        self.file.seek(0, os.SEEK_END)
        self.separator = ","
        self.quotechar = '"'


def run_logger(run_dir: Path, append: bool) -> Logger:
    """CSV and TensorBoard logs in the run folder; a resumed run appends to its ``progress.csv``."""
    progress = run_dir / "progress.csv"
    csv = AppendingCSVOutputFormat(str(progress)) if append and progress.exists() else CSVOutputFormat(str(progress))
    return Logger(str(run_dir), [csv, make_output_format("tensorboard", str(run_dir))])


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
        from sb3_disagree.prior_training import evaluate

        if self.env is None:
            self.env = build_env(self.config, None, n_envs=min(self.config.n_envs, 4),
                                 seed=self.config.seed + EVAL_SEED_OFFSET, vec_env="dummy")
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


def train(config: RunConfig, out: Path = Path("runs"), resume: Optional[Path] = None,
          callbacks: Optional[list[BaseCallback]] = None, on_priors: Optional[Callable[[list, list], None]] = None,
          run_dir: Optional[Path] = None, steps: Optional[int] = None, force: bool = False) -> tuple[Path, ACER, bool]:
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
    :return: The run folder, the model, and whether training finished (False when interrupted)
    """
    checkpoint = None
    if resume is not None:
        run_dir = Path(resume)
        if not (run_dir / "config.yaml").exists() or not (run_dir / "model.zip").exists():
            raise FileNotFoundError(f"{run_dir} is not a run folder with config.yaml and model.zip to resume")
        saved = yaml.safe_load((run_dir / "config.yaml").read_text())
        config = RunConfig(**{k: v for k, v in saved.items() if k in RunConfig.__dataclass_fields__})
        checkpoint = latest_checkpoint(run_dir)
        done = checkpoint[1]["num_timesteps"] if checkpoint else int(saved.get("num_timesteps") or 0)
        if steps is not None:  # a finished run continues to a larger budget
            if steps < done:
                raise ValueError(f"--steps {steps} is below the {done:,} steps {run_dir} has already trained")
            config.steps = steps
        if checkpoint is not None:  # the history continues from the checkpoint: what came after it is cut
            truncate_logs(run_dir, checkpoint[1]["logs"])
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
            prior_names, sims, priors = choose_priors(config, env)
            if on_priors:
                on_priors(prior_names, sims)
            horizon = config.jsrl_horizon or guide_horizon(config, prior_names) if config.mode == "jsrl" else 0
            behaviour = make_options(config.mode, priors, config.alpha, config.beta, config.entropy_offset,
                                     seed=config.seed, horizon=horizon)
        saved_config = dict(asdict(config), chosen_priors=prior_names, similarities=sims)
        if resume is not None:
            model = _resumed_model(config, run_dir, env, behaviour, checkpoint)
            remaining = max(config.steps - model.num_timesteps, 0)
        else:
            model = new_model(config, env, behaviour, priors)
            remaining = config.steps
            (run_dir / "config.yaml").write_text(yaml.safe_dump(saved_config, sort_keys=False))
    except BaseException:
        if created is not None:  # a failed start leaves nothing behind
            shutil.rmtree(created, ignore_errors=True)
        raise
    model.set_logger(run_logger(run_dir, append=resume is not None))
    own: list[BaseCallback] = []
    if config.record_trajectories:
        own.append(RecordTrajectories(run_dir / "trajectories.jsonl"))
    if config.eval_every:
        own.append(EvaluateAlone(config, run_dir, append=resume is not None, upto=model.num_timesteps))
    if config.checkpoint_every:
        own.append(Checkpoint(run_dir, config.checkpoint_every))
    finished = True
    try:
        with sigterm_as_interrupt():
            model.learn(remaining, callback=CallbackList([*own, *(callbacks or [])]), log_interval=10,
                        reset_num_timesteps=resume is None)
    except KeyboardInterrupt:
        finished = False
    # A finished run keeps no replay buffer (a continuation starts with an empty one); an interrupted one does.
    with sigterm_as_interrupt():
        save_checkpoint(model, run_dir, with_buffer=not finished)
        saved_config.update(num_timesteps=int(model.num_timesteps), finished=finished)
        write_atomic(run_dir / "config.yaml", yaml.safe_dump(saved_config, sort_keys=False))
    if (run_dir / "replay_buffer.pkl").exists():  # left by a version that kept it beside the model
        os.remove(run_dir / "replay_buffer.pkl")
    env.close()
    return run_dir, model, finished


def _resumed_model(config: RunConfig, run_dir: Path, env, behaviour, checkpoint):
    """The model a resumed run continues: from its newest complete checkpoint (with the replay buffer it kept),
    else from ``model.zip`` (and a ``replay_buffer.pkl`` beside it, as earlier versions left them)."""
    folder = checkpoint[0] if checkpoint else run_dir
    try:
        if config.mode == "ppo":
            model = algorithm_of(config.mode).load(folder / "model.zip", env=env)
        else:
            model = ACER.load(folder / "model.zip", env=env, behaviour=behaviour, overlap=config.overlap)
        if (folder / "replay_buffer.pkl").exists() and isinstance(model, ACER):
            model.load_replay_buffer(folder / "replay_buffer.pkl")
    except (EOFError, OSError, zipfile.BadZipFile, pickle.UnpicklingError) as exc:
        raise ValueError(f"{run_dir} cannot be resumed: its saved model or replay buffer is damaged ({exc})") from None
    return model


def write_card(run_dir: Path, model, episodes: int, command: str = "") -> dict[str, Any]:
    """
    Evaluate a run's policy alone greedy and sampled (``episodes`` each, env seeds the run never trained on;
    none when 0) and write its model card (``README.md``) beside ``model.zip``.

    :return: The evaluations by label ("greedy", "sampled")
    """
    from sb3_disagree.model_card import write_model_card

    config = yaml.safe_load((Path(run_dir) / "config.yaml").read_text())
    seed = config["seed"] + FINAL_EVAL_SEED_OFFSET
    evaluations = {label: evaluate_alone(model, config, episodes, label == "greedy", seed)
                   for label in ("greedy", "sampled")} if episodes > 0 else {}
    write_model_card(run_dir, config, type(model).__name__, evaluations, command)
    return evaluations


def evaluate_alone(model: ACER, config: dict[str, Any], episodes: int, deterministic: bool, seed: int):
    """
    The new policy alone (no priors) in its run's task, on 4 envs seeded from ``seed``.

    :param model: The trained model
    :param config: The run's configuration (a saved ``config.yaml`` or ``asdict(RunConfig)``): env and goal
    :param episodes: Number of episodes
    :param deterministic: Greedy actions if True, sampled otherwise
    :param seed: Seed of the first env
    :return: The :class:`~sb3_disagree.prior_training.Evaluation`
    """
    from sb3_disagree.prior_training import evaluate, make_env
    from sb3_disagree.zoo import space_fits, space_to_dict

    env = make_env(config["env_id"], config["goal"], config.get("env_kwargs") or {}, n_envs=4, seed=seed)
    try:
        for kind in ("observation", "action"):
            theirs = getattr(model, f"{kind}_space")
            if not space_fits(space_to_dict(theirs), getattr(env, f"{kind}_space")):
                raise ValueError(f"the model acts on {kind}s {space_to_dict(theirs)}, but {config['env_id']} gives "
                                 f"{space_to_dict(getattr(env, f'{kind}_space'))}: it was trained elsewhere")
        return evaluate(model, env, episodes, deterministic=deterministic)
    finally:
        env.close()
