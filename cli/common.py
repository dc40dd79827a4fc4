"""What the ``dopt`` commands share: the console, clean failures, defaults."""

import contextlib
import os
import sys
from collections.abc import Iterator
from typing import Any

import typer
import typer.core
from rich.console import Console
from rich.markup import escape

from sb3_disagree.defaults import DEFAULT_ENV  # noqa: F401  (the one definition, for the commands)
from sb3_disagree.priors.language import NotEnoughPriorsError, UnknownWordError
from sb3_disagree.priors.zoo import ZooError

# Piped to a file or a log, a table keeps its columns whole instead of wrapping them at 80 characters.
console = Console(width=None if sys.stdout.isatty() or "COLUMNS" in os.environ else 160)
err_console = Console(stderr=True)
# Errors a user can cause with their input: a message and exit code 2, never a traceback.
USER_ERRORS = (ZooError, UnknownWordError, NotEnoughPriorsError, FileNotFoundError, KeyError, ValueError)


def say_error(message: str) -> None:
    """One line on stderr: ``error: MESSAGE`` (a message of several lines keeps its first)."""
    lines = str(message).strip().splitlines() or ["(no message)"]
    err_console.print(f"[bold red]error:[/] {escape(lines[0])}", highlight=False, soft_wrap=True)


@contextlib.contextmanager
def clean_errors() -> Iterator[None]:
    try:
        yield
    except USER_ERRORS as exc:
        say_error(exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc))
        raise typer.Exit(code=2) from None
    except OSError as exc:  # a folder that cannot be written, a path that is a file, a full disk
        where = f": {exc.filename}" if exc.filename else ""
        say_error(f"{exc.strerror or exc}{where}")
        raise typer.Exit(code=2) from None


class OneLineErrors(typer.core.TyperGroup):
    """The ``dopt`` group: a usage error (an unknown option, a value out of range, a missing argument) is one line on
    stderr and exit code 2, as every other bad input, instead of click's box and usage text; Ctrl-C before a command
    has its own handling is one line and exit code 130."""

    def main(self, args: Any = None, prog_name: Any = None, complete_var: Any = None, standalone_mode: bool = True,
             **extra: Any) -> Any:
        try:
            result = super().main(args=args, prog_name=prog_name, complete_var=complete_var, standalone_mode=False,
                                  **extra)
        except typer.Abort:
            say_error("interrupted")
            result = 130
        except typer.TyperException as exc:  # click's usage errors, as Typer carries them
            if type(exc).__name__ == "NoArgsIsHelpError" and getattr(exc, "ctx", None) is not None:
                typer.echo(exc.ctx.get_help())
                result = 0
            else:
                say_error(exc.format_message())
                result = getattr(exc, "exit_code", 2)
        if not standalone_mode:
            return result
        sys.exit(result if isinstance(result, int) else 0)


def command_line() -> str:
    """The command as typed, for the records that say how something was made."""
    return "dopt " + " ".join(sys.argv[1:])
