"""A run's configuration: ``RunConfig`` (saved as the run's ``config.yaml``) and the defaults of each mode."""

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

from sb3_disagree.defaults import DEFAULT_ENV
from sb3_disagree.files import safe_name
from sb3_disagree.options import MODES

# Kickstarting's distillation: weight 1 on every state, falling linearly to 0 at 50k env steps.
KICKSTART: dict[str, Any] = dict(distill_coef=1.0, distill_steps=50_000, distill_states="all")
# SB3's PPO for the "ppo" mode: rl-zoo3's Atari settings with the runs' 4 envs (sb3_disagree/hyperparams/ppo.yml);
# learning rate and clip range fall linearly to 0 over the budget, as rl-zoo3's "lin_" values.
PPO_KWARGS: dict[str, Any] = dict(n_steps=128, n_epochs=4, batch_size=256, learning_rate=2.5e-4, clip_range=0.1,
                                  ent_coef=0.01, vf_coef=0.5)
# ACER on the apartment: images through NatureCNN; a buffer of 50k frames is 0.7 GB of uint8. Rewards scaled
# by 0.1 (Q in units of the +10 goal / 10): at scale 1 the policy's entropy collapsed by 20k steps and the
# new policy alone fell back to ~0 success; at 0.1 it trains stably (docs/history.md, "Choosing ACER's scale").
ACER_KWARGS: dict[str, Any] = dict(n_steps=20, buffer_size=50_000, replay_start=2_000, replay_ratio=4, ent_coef=0.01,
                                   learning_rate=7e-4, reward_scale=0.1)
# A mode's own ACER settings on top of ACER_KWARGS. Kickstarting: rewards at full scale (the entropy bonus ten times
# weaker against them, so the argmax is a real choice) and the saved model acting with a moving average of the
# weights (0.999 per update); over five seeds at 100k the policy alone went from 0.16 to 0.68 greedy on bathtub
# and 0.18 to 0.47 on nightstand, sampled 0.98 -> 0.99 and 0.98 -> 0.94 (docs/results.md).
MODE_ACER_KWARGS: dict[str, dict[str, Any]] = {"kickstart": dict(reward_scale=1.0, ema_decay=0.999)}
# dopt train's consistency_harvest for kickstarting, its default mode: the last 30k training steps are a greedy phase
# (the current weights' argmax, epsilon 0.2 of their samples) and model.zip is fitted to the loop-free paths of their
# successful episodes (no env step more, 12-28 s of fitting). Over five seeds a task at 100k, with loop flags, the
# policy alone reached 0.93 greedy on bathtub and 0.86 on nightstand with the harvest sampled from the moving average,
# and 0.95 and 0.92 acted greedily by the current weights, sampled 1.00 and 0.99 (docs/history.md).
DOPT_TRAIN_HARVEST = 30_000
# dopt train's memory for a new kickstarting run on images: three frames, seen as the newest frame and two loop flags
# (LoopFlagsCNN). Over five seeds a task at 100k, with the harvest, the policy alone went from 0.77
# to 0.93 greedy on bathtub and from 0.61 to 0.86 on nightstand, sampled 1.00 and 0.99 (docs/history.md).
DOPT_TRAIN_FRAME_STACK = 3
# dopt train's consistency_validation for a new kickstarting run: the harvest's fit keeps, of its epochs, the one whose
# greedy success over this many validation episodes is highest. One more epoch on the same labels moved a run's
# greedy success from 0.92 to 0.75 (docs/method.md, "A validated fit").
DOPT_TRAIN_VALIDATION = 40


MAX_STEPS = 10**9  # a budget beyond this is a typo: a billion env steps is weeks on the machines this runs on


def acer_defaults(mode: str) -> dict[str, Any]:
    """ACER's settings for a mode when a run names none: ``ACER_KWARGS`` with the mode's own on top."""
    return {**ACER_KWARGS, **MODE_ACER_KWARGS.get(mode, {})}


