"""
Saved models opened without running what they carry.

An SB3 ``model.zip`` holds its weights as tensors, which SB3 reads with torch's ``weights_only``, and some fields as
pickled Python objects (the policy class, the spaces, schedules, a few buffers), which ``BaseAlgorithm.load``
unpickles: a tampered file runs its code there. :func:`load` rebuilds those fields instead, from what the package
knows: the readable copy SB3 writes beside each pickle, a table of known classes, and the schedules a run's
configuration gives. A file that needs anything else is refused with one line, unless it is trusted (``trust=True``,
``--trust`` on the command line, or its SHA-256 on the trust list that ``SB3_DISAGREE_TRUSTED`` names).
"""

import hashlib
import importlib
import json
import os
import re
import zipfile
from pathlib import Path
from typing import Any, Optional, Union

import numpy as np

# Classes a model's readable fields may name, by "module.name": the policies, features extractors, activations and
# optimizers of this package, SB3 and sb3-contrib. Nothing else is ever imported from what a file says.
KNOWN_CLASSES = (
    "sb3_disagree.acer.policies.MlpPolicy", "sb3_disagree.acer.policies.CnnPolicy",
    "sb3_disagree.acer.policies.ACERPolicy", "sb3_disagree.acer.torch_layers.LoopFlagsCNN",
    "stable_baselines3.common.policies.ActorCriticPolicy", "stable_baselines3.common.policies.ActorCriticCnnPolicy",
    "stable_baselines3.common.policies.MultiInputActorCriticPolicy",
    "stable_baselines3.common.torch_layers.NatureCNN", "stable_baselines3.common.torch_layers.FlattenExtractor",
    "sb3_contrib.common.maskable.policies.MaskableActorCriticPolicy",
    "sb3_contrib.common.maskable.policies.MaskableActorCriticCnnPolicy",
    "torch.nn.modules.activation.ReLU", "torch.nn.modules.activation.Tanh", "torch.nn.modules.activation.ELU",
    "torch.nn.modules.activation.LeakyReLU", "torch.nn.modules.activation.GELU", "torch.nn.modules.activation.SiLU",
    "torch.optim.adam.Adam", "torch.optim.rmsprop.RMSprop", "torch.optim.sgd.SGD", "torch.optim.adamw.AdamW",
    "stable_baselines3.common.buffers.RolloutBuffer", "stable_baselines3.common.buffers.DictRolloutBuffer",
    "stable_baselines3.common.buffers.ReplayBuffer",
    "sb3_contrib.common.maskable.buffers.MaskableRolloutBuffer",
    "sb3_contrib.common.maskable.buffers.MaskableDictRolloutBuffer",
)
# Schedules SB3 saves as objects, rebuilt from their readable form ("ConstantSchedule(val=0.2)", ...).
_SCHEDULE = re.compile(r"^(ConstantSchedule|LinearSchedule)\((.*)\)$")
# Fields rebuilt empty: SB3 makes them anew before it trains (the last observation, the episode buffers) or derives
# them from plain fields when the model is set up (the learning-rate schedule).
REBUILT_EMPTY = ("lr_schedule", "_last_obs", "_last_episode_starts", "_last_original_obs", "ep_info_buffer",
                 "ep_success_buffer")
_CLASS = re.compile(r"^<class '([\w.]+)'>$")
_METHOD = re.compile(r"^<function (\w+)\.\w+ at 0x[0-9a-f]+>$")


class ModelFileError(ValueError):
    """A file that is not a usable model of a known algorithm."""


class UntrustedModelError(ModelFileError):
    """A model file that cannot be opened without unpickling what it carries."""


def sha256_of(path: Union[str, Path]) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


DISTRIBUTION_CLASSES = {
    "ACER": "sb3_disagree.acer.ACER",
    "PPO": "stable_baselines3.PPO",
    "A2C": "stable_baselines3.A2C",
    "TRPO": "sb3_contrib.TRPO",
    "MaskablePPO": "sb3_contrib.MaskablePPO",
}

