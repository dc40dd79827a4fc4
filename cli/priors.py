"""``dopt priors ...`` and ``dopt similarity``: the zoo and the choice of priors by language."""

import json
import time
from pathlib import Path
from typing import Optional

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from sb3_disagree.cli.common import DEFAULT_ENV, clean_errors, command_line, console
from sb3_disagree.cli.options import command, options_of, param_help
from sb3_disagree.defaults import PRIOR_CARD_SEED as CARD_SEED
from sb3_disagree.priors.language import load_embedding

app = typer.Typer(help="The prior zoo: list, show, add, remove, evaluate and train priors.", no_args_is_help=True)

ZOO_OPT = typer.Option(None, "--zoo", help="Zoo folder, 'greedy' for the shipped greedy zoo, or 'user' for yours "
                       "(default: the shipped zoo).")
WRITE_ZOO_OPT = typer.Option(None, "--zoo", help="Zoo folder to write to (default: yours, $SB3_DISAGREE_ZOO or "
                             "~/.local/share/sb3-disagree/zoo; the shipped zoos are read-only).")
WRITE_SHIPPED_OPT = typer.Option(False, "--write-shipped", help="Allow writing into a zoo the package ships.")
TRUST_OPT = typer.Option(False, "--trust", help="Open the model file as SB3 does, unpickling what it carries (a file "
                         "you made or trust).")
ENV_OPT = typer.Option(DEFAULT_ENV, "--env", help="Gymnasium id of the environment.")
EMB_OPT = typer.Option(None, "--embedding", help="Word vectors (word2vec/GloVe/fastText/KeyedVectors); default MiniLM.")


def _zoo(path: Optional[Path], writing: bool = False, write_shipped: bool = False):
    """The zoo a command reads (the shipped one by default) or writes (the user's by default)."""
    from sb3_disagree.priors.zoo import Zoo, user_zoo

    return Zoo(user_zoo() if writing and path is None else path, write_shipped=write_shipped)


class PlainProgress:
    """rich's Progress where no live bar can draw (a log file, a pipe): a flushed line per task at most every
    ``interval`` seconds, and one when the task completes."""

    def __init__(self, interval: float = 30.0) -> None:
        self.interval, self.tasks = interval, {}

    def __enter__(self) -> "PlainProgress":
        return self

    def __exit__(self, *exc) -> None:
        return None

    def add_task(self, description: str, total: int) -> int:
        self.tasks[len(self.tasks)] = dict(description=description, total=total, completed=0,
                                           start=time.perf_counter(), last=time.perf_counter())
        return len(self.tasks) - 1

    def advance(self, task: int, amount: int = 1) -> None:
        self.update(task, completed=self.tasks[task]["completed"] + amount)

    def update(self, task: int, completed: int) -> None:
        t, now = self.tasks[task], time.perf_counter()
        t["completed"] = completed
        if now - t["last"] >= self.interval or completed >= t["total"]:
            t["last"] = now
            print(f"{t['description']}: {completed}/{t['total']} | {now - t['start']:.0f}s", flush=True)


def _progress():
    if not console.is_terminal:
        return PlainProgress()
    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                    console=console, transient=True)


@app.command("list")
def list_priors(
    env: Optional[str] = typer.Option(None, "--env", help="Only this environment's priors."),
    goal: Optional[str] = typer.Option(None, "--goal", help="Rank by similarity to this goal and mark the two chosen."),
    k: int = typer.Option(2, "--k", help="How many priors the goal would use."),
    zoo: Optional[Path] = ZOO_OPT,
    embedding: Optional[Path] = EMB_OPT,
) -> None:
    """The zoo as a table; damaged entries are listed with their problem."""
    with clean_errors():
        from sb3_disagree.priors.select import rank_entries

        entries = _zoo(zoo).entries(env or (DEFAULT_ENV if goal else None))
        sims, chosen = rank_entries(goal, entries, load_embedding(embedding), k) if goal else ({}, set())
        entries.sort(key=lambda e: -sims.get(e.goal, 2.0))
        console.print(_zoo_table(entries, goal, sims, chosen))
        if goal and len(chosen) < k:
            console.print(f"[yellow]only {len(chosen)} usable prior(s) besides {goal!r}; the method needs {k}[/]")