@dataclass
class RunConfig:
    """
    Everything that defines a run; saved as the run's ``config.yaml``.

    :param goal: The new goal word
    :param env_id: Gymnasium id of the environment
    :param mode: "kickstart" (the default: the new policy acts alone, distilled toward the priors' mixture on every
        state with a weight annealed to zero, ``KICKSTART`` unless ``acer_kwargs`` say otherwise; of the modes
        measured, the one whose saved policy works best on its own, docs/results.md), "disagreement" (the
        paper's disagreement options), "room-sensor", "scratch", "finetune" (ACER from the most similar prior's
        weights, no behaviour), "jsrl"
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
    :param zoo: Zoo folder, or "greedy" for the shipped greedy zoo; None for the shipped one
    :param acer_kwargs: ACER's hyperparameters, on top of the mode's defaults (``acer_defaults(mode)``); the
        saved config holds them all
    :param env_kwargs: The environment's keyword arguments besides the goal
    :param eval_every: Evaluate the new policy alone (no priors, sampled actions) every this many env
        steps, logged as ``eval/success_rate`` and kept in ``evaluations.npz``; 0 never
    :param eval_episodes: Episodes per evaluation
    :param vec_env: "dummy" (envs stepped in this process) or "subproc" (one process per env: their
        rendering runs in parallel on several cores)
    :param overlap: ACER's replay updates in a second thread while the next segment is collected (faster on two
        cores). Off in the library and the experiments (the sequential loop their figures were made with); on in
        dopt train
    :param frame_stack: The new policy sees its last this many observations (its memory; 1: the current one; dopt
        train: ``DOPT_TRAIN_FRAME_STACK`` with loop flags for a new kickstarting run on images);
        each prior keeps the input it was trained on (its own stack if it has memory, else the observation)
    :param loop_flags: The new policy's CNN sees the newest frame only, and the older frames of its stack give it
        flags instead: whether the newest frame equals each of them (pressed against a wall, turning back and forth;
        ``LoopFlagsCNN``). Needs ``frame_stack`` >= 2 and image observations (dopt train: on, with
        ``DOPT_TRAIN_FRAME_STACK`` frames, for a new kickstarting run on images)
    :param jsrl_horizon: Mode "jsrl": the guide's horizon at the start, in steps; 0 for the priors' mean
        episode length on their zoo cards
    :param init: "scratch" (a fresh network) or "prior" (the most similar prior's architecture and weights, as
        "finetune" does, for any mode: e.g. disagreement options with a new policy that starts as the prior)
    :param record_trajectories: Write env 0's episodes (positions and per-step tags) to ``trajectories.jsonl``, for
        the trajectory pictures (``dopt eval --trajectory``, Figure 5)
    :param greedy_phase: The last this many env steps of the budget act by the new policy's argmax (with
        probability greedy_epsilon a sample of it instead): the states where the greedy policy gets stuck are
        visited and learned from (0: no such phase; dopt train: the harvest's steps for a new kickstarting run, so
        that the harvested paths are the ones the saved model's argmax walks)
    :param greedy_epsilon: The policy's own weight in the behaviour during the greedy phase, in (0, 1]
    :param checkpoint_every: Write a checkpoint (model, replay buffer, log positions) every this many env steps;
        0 only at the end
    :param consistency_harvest: ``model.zip`` is fitted to the loop-free paths of the training's own successful
        episodes over its last this many env steps (all of them if the budget is smaller; no env step more; 0: none;
        dopt train: ``DOPT_TRAIN_HARVEST`` for mode kickstart)
    :param consistency_epochs: Passes over the labels in the harvest's fit
    :param consistency_validation: The harvest's fit is validated after every epoch, the new
        policy acting greedily for this many episodes (env seeds of their own, cut at ``VALIDATION_MAX_STEPS``), and
        keeps the weights of the epoch that validates best (0: none, the last epoch's; dopt train:
        ``DOPT_TRAIN_VALIDATION`` for mode kickstart)
    """

    goal: str
    env_id: str = DEFAULT_ENV
    mode: str = "kickstart"
    priors: Any = "auto"
    alpha: int = 10
    beta: float = 0.1
    entropy_offset: float = 0.1
    steps: int = 100_000
    seed: int = 0
    n_envs: int = 4
    embedding: Optional[str] = None
    zoo: Optional[str] = None
    acer_kwargs: dict[str, Any] = field(default_factory=dict)
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    eval_every: int = 0
    eval_episodes: int = 20
    vec_env: str = "dummy"
    overlap: bool = False
    frame_stack: int = 1
    loop_flags: bool = False
    jsrl_horizon: int = 0
    checkpoint_every: int = 25_000
    init: str = "scratch"
    record_trajectories: bool = False
    greedy_phase: int = 0
    greedy_epsilon: float = 0.2
    consistency_harvest: int = 0
    consistency_epochs: int = 3
    consistency_validation: int = 0

    def __post_init__(self) -> None:
        if isinstance(self.acer_kwargs, dict) and isinstance(self.mode, str):  # anything else: validate() says so
            self.acer_kwargs = {**acer_defaults(self.mode), **self.acer_kwargs}

    @classmethod
    def of_saved(cls, saved: dict[str, Any]) -> "RunConfig":
        """The configuration in a run's ``config.yaml`` (read as a mapping), without what the run added to it
        (the chosen priors, their similarities, the steps taken)."""
        return cls(**{k: v for k, v in saved.items() if k in cls.__dataclass_fields__})

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
        if not 1 <= self.steps <= MAX_STEPS or not 1 <= self.n_envs <= 256:
            raise ValueError(f"--steps must be between 1 and {MAX_STEPS:,} and --n-envs between 1 and 256, got "
                             f"{self.steps:,} and {self.n_envs}")
        if not 0 <= self.seed < 2**32:
            raise ValueError(f"--seed must be between 0 and 2**32 - 1 (numpy's seeds), got {self.seed}")
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
        if self.loop_flags and self.frame_stack < 2:
            raise ValueError("--loop-flags compares the newest frame with older ones: give --frame-stack 2 or more")
        if self.loop_flags and not image_observations(self.env_id):
            raise ValueError("--loop-flags compares frames: the env's observations must be images")
        if not 0 <= self.greedy_phase <= self.steps or not 0 < self.greedy_epsilon <= 1:
            raise ValueError("--greedy-phase must be between 0 and --steps and --greedy-epsilon in (0, 1], got "
                             f"{self.greedy_phase} and {self.greedy_epsilon}")
        if self.greedy_phase and self.mode == "ppo":
            raise ValueError("--greedy-phase is a behaviour of ACER; --mode ppo trains SB3's PPO without one")
        if self.consistency_epochs < 1:
            raise ValueError(f"--consistency-epochs must be >= 1, got {self.consistency_epochs}")
        if self.consistency_harvest < 0:
            raise ValueError(f"--consistency-harvest must be >= 0, got {self.consistency_harvest}")
        if self.consistency_validation < 0:
            raise ValueError(f"--consistency-validation must be >= 0, got {self.consistency_validation}")
        if self.consistency_validation and not self.consistency_harvest:
            raise ValueError("--consistency-validation validates the harvest's fit: give --consistency-harvest too")
        if self.consistency_harvest and self.mode == "ppo":
            raise ValueError("--consistency-harvest refines an ACER policy; --mode ppo trains SB3's PPO")
        if self.mode == "ppo":  # ACER's settings beyond the defaults (--reward-scale, --ema-decay) would be ignored
            given = [k for k, v in self.acer_kwargs.items() if acer_defaults(self.mode).get(k) != v]
            if given:
                flags = ", ".join("--" + k.replace("_", "-") for k in given)
                raise ValueError(f"{flags}: settings of ACER; --mode ppo trains SB3's PPO without them")
        unknown = sorted(set(self.acer_kwargs) - acer_parameters())
        if unknown:
            raise ValueError(f"unknown ACER settings {', '.join(map(str, unknown))}: ACER takes "
                             f"{', '.join(sorted(acer_parameters()))}")
        reward_scale = self.acer_kwargs.get("reward_scale", 1.0)
        if isinstance(reward_scale, bool) or not isinstance(reward_scale, (int, float)) or not reward_scale > 0:
            raise ValueError(f"--reward-scale must be a number > 0, got {reward_scale!r}")
        if self.acer_kwargs.get("features_dtype") not in (None, "float32", "bfloat16"):
            raise ValueError(f"--features-dtype must be float32 or bfloat16, got {self.acer_kwargs['features_dtype']!r}")
        if self.acer_kwargs.get("average_ahead") and not self.overlap:
            raise ValueError("--average-ahead computes the replays' reference while the worker replays: it needs "
                             "the overlapped loop (drop --no-overlap)")
        ema_decay = self.acer_kwargs.get("ema_decay", 0.0)
        if isinstance(ema_decay, bool) or not isinstance(ema_decay, (int, float)) or not 0 <= ema_decay < 1:
            raise ValueError(f"--ema-decay must be a number in [0, 1), got {ema_decay!r}")
        if self.eval_every < 0 or self.eval_episodes < 1:
            raise ValueError("--eval-every must be >= 0 and --eval-episodes positive")
        penalty = self.env_kwargs.get("collision_penalty", 0.0)
        if isinstance(penalty, bool) or not isinstance(penalty, (int, float)) or not penalty >= 0:
            raise ValueError(f"--collision-penalty must be a number >= 0, got {penalty!r}")
        if self.env_kwargs.get("reward_distance", "euclidean") not in ("euclidean", "geodesic"):
            raise ValueError(f"--reward-distance must be euclidean or geodesic, got {self.env_kwargs['reward_distance']!r}")

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