# Algorithms a card may name beyond the known ones, added by the user (``register_algorithm``).
_REGISTERED: set[str] = set()


def register_algorithm(path: str) -> None:
    """
    Let cards name another algorithm class (import path ``package.module.Class``) with a discrete action
    distribution. Only the known SB3, sb3-contrib and sb3-disagree classes and those registered here are
    ever imported from a card.
    """
    _REGISTERED.add(path)


def known_algorithm(path: str) -> bool:
    """Whether a card or a caller may name this algorithm class (a known one, or one registered)."""
    return path in DISTRIBUTION_CLASSES.values() or path in _REGISTERED


def algorithm_class(path: str) -> type:
    """The algorithm class a card names: a known one or a registered one; a ModelFileError for anything else (a card
    must not make this process import whatever module it names)."""
    if not known_algorithm(path):
        raise ModelFileError(f"a card names the algorithm {path!r}, which is neither a known one "
                       f"({', '.join(DISTRIBUTION_CLASSES.values())}) nor registered with "
                       "sb3_disagree.priors.register_algorithm")
    module, _, name = path.rpartition(".")
    return getattr(importlib.import_module(module), name)


def check_model_file(path: Path) -> None:
    """Refuse what is not a readable SB3 model archive."""
    try:
        with zipfile.ZipFile(path) as z:
            names = set(z.namelist())
            if "data" not in names or z.testzip() is not None:
                raise ModelFileError(f"{path} is not an SB3 model file (damaged archive or no 'data' member)")
    except zipfile.BadZipFile as exc:
        raise ModelFileError(f"{path} is not an SB3 model file: {exc}") from exc


def identify_algorithm(model_path: Path) -> str:
    """
    Which supported algorithm saved a model file, read from the file's own record of its policy class
    and hyperparameters (PPO and A2C share SB3's ActorCriticPolicy; PPO records a clip range).

    :return: Import path of the algorithm class
    """
    with zipfile.ZipFile(model_path) as z:
        data = json.loads(z.read("data"))
    policy_module = str(data.get("policy_class", {}).get("__module__", ""))
    if policy_module.startswith("sb3_disagree."):
        name = "ACER"
    elif policy_module.startswith("sb3_contrib.common.maskable"):
        name = "MaskablePPO"
    elif policy_module == "stable_baselines3.common.policies" and "cg_max_steps" in data:
        name = "TRPO"
    elif policy_module == "stable_baselines3.common.policies" and "clip_range" in data:
        name = "PPO"
    elif policy_module == "stable_baselines3.common.policies":
        name = "A2C"
    else:
        raise ModelFileError(
            f"{model_path} was saved with a policy from {policy_module or 'an unknown module'}: a prior must come from "
            f"an algorithm with a discrete action distribution ({', '.join(DISTRIBUTION_CLASSES)}); DQN, SAC, TD3 "
            "and DDPG models have none"
        )
    return DISTRIBUTION_CLASSES[name]




def trust_list(path: Optional[Union[str, Path]] = None) -> Optional[set[str]]:
    """
    The SHA-256 hashes of a trust list (one per line, ``#`` comments), by default the file ``SB3_DISAGREE_TRUSTED``
    names; None where there is none.

    :raises ValueError: A trust list that is not a readable file
    """
    path = path if path is not None else os.environ.get("SB3_DISAGREE_TRUSTED")
    if not path:
        return None
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"the trust list {path} (SB3_DISAGREE_TRUSTED) is not a file of SHA-256 hashes")
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"the trust list {path} cannot be read: {exc}") from None
    return {line.split("#")[0].strip().lower() for line in lines if line.split("#")[0].strip()}


def is_trusted(path: Union[str, Path], trust: bool = False) -> bool:
    """Whether a file may be unpickled: asked for, or its hash on the trust list."""
    listed = trust_list()
    return trust or (listed is not None and sha256_of(path) in listed)


