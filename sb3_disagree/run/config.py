"""A run's configuration: ``RunConfig`` (saved as the run's ``config.yaml``) and the defaults of each mode."""

import typing
from dataclasses import MISSING, dataclass, field
from pathlib import Path
from typing import Any, Optional

from sb3_disagree.defaults import DEFAULT_ENV
from sb3_disagree.files import safe_name
from sb3_disagree.options import MODES
from sb3_disagree.run.presets import (RESOLVED, acer_defaults, acer_parameters, acer_signature_defaults, preset, resolve,
                                      trained_with)

# Each mode's settings live in hyperparams/modes.yml (run/presets.py); these names read them.
KICKSTART: dict[str, Any] = {k: v for k, v in preset("kickstart", "acer").items() if k.startswith("distill")}
PPO_KWARGS: dict[str, Any] = preset("ppo", "ppo")
ACER_KWARGS: dict[str, Any] = preset("all", "acer")
MAX_STEPS = 10**9  # a budget beyond this is a typo: a billion env steps is weeks on the machines this runs on


@dataclass
class RunConfig:
    """
    Everything that defines a run; saved, resolved, as the run's ``config.yaml``. A setting left at None comes from
    the mode's preset (``hyperparams/modes.yml``, :mod:`sb3_disagree.run.presets`): ``RunConfig(goal=G)`` is what
    ``dopt train --goal G`` runs. The fields, by what they are for:

    **The run**

    :param goal: The new goal word
    :param env_id: Gymnasium id of the environment (a goal-navigation env of this package)
    :param mode: "kickstart" (the default: the new policy acts alone and is distilled toward the priors' mixture),
        "disagreement" (the paper's disagreement options), "disagreement-distill" (the same, distilled toward the
        priors' mixture as kickstarting is), "room-sensor" (the oracle gate), "jsrl"
        (the priors guide each episode's first steps), "finetune" (ACER from the nearest prior's weights),
        "scratch" (ACER alone) or "ppo" (SB3's PPO alone); README's table says what each measured
    :param priors: "auto" (the two nearest the goal in the embedding) or the goal labels of the priors
    :param steps: Env steps to train
    :param seed: Seed of the policy and the envs
    :param n_envs: Parallel envs

    **The method**

    :param alpha: Disagreement window
    :param beta: Follow the priors while the window's mean disagreement is below this (>= 0)
    :param entropy_offset: Enter the prior branch when ``U(0, 1) < H(pi) - entropy_offset``
    :param jsrl_horizon: Mode "jsrl": the guide's horizon at the start, in steps; 0 for the priors' mean
        episode length on their zoo cards
    :param init: "scratch" (a fresh network) or "prior" (the nearest prior's architecture and weights, for any mode)
    :param zoo: Zoo folder, "greedy" or "user"; None for the shipped one
    :param embedding: Word vectors file; None for the default (MiniLM)

    **Memory**

    :param frame_stack: The new policy sees its last this many observations (1: the current one); each prior keeps
        the input it was trained on
    :param loop_flags: The new policy's CNN sees the newest frame, and flags say whether it equals each older frame
        of its stack (pressed against a wall, turning back and forth; ``LoopFlagsCNN``); needs images

    **The finish** (what makes the handed-over policy work greedily on its own; its defaults:
    ``hyperparams/modes.yml``'s ``finish``)

    :param finish: Give the mode the finish: memory as loop flags (on images), a moving average of the weights to
        act with (``ema_decay``), the greedy phase and the validated fit to the harvest; ppo gets the harvest's
        validated fit, which acts through ``predict`` (False: the mode bare, as the paper's figures ran; None: True)
    :param consistency_harvest: ``model.zip`` is fitted to the loop-free paths of the training's own successful
        episodes over its last this many env steps (all of them if the budget is smaller; no env step more; 0: none)
    :param greedy_phase: The last this many env steps act by the new policy's argmax (``greedy_epsilon`` of its own
        samples), so that the harvested paths are those the saved argmax walks (0: none)
    :param greedy_epsilon: The policy's own weight in the behaviour during the greedy phase, in (0, 1]
    :param ready: The greedy phase starts at its step only if the training success over the last 100 episodes has
        reached this by then; otherwise the run trains on until it has (or until its budget times ``extend`` less the
        phase), then the phase runs its steps: a goal slow to learn gets more env steps (0: the phase never waits)
    :param extend: The most a run's budget may grow while its greedy phase waits, as a multiple of ``steps`` (>= 1)
    :param consistency_epochs: Passes over the harvest's labels
    :param consistency_validation: The fit keeps the epoch whose greedy success over this many validation episodes
        (env seeds of their own, cut at ``VALIDATION_MAX_STEPS``) is highest (0: the last epoch's)

    **ACER**

    :param acer_kwargs: ACER's keyword arguments on top of the mode's (``presets.acer_defaults``)
    :param overlap: ACER's replay updates in a second thread while the next segment is collected (faster on two
        cores); the experiments' grids pin the sequential loop their figures were made with
    :param vec_env: "dummy" (envs stepped in this process) or "subproc" (one process per env)

    **The environment**

    :param env_kwargs: The environment's keyword arguments besides the goal

    **Evaluation and logging**

    :param eval_every: Evaluate the new policy alone, greedy and sampled, every this many env steps (0: never),
        logged as ``eval/success_rate`` and kept in ``evaluations.npz``
    :param eval_episodes: Episodes per evaluation
    :param checkpoint_every: Write a checkpoint (model, replay buffer, log positions) every this many env steps;
        0 only at the end
    :param record_trajectories: Write env 0's training episodes (positions and per-step tags) to
        ``trajectories.jsonl`` (Figure 5)
    """

    goal: str
    env_id: str = DEFAULT_ENV
    mode: str = "kickstart"
    priors: Any = "auto"
    steps: int = 100_000
    seed: int = 0
    n_envs: int = 4
    alpha: int = 10
    beta: float = 0.1
    entropy_offset: float = 0.1
    jsrl_horizon: int = 0
    init: str = "scratch"
    zoo: Optional[str] = None
    embedding: Optional[str] = None
    frame_stack: Optional[int] = None
    loop_flags: Optional[bool] = None
    finish: Optional[bool] = None
    consistency_harvest: Optional[int] = None
    greedy_phase: Optional[int] = None
    greedy_epsilon: float = 0.2
    ready: Optional[float] = None
    extend: Optional[float] = None
    consistency_epochs: int = 3
    consistency_validation: Optional[int] = None
    acer_kwargs: dict[str, Any] = field(default_factory=dict)
    overlap: Optional[bool] = None
    vec_env: str = "dummy"
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    eval_every: int = 0
    eval_episodes: int = 20
    checkpoint_every: int = 25_000
    record_trajectories: bool = False

    def __post_init__(self) -> None:
        # What is not given comes from the mode's preset (hyperparams/modes.yml); anything mistyped, validate() says.
        if isinstance(self.acer_kwargs, dict) and self.mode in MODES:
            names = ("mode", "steps", "acer_kwargs", *RESOLVED)
            resolved = resolve({k: getattr(self, k) for k in names}, image_observations(self.env_id)
                               if isinstance(self.env_id, str) else False)
            for name in names:
                setattr(self, name, resolved[name])

    @classmethod
    def of_saved(cls, saved: dict[str, Any]) -> "RunConfig":
        """The configuration in a run's ``config.yaml`` (read as a mapping), without what the run added to it
        (the chosen priors, their similarities, the steps taken). A setting the saved run does not name ran at
        what the library had then: ``presets.RESOLVED``, and ACER's own default for an ACER setting."""
        defaults = {k: f.default for k, f in cls.__dataclass_fields__.items() if f.default is not MISSING}
        fields = {k: v for k, v in trained_with(saved, defaults).items() if k in cls.__dataclass_fields__}
        return cls(**fields)

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
        if not 0 <= self.ready <= 1 or not 1 <= self.extend <= 10:
            raise ValueError(f"--ready must be in [0, 1] and --extend between 1 and 10, got {self.ready} and {self.extend}")
        if self.ready and not self.greedy_phase:
            raise ValueError("--ready decides when the greedy phase starts: give --greedy-phase too (or --ready 0)")
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
        if self.mode == "ppo":  # ACER's settings beyond the defaults (--reward-scale, --ema-decay) would be ignored
            # (a ppo run saved before ppo kept none of them recorded the defaults of then: those pass)
            defaults = {**acer_signature_defaults(), **acer_defaults("all", False, self.overlap)}
            given = [k for k, v in self.acer_kwargs.items() if defaults.get(k) != v]
            if given:
                flags = ", ".join("--" + k.replace("_", "-") for k in given)
                raise ValueError(f"{flags}: settings of ACER; --mode ppo trains SB3's PPO without them")
        unknown = sorted(set(self.acer_kwargs) - acer_parameters())
        if unknown:
            raise ValueError(f"unknown ACER settings {', '.join(map(str, unknown))}: ACER takes "
                             f"{', '.join(sorted(acer_parameters()))}")
        from sb3_disagree.acer import ACER

        try:  # ACER's own check, before anything is written; its message names the setting as the CLI spells it
            ACER.check_settings(**{**self.acer_kwargs, "overlap": self.overlap})
        except ValueError as exc:
            name, rest = str(exc).split(" ", 1)
            raise ValueError(f"--{name.replace('_', '-')} {rest}") from None
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
            kind = spec.type
            if typing.get_origin(kind) is typing.Union:  # Optional[T]: None where not given (the preset's, resolved)
                if value is None:
                    continue
                kind = next(t for t in typing.get_args(kind) if t is not type(None))
            if kind not in kinds:
                continue
            allowed, what = kinds[kind]
            if (isinstance(value, bool) and bool not in allowed) or not isinstance(value, allowed):
                raise ValueError(f"{name} must be {what}, got {value!r}")
        if not (self.priors == "auto" or (isinstance(self.priors, (list, tuple))
                                          and all(isinstance(p, str) for p in self.priors))):
            raise ValueError(f"priors must be 'auto' or a list of goal words, got {self.priors!r}")

    def run_dir(self, out: Path) -> Path:
        return out / self.env_id.replace("/", "__") / self.goal / f"{self.mode}-{self.seed}"


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