def _zoo_table(entries: list, goal: Optional[str], sims: dict[str, float], chosen: set[str]) -> Table:
    from sb3_disagree.priors.zoo import memory_label

    envs = sorted({e.env_id for e in entries})
    table = Table(title=(f"priors for {goal!r}" if goal else "prior zoo") + (f" in {envs[0]}" if len(envs) == 1 else ""))
    table.add_column("goal", no_wrap=True)
    if len(envs) > 1:
        table.add_column("env", overflow="fold")
    for col in ["algorithm", "method", "steps", "frames", "success greedy", "success sampled",
                *(["similarity", ""] if goal else []), "status"]:
        table.add_column(col, no_wrap=col in ("similarity", ""))
    for e in entries:
        card = e.card
        success = [(c.get("success_rate") if card else None) for c in
                   ((card.evaluation_greedy, card.evaluation) if card else ({}, {}))]
        row = [e.goal, *([e.env_id] if len(envs) > 1 else []), card.sb3_class.rsplit(".", 1)[-1] if card else "?",
               str(card.training.get("method", "?")) if card else "?", str(card.training.get("steps", "?")) if card else "?",
               memory_label(card.training) if card else "?",
               *(f"{v:.2f}" if v is not None else "-" for v in success)]
        if goal:
            row += [f"{sims[e.goal]:.3f}" if e.goal in sims else "(goal)", "[bold green]chosen[/]" if e.goal in chosen else ""]
        row.append("[green]ok[/]" if not e.problem else f"[red]{e.problem}[/]")
        table.add_row(*row)
    return table


@app.command()
def show(goal: str, env: str = ENV_OPT, zoo: Optional[Path] = ZOO_OPT) -> None:
    """A prior's card."""
    with clean_errors():
        entry = _zoo(zoo).get(goal, env)
        console.print_json(json.dumps(entry.card.__dict__ if entry.card else {}))
        console.print(f"status: {'ok' if not entry.problem else entry.problem}")


@app.command()
def add(
    model: Path = typer.Argument(..., help="An SB3 model file (ACER, PPO, A2C, TRPO, MaskablePPO)."),
    goal: Optional[str] = typer.Option(None, "--goal", help="The goal it reaches (default: the goal on the model "
                                       "card (README.md) beside the model)."),
    env: str = ENV_OPT,
    episodes: int = typer.Option(100, "--episodes", help="Evaluation episodes for the card (0: none)."),
    replace: bool = typer.Option(False, "--replace", help="Replace an existing prior for this goal."),
    zoo: Optional[Path] = WRITE_ZOO_OPT,
    write_shipped: bool = WRITE_SHIPPED_OPT,
    trust: bool = TRUST_OPT,
) -> None:
    """Add a saved model to your zoo, evaluated and with its card; a model card beside the model (as dopt train
    writes) gives the goal and how the model was trained (sb3_disagree.priors.make.add_prior)."""
    with clean_errors():
        from sb3_disagree.priors.make import add_prior

        z = _zoo(zoo, writing=True, write_shipped=write_shipped)
        with _progress() as progress:
            tasks = {label: progress.add_task(f"evaluating ({label})", total=episodes) for label in ("greedy", "sampled")}
            entry, evaluations = add_prior(z, model, env, goal, episodes, replace, command_line(),
                                           lambda label, n: progress.update(tasks[label], completed=n), trust)
        _show_evaluations(entry.goal, evaluations)
        console.print(f"added {entry.goal!r} to {z.root}")