def saved_fields(path: Union[str, Path]) -> dict[str, Any]:
    """
    The fields of a model file's ``data`` record as written (nothing unpickled).

    :raises ValueError: Not an SB3 model file
    """
    try:
        with zipfile.ZipFile(path) as archive:
            data = json.loads(archive.read("data"))
    except (zipfile.BadZipFile, KeyError, OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path} is not a readable SB3 model file ({exc})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path} is not a readable SB3 model file (its data record is not a mapping)")
    return data


def known_class(name: str) -> type:
    """A class of ``KNOWN_CLASSES`` by its "module.name"; a ValueError for any other."""
    if name not in KNOWN_CLASSES:
        raise ValueError(name)
    module, _, attr = name.rpartition(".")
    return getattr(importlib.import_module(module), attr)


def _class_field(field: dict[str, Any], key: str) -> type:
    """The class a saved class field names: its module, and its name as the methods it defines spell it
    ("<function CnnPolicy.__init__ at ...>"), or else its docstring; only among ``KNOWN_CLASSES``."""
    module = field.get("__module__")
    names = {m[1] for v in field.values() if isinstance(v, str) and (m := _METHOD.match(v))}
    candidates = {c for c in map(known_class, KNOWN_CLASSES) if c.__module__ == module
                  and (c.__name__ in names if names else c.__doc__ == field.get("__doc__"))}
    if len(candidates) != 1 or len(names) > 1:
        raise ValueError(key)
    return candidates.pop()


def _policy_class(field: dict[str, Any], algorithm: type, path: Union[str, Path]) -> type:
    cls = _class_field(field, "policy_class")
    if not issubclass(cls, tuple(algorithm.policy_aliases.values())):
        raise ModelFileError(f"{path} could not be loaded as {algorithm.__name__}: it holds a {cls.__name__}, a policy "
                             "of another algorithm")
    return cls


def _schedule(field: dict[str, Any], key: str) -> Any:
    """A schedule saved as an object: a constant or a linear one, from its readable form."""
    from stable_baselines3.common.utils import ConstantSchedule, FloatSchedule, LinearSchedule

    kind = str(field.get(":type:", ""))
    if "FloatSchedule" in kind:  # its readable copy is the wrapped schedule's repr
        match = _SCHEDULE.match(str(field.get("value_schedule", "")))
        if match is None:
            raise ValueError(key)
        name, values = match[1], dict(p.split("=") for p in match[2].replace(" ", "").split(",") if "=" in p)
    elif "ConstantSchedule" in kind or "LinearSchedule" in kind:  # its readable copy is its fields
        name, values = ("ConstantSchedule" if "ConstantSchedule" in kind else "LinearSchedule"), field
    else:
        raise ValueError(key)
    if name == "ConstantSchedule":
        return FloatSchedule(ConstantSchedule(float(values["val"])))
    return FloatSchedule(LinearSchedule(float(values["start"]), float(values["end"]), float(values["end_fraction"])))


def _plain(value: Any, key: str) -> Any:
    """A readable field's value: JSON as written, a known class where it names one."""
    if isinstance(value, str) and value.startswith("<"):
        match = _CLASS.match(value)
        if match is None:
            raise ValueError(key)
        try:
            return known_class(match[1])
        except ValueError:
            raise ValueError(f"{key} ({match[1]})") from None
    if isinstance(value, dict):
        return {k: _plain(v, f"{key}.{k}") for k, v in value.items()}
    return value


def _numbers(text: str) -> Optional[np.ndarray]:
    if not isinstance(text, str) or "..." in text:
        return None
    try:
        return np.array([float(x) for x in text.replace("[", " ").replace("]", " ").split()])
    except ValueError:
        return None


