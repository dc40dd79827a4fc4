"""
Command-line options generated from the library: a dataclass's fields or a function's parameters, with the
defaults they declare and the help of their ``:param:`` docstrings, so that the CLI repeats neither.
"""

import inspect
import re
import typing
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, Optional

import typer

_PARAM = re.compile(r":param (\w+):(.*?)(?=\n\s*:(?:param|return|raises)|\Z)", re.S)


def param_help(obj: Any) -> dict[str, str]:
    """The ``:param name: text`` entries of a docstring, each text on one line."""
    return {name: " ".join(text.replace("``", "").split()) for name, text in _PARAM.findall(inspect.getdoc(obj) or "")}


def flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def options_of(obj: Any, only: Optional[Iterable[str]] = None, skip: Iterable[str] = (),
               defaults: Optional[dict[str, Any]] = None, flags: Optional[dict[str, str]] = None,
               types: Optional[dict[str, Any]] = None, helps: Optional[dict[str, str]] = None) -> list[inspect.Parameter]:
    """
    Typer options for the parameters of ``obj`` (a function, or a dataclass's fields), in their order.

    :param obj: The function or dataclass
    :param only: Only these parameters (default: all with a plain type)
    :param skip: Not these
    :param defaults: Defaults that differ from the library's (what the command line wants on by default)
    :param flags: Option names other than ``--name-with-dashes``
    :param types: Types other than the declared one (a list given as "a,b" is a ``str`` here)
    :param helps: Help texts other than the docstring's
    :return: Keyword-only parameters whose defaults are ``typer.Option``
    """
    defaults, flags, types = defaults or {}, flags or {}, types or {}
    helps = {**param_help(obj), **(helps or {})}
    hints = typing.get_type_hints(obj.__init__ if inspect.isclass(obj) else obj)
    out = []
    for p in inspect.signature(obj).parameters.values():
        if p.kind in (p.VAR_KEYWORD, p.VAR_POSITIONAL) or p.name in skip or (only is not None and p.name not in only):
            continue
        kind = types.get(p.name, hints.get(p.name, str))
        if only is None and kind not in (int, float, str, bool, Optional[bool], Optional[str], Optional[int],
                                           Optional[float], Optional[Path], Path):
            continue
        default = defaults.get(p.name, p.default)
        if default is inspect.Parameter.empty:
            default = ...
        decls = flags.get(p.name, flag(p.name))
        if kind is bool:
            decls = f"{decls}/--no-{decls[2:]}" if default is True else decls
        option = default if isinstance(default, typer.models.OptionInfo) else typer.Option(  # a command's own option
            default, decls, help=helps.get(p.name, ""))
        out.append(inspect.Parameter(p.name, inspect.Parameter.KEYWORD_ONLY, annotation=kind, default=option))
    return out


def command(*groups: list[inspect.Parameter]) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Give a ``def f(**options)`` command the generated options as its signature (what Typer reads)."""
    params = [p for group in groups for p in group]

    def wrap(func: Callable[..., Any]) -> Callable[..., Any]:
        func.__signature__ = inspect.Signature(params, return_annotation=None)  # type: ignore[attr-defined]
        func.__annotations__ = {p.name: p.annotation for p in params}
        return func

    return wrap


def split(text: str) -> list[str]:
    """A comma-separated list as typed: "a, b" -> ["a", "b"]."""
    return [part.strip() for part in text.split(",") if part.strip()]
