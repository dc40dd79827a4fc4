"""What the ``dopt`` commands share: the console, clean failures, defaults."""

import contextlib
import os
import sys
from collections.abc import Iterator

import typer
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


@contextlib.contextmanager
def clean_errors() -> Iterator[None]:
    try:
        yield
    except USER_ERRORS as exc:
        message = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)
        err_console.print(f"[bold red]error:[/] {escape(message)}", highlight=False, soft_wrap=True)
        raise typer.Exit(code=2) from None


def command_line() -> str:
    """The command as typed, for the records that say how something was made."""
    return "dopt " + " ".join(sys.argv[1:])