def _space(field: dict[str, Any], key: str):
    from gymnasium import spaces

    kind = field.get(":type:")
    if kind == "<class 'gymnasium.spaces.discrete.Discrete'>":
        return spaces.Discrete(int(field["n"]), start=int(field.get("start", 0)))
    if kind != "<class 'gymnasium.spaces.box.Box'>":
        raise ValueError(key)
    shape = tuple(json.loads(field["_shape"]) if isinstance(field["_shape"], str) else field["_shape"])
    dtype = np.dtype(field["dtype"])
    if dtype == np.uint8 and len(shape) == 3:  # an image: SB3 wants 0-255 exactly
        return spaces.Box(0, 255, shape, dtype)
    low, high = _numbers(field.get("low")), _numbers(field.get("high"))
    size = int(np.prod(shape))
    if low is None or high is None or low.size not in (1, size) or high.size not in (1, size):
        raise ValueError(key)
    low, high = low.astype(dtype), high.astype(dtype)
    return spaces.Box(low.reshape(shape) if low.size == size else low[0],
                      high.reshape(shape) if high.size == size else high[0], shape, dtype)


def rebuilt_fields(path: Union[str, Path], algorithm: type, schedules: Optional[dict[str, Any]] = None) -> dict:
    """
    ``custom_objects`` for SB3's ``load`` that stand in for every pickled field of a model file.

    :param path: The model file
    :param algorithm: The SB3 algorithm class that saved it
    :param schedules: Schedules a run's configuration gives (``learning_rate``, ``clip_range``: PPO's lambdas)
    :raises UntrustedModelError: A pickled field the package cannot rebuild
    """
    rebuilt: dict[str, Any] = {}
    for key, value in saved_fields(path).items():
        if not (isinstance(value, dict) and ":serialized:" in value):
            continue
        readable = {k: v for k, v in value.items() if k not in (":serialized:", ":type:")}
        try:
            if key in REBUILT_EMPTY:
                rebuilt[key] = None
            elif schedules and key in schedules:
                rebuilt[key] = schedules[key]
            elif key == "policy_class":
                rebuilt[key] = _policy_class(value, algorithm, path)
            elif key.endswith("_class") and value.get(":type:") in ("<class 'abc.ABCMeta'>", "<class 'type'>"):
                rebuilt[key] = _class_field(value, key)
            elif key in ("learning_rate", "clip_range", "clip_range_vf", "ent_coef"):
                rebuilt[key] = _schedule(value, key)
            elif key == "policy_kwargs" and value.get(":type:") == "<class 'dict'>":
                rebuilt[key] = _plain(readable, key)
            elif key in ("observation_space", "action_space"):
                rebuilt[key] = _space(value, key)
            else:
                raise ValueError(key)
        except ModelFileError:
            raise
        except (ValueError, KeyError, TypeError) as exc:
            raise UntrustedModelError(
                f"{path} holds a pickled field the package cannot rebuild ({exc.args[0] if exc.args else key}): "
                "opening it could run code; pass --trust (or add its SHA-256 to the trust list) if you trust its "
                "source") from None
    return rebuilt


def load(path: Union[str, Path], algorithm: Optional[type] = None, env: Any = None, device: str = "auto",
         trust: bool = False, schedules: Optional[dict[str, Any]] = None, **kwargs: Any):
    """
    Open a saved SB3 model without unpickling anything it carries (unless trusted): the safe ``ACER.load``.

    :param path: The model file
    :param algorithm: Its algorithm class (default: read from the file's readable record: ACER, PPO, A2C, ...)
    :param env: An environment to continue training in, as SB3's ``load`` takes
    :param device: Torch device
    :param trust: Unpickle the file as SB3 does (for a file you made or whose source you trust)
    :param schedules: Schedules that stand in for pickled ones (a run's configuration gives them)
    :param kwargs: Passed to the algorithm's ``load`` (ACER's ``behaviour``, ``overlap``)
    :raises UntrustedModelError: The file needs code to open and is not trusted
    :return: The model
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no model file at {path}")
    if algorithm is None:
        algorithm = algorithm_class(identify_algorithm(path))
    custom = None if is_trusted(path, trust) else rebuilt_fields(path, algorithm, schedules)
    return algorithm.load(path, env=env, device=device, custom_objects=custom, **kwargs)