@app.command()
def remove(goal: str, env: str = ENV_OPT, zoo: Optional[Path] = WRITE_ZOO_OPT,
           write_shipped: bool = WRITE_SHIPPED_OPT) -> None:
    """Remove a prior from your zoo."""
    with clean_errors():
        _zoo(zoo, writing=True, write_shipped=write_shipped).remove(goal, env)
        console.print(f"removed {goal!r}")


@app.command("eval")
def eval_prior(
    goal: str,
    episodes: int = typer.Option(100, "--episodes", min=1),
    deterministic: Optional[bool] = typer.Option(None, "--deterministic/--stochastic", help="Only greedy or only "
                                                 "sampled actions (default: both, side by side)."),
    seed: int = typer.Option(CARD_SEED, "--seed", help="Seed of the first env; the card's episodes start at 10000."),
    record: bool = typer.Option(False, "--record", help="Write the evaluations on the prior's card."),
    env: str = ENV_OPT,
    zoo: Optional[Path] = ZOO_OPT,
    write_shipped: bool = WRITE_SHIPPED_OPT,
) -> None:
    """Evaluate a prior alone from the environment's start distribution, greedy and sampled."""
    with clean_errors():
        z = _zoo(zoo, write_shipped=write_shipped)
        if record:
            z.check_writable()  # before the episodes
        entry = z.get(goal, env)
        for greedy in (True, False) if deterministic is None else (deterministic,):
            result = _evaluate(z, entry, episodes, greedy, seed)
            console.print(f"{goal}: success {result.success_rate:.2f}, mean length {result.mean_length:.1f}, "
                          f"mean return {result.mean_return:.2f} over {episodes} episodes "
                          f"({'greedy' if greedy else 'sampled'} actions)")
            if record:
                entry = z.record_evaluation(entry, {**result.as_dict(), "seed": seed})
                console.print(f"recorded on {entry.path / 'card.json'}")


def _make_options() -> list:
    from sb3_disagree.priors.make import make_prior, train_dagger

    return [*options_of(make_prior, only=("goal", "method", "env_id", "steps", "n_envs", "seed", "episodes", "replace",
                                                 "consistency_rounds", "consistency_steps",
                                                 "consistency_loop_uniform", "consistency_validation_episodes",
                                                 "consistency_expert_in_loops"),
                        flags={"env_id": "--env"}, defaults={"env_id": DEFAULT_ENV}),
            *options_of(train_dagger, only=("rounds", "steps_per_round", "epochs", "final_epochs",
                                            "validation_episodes", "learner_actions", "frame_stack", "loop_flags",
                                            "flags_cnn", "expert_no_return"),
                        flags={"loop_flags": "--loop-flags/--no-loop-flags"},
                        helps={k: "DAgger: " + v for k, v in param_help(train_dagger).items()}),
            *options_of(_writes, only=("zoo", "write_shipped"))]


def _writes(zoo: Optional[Path] = WRITE_ZOO_OPT, write_shipped: bool = WRITE_SHIPPED_OPT) -> None:
    """The options of a command that writes a prior."""


@app.command()
@command(_make_options())
def train(**options) -> None:
    """Train a prior for a goal and add it to the zoo with its card (sb3_disagree.priors.make.make_prior)."""
    with clean_errors():
        from sb3_disagree.priors.make import make_prior

        goal, method, zoo = options.pop("goal"), options.pop("method"), options.pop("zoo")
        z = _zoo(zoo, writing=True, write_shipped=options.pop("write_shipped"))
        dagger = {k: options.pop(k) for k in ("rounds", "steps_per_round", "epochs", "final_epochs",
                                              "validation_episodes", "learner_actions", "frame_stack",
                                              "loop_flags", "flags_cnn", "expert_no_return")}
        with _progress() as progress:
            # a line per round, and one each for the kept round and the final epochs where there are any
            lines = dagger["rounds"] + (dagger["validation_episodes"] > 0) + (dagger["final_epochs"] > 0)
            phase = options["consistency_rounds"]
            kept = phase > 0 and options["consistency_validation_episodes"] > 0  # the line of the kept round
            total = (lines if method == "dagger" else 1) + phase + kept
            task = progress.add_task(f"{method} {goal}", total=total)
            entry, evaluations = make_prior(z, goal, method=method, command=command_line(),
                                            progress=lambda line: (progress.advance(task), console.print(line)),
                                            **options, **(dagger if method == "dagger" else {}))
        _show_evaluations(goal, evaluations)


