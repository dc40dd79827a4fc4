"""
The prior zoo: a folder of saved SB3 policies, each labelled with the goal it reaches.

Layout: ``<root>/<env-id>/<goal>/model.zip`` (a standard SB3 model file) and ``card.json`` (what the
prior is, how it was made and how well it does). The env id's "/" becomes "__" in the folder name.
Listing never raises: an entry whose card or file is damaged is reported with its problem, and
refused when loaded. Writes go to a temporary folder that is renamed into place.
"""

import datetime as _dt
import json
import os
import shutil
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Optional, Union

from gymnasium import spaces

from sb3_disagree.files import write_atomic
from sb3_disagree.loading import (DISTRIBUTION_CLASSES, ModelFileError, algorithm_class, check_model_file,  # noqa: F401
                                   identify_algorithm, known_algorithm, load, register_algorithm, sha256_of,
                                   trust_list)

CARD = "card.json"
MODEL = "model.zip"
_PACKAGE = Path(__file__).resolve().parent.parent
# The shipped zoos: the repository's zoo/ folder, which the wheel carries as the package's own zoo/.
SHIPPED = _PACKAGE / "zoo" if (_PACKAGE / "zoo").is_dir() else _PACKAGE.parent / "zoo"
DEFAULT_ZOO = SHIPPED / "default"
# Zoos shipped beside it, by the name that --zoo accepts: "greedy", the priors made to work alone greedily (DAgger with
# loop flags, then the greedy-consistency phase; docs/zoo.md).
SHIPPED_ZOOS = {"greedy": SHIPPED / "greedy"}


