"""Entry point of the ``dopt`` command line: a thin Typer layer over the library."""

from typing import Optional

import typer

from sb3_disagree.cli.common import OneLineErrors
from sb3_disagree.version import __version__

app = typer.Typer(
    cls=OneLineErrors,
    name="dopt",
    help="Disagreement Options: learn a new navigation goal by reusing the policies you already have.",
    no_args_is_help=True,
    add_completion=False,
)


def _version_callback(value: bool) -> None:
    if value:
        typer.echo(f"dopt (sb3-disagree) {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Optional[bool] = typer.Option(
        None, "--version", callback=_version_callback, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    """Disagreement Options on Stable-Baselines3."""


import sb3_disagree.cli.experiment as _experiment  # noqa: E402
import sb3_disagree.cli.priors as _priors  # noqa: E402
import sb3_disagree.cli.train as _train  # noqa: E402

app.command("train")(_train.train)
app.command("eval")(_train.eval_run)
app.command("consistency")(_train.consistency)
app.add_typer(_priors.app, name="priors")
app.command("similarity")(_priors.similarity)
app.add_typer(_experiment.app, name="experiment")


def main() -> None:
    app()


if __name__ == "__main__":
    main()
