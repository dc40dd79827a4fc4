"""
Each mode's settings as data (``hyperparams/modes.yml``), read here once, and the one function that resolves a run's
settings from them: what a RunConfig is not given, it takes from its mode's preset.
"""

import functools
from pathlib import Path
from typing import Any, Optional

import yaml

PRESETS = Path(__file__).resolve().parents[1] / "hyperparams" / "modes.yml"
# The RunConfig fields a preset may set, and what the library ran with before a preset set them (a saved config
# without one of them ran with this).
RESOLVED = {"overlap": False, "finish": False, "frame_stack": 1, "loop_flags": False, "consistency_harvest": 0,
            "greedy_phase": 0, "consistency_validation": 0, "ready": 0.0, "extend": 1.0}


@functools.lru_cache(maxsize=1)
def presets() -> dict[str, dict[str, Any]]:
    """The presets file, as written."""
    return yaml.safe_load(PRESETS.read_text())


def preset(mode: str, key: str, finish: bool = False) -> dict[str, Any]:
    """One part of a mode's preset (``run``, ``images``, ``acer``, ``overlapped``, ``ppo``): ``all``'s, then the
    finish's where ``finish``, then the mode's own, then, where not ``finish``, ``bare``'s (the settings the bare
    modes ran with)."""
    data = presets()
    return {**data["all"].get(key, {}), **(data["finish"].get(key, {}) if finish else {}),
            **data.get(mode, {}).get(key, {}), **(data["bare"].get(key, {}) if not finish else {})}


def finished(mode: str) -> bool:
    """Whether a mode's runs get the finish when a run does not say."""
    return bool(preset(mode, "run")["finish"])


def acer_defaults(mode: str, finish: Optional[bool] = None, overlap: bool = False) -> dict[str, Any]:
    """ACER's settings for a mode when a run names none; ``finish`` None: as the mode's runs are by default;
    ``overlap``: with those of the overlapped loop."""
    finish = finished(mode) if finish is None else finish
    return {**preset(mode, "acer", finish), **(preset(mode, "overlapped", finish) if overlap else {})}


def resolve(fields: dict[str, Any], images: bool) -> dict[str, Any]:
    """
    A run's settings with what it was not given (None) taken from its mode's preset.

    :param fields: RunConfig's fields as given: ``mode``, ``steps``, ``acer_kwargs`` and the fields of ``RESOLVED``
        (None where not given; ``finish`` None: the mode's)
    :param images: Whether the env observes images (a preset's ``images`` part applies)
    :return: Those fields resolved
    """
    mode = fields["mode"]
    finish = finished(mode) if fields.get("finish") is None else bool(fields["finish"])
    run = {**preset(mode, "run", finish), **(preset(mode, "images", finish) if images else {})}
    out = dict(fields)
    out["finish"] = finish
    given = {k for k in RESOLVED if fields.get(k) is not None}
    for key in RESOLVED:
        if key not in given and key not in ("finish", "greedy_phase", "consistency_validation", "frame_stack",
                                            "loop_flags"):
            out[key] = run[key]
    # Memory: loop flags need a stack, and a stack asked for alone is a plain one.
    flags, stack = fields.get("loop_flags"), fields.get("frame_stack")
    if flags is None:
        flags = bool(run["loop_flags"]) and stack is None
    if stack is None:
        stack = (run["frame_stack"] if run["frame_stack"] > 1 else presets()["all"]["loop_flags_stack"]) if flags else 1
    out["frame_stack"], out["loop_flags"] = stack, bool(flags)
    # The greedy phase is the harvest's steps (capped at the budget); a fit is validated only where there is one.
    if "greedy_phase" not in given:
        phase = run["greedy_phase"]
        harvest = max(0, min(_int(out["consistency_harvest"]), _int(fields.get("steps"))))
        out["greedy_phase"] = harvest if phase == "harvest" else phase
    if "ready" not in given and not out["greedy_phase"]:  # nothing waits where there is no greedy phase
        out["ready"] = 0.0
    if "extend" not in given and not out["ready"]:  # and a budget that never waits never grows
        out["extend"] = 1.0
    if "consistency_validation" not in given:
        out["consistency_validation"] = run["consistency_validation"] if out["consistency_harvest"] else 0
    acer = dict(fields.get("acer_kwargs") or {})
    # SB3's PPO takes none of ACER's settings: a ppo run keeps only those given (which validation refuses).
    out["acer_kwargs"] = acer if mode == "ppo" else {**acer_defaults(mode, finish, out["overlap"]), **acer}
    return out


# Kickstarting's distillation, which runs saved before the presets got from the code rather than their config.yaml.
DISTILL = ("distill_coef", "distill_steps", "distill_states")


def trained_with(saved: dict[str, Any], field_defaults: dict[str, Any]) -> dict[str, Any]:
    """
    A saved run's settings completed with what the library ran it with where the record does not name one (a setting
    newer than the record): ``RESOLVED`` for the fields a preset sets, ``field_defaults`` for the others, ACER's own
    defaults for its settings, and for a kickstarting run the distillation its mode applied.

    :param saved: A run's ``config.yaml`` (or ``result.json``'s ``config``)
    :param field_defaults: RunConfig's own defaults of its other fields
    """
    out = {**field_defaults, **{k: v for k, v in saved.items() if v is not None or k not in RESOLVED}}
    for name, old in RESOLVED.items():
        if out.get(name) is None:
            out[name] = old
    if isinstance(saved.get("acer_kwargs"), dict):
        implicit = {k: preset("kickstart", "acer")[k] for k in DISTILL} if saved.get("mode") == "kickstart" else {}
        out["acer_kwargs"] = {**acer_signature_defaults(), **implicit, **saved["acer_kwargs"]}
    return out


@functools.lru_cache(maxsize=1)
def acer_parameters() -> frozenset[str]:
    """The keyword arguments of ACER a run's ``acer_kwargs`` may set (not the policy, the env, the behaviour, the
    seed, the loop or the device, which the run sets itself)."""
    import inspect

    from sb3_disagree.acer import ACER

    return frozenset(inspect.signature(ACER.__init__).parameters) - {
        "self", "policy", "env", "behaviour", "seed", "overlap", "kwargs", "_init_setup_model", "device"}


@functools.lru_cache(maxsize=1)
def acer_signature_defaults() -> dict[str, Any]:
    """ACER's own defaults of those settings (what a run that did not name one trained with)."""
    import inspect

    from sb3_disagree.acer import ACER

    return {name: p.default for name, p in inspect.signature(ACER.__init__).parameters.items()
            if name in acer_parameters() and isinstance(p.default, (int, float, str, bool))}


def _int(value: Optional[Any]) -> int:
    return value if isinstance(value, int) and not isinstance(value, bool) else 0