def user_zoo() -> Path:
    """
    The zoo that the commands which write a prior use unless told otherwise (the shipped zoos are read-only):
    ``$SB3_DISAGREE_ZOO``, else ``$XDG_DATA_HOME/sb3-disagree/zoo`` (``~/.local/share/sb3-disagree/zoo``).
    """
    if os.environ.get("SB3_DISAGREE_ZOO"):
        return Path(os.environ["SB3_DISAGREE_ZOO"])
    return Path(os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share") / "sb3-disagree" / "zoo"


def zoo_root(root: Optional[Union[str, Path]] = None) -> Path:
    """
    The folder of a zoo: the shipped zoo for None; a shipped zoo's name (``SHIPPED_ZOOS``), or "user" for
    :func:`user_zoo`, unless a folder of that name exists where the name is read; else the folder itself.
    """
    if root is None:
        return DEFAULT_ZOO
    if str(root) in (*SHIPPED_ZOOS, "user") and not Path(root).exists():
        return user_zoo() if str(root) == "user" else SHIPPED_ZOOS[str(root)]
    return Path(root)


def is_shipped(root: Path) -> bool:
    """Whether a folder is one of the zoos the package ships (read-only for the commands)."""
    try:
        return Path(root).resolve() in {z.resolve() for z in (DEFAULT_ZOO, *SHIPPED_ZOOS.values())}
    except OSError:
        return False


# Algorithms whose policies expose a discrete action distribution (``policy.get_distribution``).



def _memory_of(policy: Any) -> dict[str, Any]:
    """
    A policy's memory as a card's training record names it (``frame_stack``, ``loop_flags``, ``flags_cnn``), where it
    has one: a model added from outside has no record of how it was made, and ``dopt priors list`` shows its memory
    from these.

    :param policy: The loaded model's policy
    :return: ``{}`` for a single-frame policy
    """
    from sb3_disagree.acer.torch_layers import LoopFlagsCNN

    frame_stack = int(getattr(policy, "frame_stack", 1))
    if frame_stack <= 1:
        return {}
    if getattr(policy, "features_extractor_class", None) is not LoopFlagsCNN:
        return {"frame_stack": frame_stack, "loop_flags": False}
    return {"frame_stack": frame_stack, "loop_flags": True,
            "flags_cnn": policy.features_extractor_kwargs.get("cnn_sees", "newest")}


def memory_label(training: dict[str, Any]) -> str:
    """
    A prior's memory as ``dopt priors list`` and docs/zoo.md show it: the frames it sees, ``+flags`` for loop flags
    on a CNN over the newest frame, `` all+flags`` for loop flags on a CNN over every frame ("3", "3+flags",
    "4 all+flags").

    :param training: A card's training record
    """
    flags = " all+flags" if training.get("flags_cnn") == "stack" else "+flags"
    return str(training.get("frame_stack", 1)) + (flags if training.get("loop_flags") else "")


class ZooError(ValueError):
    """A zoo entry that cannot be used, with the reason."""


def env_dir_name(env_id: str) -> str:
    return env_id.replace("/", "__")


def space_to_dict(space: spaces.Space) -> dict[str, Any]:
    """A JSON form of a space that two spaces can be compared by."""
    if isinstance(space, spaces.Discrete):
        return {"type": "Discrete", "n": int(space.n), "start": int(space.start)}
    if isinstance(space, spaces.Box):
        return {"type": "Box", "shape": list(space.shape), "dtype": str(space.dtype),
                "low": float(space.low.min()), "high": float(space.high.max())}
    return {"type": type(space).__name__, "repr": repr(space)}


def _channel_first(space: dict[str, Any]) -> dict[str, Any]:
    """SB3 stores image spaces channel-first (VecTransposeImage); compare HWC and CHW images as equal."""
    shape = space.get("shape")
    if space.get("type") == "Box" and space.get("dtype") == "uint8" and shape and len(shape) == 3 and shape[-1] in (1, 3, 4):
        return dict(space, shape=[shape[-1], *shape[:-1]])
    return space


def space_fits(recorded: dict[str, Any], space: spaces.Space) -> bool:
    """Whether a space recorded on a card is ``space`` (HWC and CHW images taken as equal): the one check that
    ranking priors, loading them and adding them share."""
    return _channel_first(recorded) == _channel_first(space_to_dict(space))


@dataclass
class Card:
    """
    What a zoo entry is.

    :param goal: The goal label
    :param env_id: Gymnasium id of the environment the prior acts in
    :param env_kwargs: Keyword arguments of that environment (without the goal)
    :param observation_space: JSON form of the observation space
    :param action_space: JSON form of the action space
    :param sb3_class: Import path of the algorithm class that loads the model
    :param training: How it was trained: method, steps, seed, ...
    :param evaluation: success_rate, episodes, mean_length with sampled actions (as the method follows priors)
    :param evaluation_greedy: The same with greedy actions (SB3's ``evaluate_policy`` default)
    :param sha256: Of model.zip
    :param created: ISO time of creation
    :param command: The command that made it
    """

    goal: str
    env_id: str
    env_kwargs: dict[str, Any]
    observation_space: dict[str, Any]
    action_space: dict[str, Any]
    sb3_class: str
    training: dict[str, Any] = field(default_factory=dict)
    evaluation: dict[str, Any] = field(default_factory=dict)
    evaluation_greedy: dict[str, Any] = field(default_factory=dict)
    sha256: str = ""
    created: str = ""
    command: str = ""

    @classmethod
    def from_json(cls, text: str) -> "Card":
        data = json.loads(text)
        missing = [k for k in ("goal", "env_id", "observation_space", "action_space", "sb3_class") if k not in data]
        if missing:
            raise ValueError(f"card lacks {', '.join(missing)}")
        known = {k: v for k, v in data.items() if k in cls.__dataclass_fields__}
        known.setdefault("env_kwargs", {})
        return cls(**known)


@dataclass
class Entry:
    """A zoo entry as found on disk; ``problem`` says why it cannot be used (None when it can)."""

    path: Path
    env_id: str
    goal: str
    card: Optional[Card]
    problem: Optional[str]

    @property
    def model_path(self) -> Path:
        return self.path / MODEL


def _card_problem(card: Card, goal_dir: Path, env_id: str) -> Optional[str]:
    """What is wrong with a card's fields, or None: the checks made before anything of the entry is loaded."""
    if card.goal != goal_dir.name:
        return f"the card's goal {card.goal!r} is not its folder's name {goal_dir.name!r}"
    if card.env_id != env_id:
        return f"the card's env {card.env_id!r} is not its folder's {env_id!r}"
    if not known_algorithm(card.sb3_class):
        return f"the card names an unknown algorithm {card.sb3_class!r}"
    if not isinstance(card.env_kwargs, dict) or not all(isinstance(k, str) for k in card.env_kwargs):
        return "the card's env_kwargs are not a mapping of names"
    if not all(isinstance(v, (str, int, float, bool, type(None))) for v in card.env_kwargs.values()):
        return "the card's env_kwargs hold values other than plain numbers, strings and booleans"
    return None


class Zoo:
    """
    A prior zoo rooted at a folder.

    :param root: The zoo folder, or the name of a zoo shipped beside the default one ("greedy"); the zoo shipped
        with the package by default
    """

    def __init__(self, root: Optional[Union[str, Path]] = None, trusted: Optional[Union[str, Path]] = None,
                 write_shipped: bool = False) -> None:
        self.root = zoo_root(root)
        self.write_shipped = write_shipped
        # A trust list kept outside the zoo (a file of SHA-256 hashes, one per line; SB3_DISAGREE_TRUSTED names
        # one for every command): where given, an entry whose model is not on it is refused before anything
        # of it is unpickled. The shipped zoo needs none.
        self.trusted = trust_list(trusted)

    def check_writable(self) -> None:
        """A ZooError if this is a shipped zoo and writing to it was not asked for (``write_shipped``)."""
        if is_shipped(self.root) and not self.write_shipped:
            raise ZooError(f"the shipped zoo {self.root} is read-only: write to your own zoo with --zoo FOLDER (by "
                           f"default {user_zoo()}), or pass --write-shipped to change the package's own")

    def entries(self, env_id: Optional[str] = None) -> list[Entry]:
        """All entries (of one env id if given), sorted; damaged ones carry their problem."""
        out = []
        if not self.root.is_dir():
            return out
        env_dirs = [self.root / env_dir_name(env_id)] if env_id else sorted(p for p in self.root.iterdir() if p.is_dir() and not p.name.startswith("."))
        for env_dir in env_dirs:
            if not env_dir.is_dir():
                continue
            for goal_dir in sorted(p for p in env_dir.iterdir() if p.is_dir() and not p.name.startswith(".")):
                out.append(self._read(goal_dir, env_dir.name.replace("__", "/")))
        return out

    def _read(self, goal_dir: Path, env_id: str) -> Entry:
        card, problem = None, None
        try:
            card = Card.from_json((goal_dir / CARD).read_text())
        except FileNotFoundError:
            problem = "no card.json"
        except (ValueError, TypeError) as exc:
            problem = f"unreadable card.json ({exc})"
        if problem is None:
            problem = _card_problem(card, goal_dir, env_id)
        if problem is None:
            if not (goal_dir / MODEL).exists():
                problem = "no model.zip"
            elif sha256_of(goal_dir / MODEL) != card.sha256:
                problem = "model.zip does not match the card's sha256 (corrupt or replaced)"
            elif (self.trusted is not None and not is_shipped(self.root)
                  and card.sha256 not in self.trusted):
                problem = "model.zip is not on the trust list"
        return Entry(goal_dir, env_id, card.goal if card else goal_dir.name, card, problem)

    def get(self, goal: str, env_id: str) -> Entry:
        for entry in self.entries(env_id):
            if entry.goal == goal:
                return entry
        raise ZooError(f"the zoo at {self.root} has no prior for {goal!r} in {env_id}")

    def labels(self, env_id: str, observation_space: Optional[spaces.Space] = None,
               action_space: Optional[spaces.Space] = None) -> list[str]:
        """Goals of the usable entries of an env id whose spaces match the given ones."""
        out = []
        for e in self.entries(env_id):
            if e.problem or e.card is None:
                continue
            if observation_space is not None and not space_fits(e.card.observation_space, observation_space):
                continue
            if action_space is not None and not space_fits(e.card.action_space, action_space):
                continue
            out.append(e.goal)
        return out

    def load(self, entry: Entry, env: Any = None, device: str = "auto"):
        """
        Load a prior, checking its file, its spaces against ``env`` and its action distribution.

        :param entry: The zoo entry
        :param env: An environment (or VecEnv) the prior must act in; its spaces are checked
        :param device: Torch device of the prior
        :return: The SB3 model, its policy in eval mode
        """
        if entry.problem:
            raise ZooError(f"prior {entry.goal!r} ({entry.path}) cannot be used: {entry.problem}")
        card = entry.card
        assert card is not None
        if env is not None:
            for kind, space in (("observation", env.observation_space), ("action", env.action_space)):
                have = getattr(card, f"{kind}_space")
                if not space_fits(have, space):
                    raise ZooError(f"prior {entry.goal!r} expects {kind}s {have}, the environment gives "
                                   f"{space_to_dict(space)}")
        try:
            check_model_file(entry.model_path)
            cls = algorithm_class(card.sb3_class)
            # Opened without unpickling what it carries unless its hash is on the trust list (sb3_disagree.loading).
            model = load(entry.model_path, cls, device=device)
        except ModelFileError as exc:
            raise ZooError(f"prior {entry.goal!r}: {exc}") from None
        except Exception as exc:
            raise ZooError(f"prior {entry.goal!r}: {entry.model_path} could not be loaded: {exc}") from exc
        check_distribution(model)
        model.policy.set_training_mode(False)
        return model

    def add(
        self,
        model_path: Union[str, Path],
        goal: str,
        env_id: str,
        env_kwargs: Optional[dict[str, Any]] = None,
        training: Optional[dict[str, Any]] = None,
        evaluation: Optional[dict[str, Any]] = None,
        command: str = "",
        replace: bool = False,
        trust: bool = False,
    ) -> Entry:
        """
        Copy a saved model into the zoo with its card, atomically.

        :param model_path: An SB3 model file
        :param goal: The goal label it reaches
        :param env_id: Gymnasium id of its environment
        :param env_kwargs: The environment's keyword arguments, without the goal
        :param training: How it was trained
        :param evaluation: How well it does
        :param command: The command that made it
        :param replace: Whether an existing entry for this goal may be replaced
        :param trust: Open the model file as SB3 does, unpickling what it carries (a file you made or trust);
            otherwise a file that needs that is refused (``sb3_disagree.loading``)
        :return: The new entry
        """
        from sb3_disagree.files import safe_name

        self.check_writable()
        model_path = Path(model_path)
        safe_name(goal, "the goal")
        from sb3_disagree.envs.vec import make_task

        try:
            env = make_task(env_id, goal, env_kwargs)  # everything is checked before anything is written
        except ValueError as exc:
            raise ZooError(str(exc)) from None
        target = self.root / env_dir_name(env_id) / goal
        if target.exists() and not replace:  # refused before the file is opened
            raise ZooError(f"the zoo already has a prior for {goal!r} in {env_id} (remove it first)")
        sb3_class = "an SB3 algorithm"
        try:
            check_model_file(model_path)
            sb3_class = identify_algorithm(model_path)
            model = load(model_path, algorithm_class(sb3_class), device="cpu", trust=trust)
        except ModelFileError as exc:
            raise ZooError(str(exc)) from None
        except Exception as exc:
            raise ZooError(f"{model_path} could not be loaded as {sb3_class}: {exc}") from exc
        check_distribution(model)
        for kind in ("observation", "action"):
            if not space_fits(space_to_dict(getattr(model, f"{kind}_space")), getattr(env, f"{kind}_space")):
                raise ZooError(f"{model_path} acts on {kind}s {space_to_dict(getattr(model, f'{kind}_space'))}, but "
                               f"{env_id} gives {space_to_dict(getattr(env, f'{kind}_space'))}")
        card = Card(
            goal=goal, env_id=env_id, env_kwargs=dict(env_kwargs or {}),
            observation_space=space_to_dict(model.observation_space), action_space=space_to_dict(model.action_space),
            sb3_class=sb3_class, training={**_memory_of(model.policy), **(training or {})},
            evaluation=dict(evaluation or {}),
            sha256=sha256_of(model_path), created=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            command=command,
        )
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{goal}-", dir=target.parent))
        os.chmod(tmp, 0o755)  # mkdtemp's private mode would hide the entry from other users of a shared zoo
        try:
            shutil.copyfile(model_path, tmp / MODEL)
            (tmp / CARD).write_text(json.dumps(asdict(card), indent=2) + "\n")
            if target.exists():
                old = target.with_name(f".{goal}-old")
                os.replace(target, old)
                os.replace(tmp, target)
                shutil.rmtree(old)
            else:
                os.replace(tmp, target)
        finally:
            if tmp.exists():
                shutil.rmtree(tmp)
        return self._read(target, env_id)

    def record_evaluation(self, entry: Entry, evaluation: dict[str, Any]) -> Entry:
        """
        Replace the evaluation on an entry's card, atomically (the model file is left as it is): the greedy one
        where ``evaluation["deterministic"]`` is true, else the sampled one.

        :param entry: A usable entry
        :param evaluation: success_rate, episodes, mean_length, deterministic, ... of the new evaluation
        :return: The entry as read back
        """
        self.check_writable()
        if entry.card is None or entry.problem is not None:
            raise ZooError(f"prior {entry.goal!r}: cannot record an evaluation on an unusable entry ({entry.problem})")
        if evaluation.get("deterministic"):
            entry.card.evaluation_greedy = dict(evaluation)
        else:
            entry.card.evaluation = dict(evaluation)
        write_atomic(entry.path / CARD, json.dumps(asdict(entry.card), indent=2) + "\n")
        return self._read(entry.path, entry.env_id)

    def remove(self, goal: str, env_id: str) -> None:
        self.check_writable()
        entry = self.get(goal, env_id)
        trash = entry.path.with_name(f".{entry.path.name}-removed")
        os.replace(entry.path, trash)
        shutil.rmtree(trash)


def check_distribution(model: Any) -> None:
    """Refuse a model whose policy does not give a discrete action distribution."""
    if not isinstance(model.action_space, spaces.Discrete):
        raise ZooError(f"a prior needs a Discrete action space, this model has {model.action_space}")
    if not hasattr(model.policy, "get_distribution"):
        raise ZooError(f"{type(model).__name__} has no action distribution (a prior must give pi(a|s))")