def acer_parameters() -> set[str]:
    """The keyword arguments ACER takes beyond the policy, the env and what a run sets itself."""
    import inspect

    from sb3_disagree.acer import ACER

    return set(inspect.signature(ACER.__init__).parameters) - {"self", "policy", "env", "behaviour", "seed", "overlap",
                                                                "kwargs", "_init_setup_model", "device"}


def image_observations(env_id: str) -> bool:
    """Whether the registered env ``env_id`` observes images (False for an unknown id: validation says so)."""
    import gymnasium as gym

    try:
        return gym.spec(env_id).kwargs.get("obs") == "rgb"
    except gym.error.Error:
        return False


def check_navigation_env(env_id: str) -> None:
    """A ValueError unless ``env_id`` is a registered goal-navigation env (one that takes ``goal=``)."""
    import gymnasium as gym

    from sb3_disagree.envs.navigation import NavigationEnv

    from sb3_disagree.envs.vec import check_env_id

    check_env_id(env_id)
    entry = gym.spec(env_id).entry_point
    cls = gym.envs.registration.load_env_creator(entry) if isinstance(entry, str) else entry
    if not (isinstance(cls, type) and issubclass(cls, NavigationEnv)):
        raise ValueError(f"{env_id} is not a goal-navigation environment of this package (it takes no goal); "
                         "use one of the sb3_disagree/ environments")