def _refine_options() -> list:
    from sb3_disagree.priors.make import refine_entry

    return [*options_of(refine_entry, only=("goal", "env_id", "rounds", "steps", "loop_uniform", "n_envs", "seed",
                                            "episodes", "only_if_better", "validation_episodes",
                                            "expert_in_loops"),
                        flags={"env_id": "--env"}, defaults={"env_id": DEFAULT_ENV}),
            *options_of(_writes, only=("zoo", "write_shipped"))]


@app.command()
@command(_refine_options())
def refine(**options) -> None:
    """Run the greedy-consistency phase on a prior in the zoo, replacing it and its card's evaluations
    (sb3_disagree.priors.make.refine_entry)."""
    with clean_errors():
        from sb3_disagree.priors.make import refine_entry

        goal, zoo = options.pop("goal"), options.pop("zoo")
        z = _zoo(zoo, writing=True, write_shipped=options.pop("write_shipped"))
        with _progress() as progress:
            task = progress.add_task(f"refining {goal}", total=options["rounds"] + (options["validation_episodes"] > 0))
            entry, evaluations, replaced = refine_entry(
                z, goal, command=command_line(),
                progress=lambda line: (progress.advance(task), console.print(line)), **options)
        _show_evaluations(goal, evaluations)
        if not replaced:
            card = entry.card
            console.print(f"kept the prior in the zoo: the refined one is no better alone (the lower of greedy and "
                          f"sampled success {min(e.success_rate for e in evaluations.values()):.3f}, the card's "
                          f"{min(card.evaluation_greedy['success_rate'], card.evaluation['success_rate']):.3f})")


def _evaluate(z, entry, episodes: int, deterministic: bool, seed: int):
    """Run a zoo entry alone for some episodes on 4 envs seeded from ``seed``, with a progress display."""
    from sb3_disagree.priors.make import evaluate_entry

    with _progress() as progress:
        task = progress.add_task(f"evaluating {entry.goal}", total=episodes)
        return evaluate_entry(z, entry, episodes, deterministic, seed, lambda n: progress.update(task, completed=n))


def _show_evaluations(goal: str, evaluations: dict) -> None:
    for label, result in evaluations.items():
        console.print(f"{goal}: success {result.success_rate:.2f} over {result.episodes} episodes ({label}), "
                      f"mean length {result.mean_length:.1f}")


def similarity(
    words: list[str] = typer.Argument(..., help="Goal words (quote multi-word goals)."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Draw the matrix as a heatmap PNG."),
    embedding: Optional[Path] = EMB_OPT,
) -> None:
    """Cosine similarities between goal words, as the paper's Figure 1."""
    with clean_errors():
        from sb3_disagree.priors.language import normalise_goal

        emb = load_embedding(embedding)
        labels = [normalise_goal(w) for w in words]
        m = emb.similarity_matrix(labels)
        table = Table(title=f"cosine similarity ({emb.name})")
        table.add_column("")
        for w in labels:
            table.add_column(w, justify="right")
        for i, w in enumerate(labels):
            table.add_row(w, *[f"{m[i, j]:.4f}" for j in range(len(labels))])
        console.print(table)
        if plot is not None:
            from sb3_disagree.plots import similarity_heatmap

            similarity_heatmap(m, labels, plot, title=f"cosine similarity, {emb.name}")
            console.print(f"wrote {plot}")
