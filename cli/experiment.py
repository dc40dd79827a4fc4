"""``dopt experiment ...``: run a named grid of runs and report on it."""

from pathlib import Path
from typing import Optional

import typer
from rich.table import Table

from sb3_disagree.cli.common import clean_errors, console

app = typer.Typer(help="Named experiments: grids of runs with curves and a table over seeds.", no_args_is_help=True)

OUT_OPT = typer.Option(None, "--out", help="Results folder (default: runs/experiments/NAME).")
DEFAULT_ROOT = Path("runs") / "experiments"


def _root(name: str, out: Optional[Path]) -> Path:
    return out if out is not None else DEFAULT_ROOT / name


@app.command("list")
def list_experiments() -> None:
    """The experiments shipped in sb3_disagree/data/experiments/."""
    from sb3_disagree.experiments.spec import SHIPPED, load_experiment

    t = Table("name", "goal", "cells", "seeds", "steps")
    for path in sorted(SHIPPED.glob("*.yaml")):
        e = load_experiment(str(path))
        t.add_row(e.name, e.goal, ", ".join(e.cells), str(len(e.seeds)), f"{e.steps:,}")
    console.print(t)


SEEDS_OPT = typer.Option(None, "--seeds", help="Only these of the experiment's seeds: 0,1,2")


def _seeds(text: Optional[str]) -> Optional[list[int]]:
    if not text:
        return None
    try:
        return [int(s) for s in text.split(",")]
    except ValueError:
        raise ValueError(f"--seeds takes whole numbers separated by commas, got {text!r}") from None


CELLS_OPT = typer.Option(None, "--cells", help="Only these cells: a,b")


def _cells(text: Optional[str]) -> Optional[list[str]]:
    return [c.strip() for c in text.split(",") if c.strip()] if text else None


@app.command("run")
def run(
    name: str = typer.Argument(..., help="A shipped experiment's name, or a YAML file."),
    backend: str = typer.Option("local", "--backend", help="local (a process pool) or ray."),
    jobs: Optional[int] = typer.Option(None, "--jobs", min=1, max=256, help="Runs at a time on the local backend (default: cores)."),
    address: Optional[str] = typer.Option(None, "--address", help="Ray cluster address (default: a local Ray)."),
    seeds: Optional[str] = SEEDS_OPT,
    cells: Optional[str] = CELLS_OPT,
    out: Optional[Path] = OUT_OPT,
) -> None:
    """Run every cell and seed of an experiment; finished runs are skipped."""
    with clean_errors():
        from sb3_disagree.experiments.runner import run_experiment
        from sb3_disagree.experiments.spec import load_experiment

        experiment = load_experiment(name)
        experiment.restrict(seeds=_seeds(seeds), cells=_cells(cells))
        root = _root(experiment.name, out)
        runs = experiment.runs()
        todo = [r for r in runs if not r.finished(root)]
        console.print(f"{experiment.name}: {len(runs)} runs, {len(runs) - len(todo)} finished, {len(todo)} to do "
                      f"({backend}) -> {root}")

        def show(result: dict) -> None:
            greedy = result.get("final_alone_greedy", {}).get("success_rate")
            console.print(f"  {result['cell']} seed {result['seed']}: {result['steps']:,} steps in "
                          f"{result['seconds']:.0f} s; the new policy alone "
                          + (f"{greedy:.2f} greedy, " if greedy is not None else "")
                          + f"{result['final_alone']['success_rate']:.2f} sampled"
                          + (f" (copied from {result['copied_from']})" if "copied_from" in result else ""))

        # Where no live display can draw (a log file, a scheduler), each run prints plain progress lines.
        run_experiment(experiment, root, backend=backend, jobs=jobs, address=address, on_result=show,
                       progress_every=None if console.is_terminal else 60.0)


@app.command("report")
def report(
    name: str = typer.Argument(..., help="A shipped experiment's name, or a YAML file."),
    out: Optional[Path] = OUT_OPT,
    figure: Optional[Path] = typer.Option(None, "--figure", help="Also write the figure here (PNG)."),
    seeds: Optional[str] = SEEDS_OPT,
    note: str = typer.Option("", "--note", help="What else ran on the machine meanwhile, said beside the machine."),
    section: Optional[Path] = typer.Option(None, "--section", help="Also write the report into this markdown page, "
                                           "between its <!-- NAME:start --> and <!-- NAME:end --> lines."),
    cells: Optional[str] = CELLS_OPT,
    title: Optional[str] = typer.Option(None, "--name", help="The report's own name, for a report on some cells "
                                        "beside the full one: NAME.md, NAME.png and the page's NAME block "
                                        "(default: the experiment's name and report.md)."),
) -> None:
    """Curves (mean and 95% band over seeds) and the table; writes report.md and a PNG in the results folder.
    ``--seeds`` compares cells on the seeds they share where some have more finished than others."""
    with clean_errors():
        from sb3_disagree.experiments.spec import load_experiment
        from sb3_disagree.experiments.writeup import report_files, write_report

        experiment, only, chosen = load_experiment(name), _seeds(seeds), _cells(cells)
        experiment.restrict(seeds=only, cells=chosen)
        root = _root(experiment.name, out)
        console.print(write_report(experiment, root, figure, note, section, only, chosen, title))
        markdown, png = report_files(root, experiment, title)
        console.print(f"wrote {markdown} and {png}"
                      + (f"; the section {title or experiment.name} of {section}" if section else ""))
