"""
Aggregating an experiment: curves with a 95% band over seeds, and a table per cell of steps to 50% and
90% training success, success at fixed budgets, the normalised area under the curve, and the final
success of the new policy alone (no priors).
"""

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

from sb3_disagree.envs.navigation import MAX_EPISODE_STEPS
from sb3_disagree.experiments.curves import (
    TRAINING_CURVES,
    check_monitor_coverage,
    has_monitors,
    last_defined,
    mean_and_band,
    progress_curve,
    read_training_curves,
    steps_to,
    success_curve,
)
from sb3_disagree.experiments.spec import RESULT, Experiment

GRID_POINTS = 50


MIN_SEEDS_FOR_BAND = 3


@dataclass
class CellSummary:
    """What the report says about one cell, over its finished seeds."""

    cell: str
    seeds: list[int]
    mean: np.ndarray
    low: np.ndarray
    high: np.ndarray
    usage: np.ndarray
    steps_to_50: Optional[float]
    steps_to_90: Optional[float]
    at_budgets: dict[int, float]
    auc: float
    final_alone: float
    final_alone_seeds: list[float]
    fps: float
    minutes: float = float("nan")  # wall-clock per run (training, the periodic evaluations included)
    records: list[dict] = field(default_factory=list)
    alone_steps: np.ndarray = field(default_factory=lambda: np.zeros(0))
    alone_mean: np.ndarray = field(default_factory=lambda: np.zeros(0))
    alone_greedy: np.ndarray = field(default_factory=lambda: np.zeros(0))  # empty where not measured
    final_greedy_seeds: list[float] = field(default_factory=list)  # empty where not measured
    seed_final: list[float] = field(default_factory=list)  # each seed's training success at the end of its run
    seed_steps_to_90: list[Optional[float]] = field(default_factory=list)
    seed_curves: list[np.ndarray] = field(default_factory=list)  # each seed's training success on the grid


def cell_colors(n: int) -> list[tuple[float, float, float]]:
    """
    One colour per cell: tab10 for up to 10 cells, else tab20, tab20b and tab20c one after the other (60
    colours; a colormap indexed past its end repeats its last colour, which made the later cells of a large grid
    look alike).

    :param n: The number of cells
    :return: ``n`` RGB colours, distinct for up to 60 cells (then repeating)
    """
    import matplotlib.pyplot as plt

    palette = [c for name in (("tab10",) if n <= 10 else ("tab20", "tab20b", "tab20c"))
               for c in plt.get_cmap(name).colors]
    return [tuple(palette[i % len(palette)]) for i in range(n)]


def alone_curve(folders: list[Path], key: str = "successes") -> tuple[np.ndarray, np.ndarray]:
    """The periodic evaluations of the new policy alone (``evaluations.npz``), averaged over runs at common
    steps: sampled actions (``successes``) or greedy ones (``successes_greedy``, where the runs measured it)."""
    evals = [np.load(f / "evaluations.npz") for f in folders if (f / "evaluations.npz").exists()]
    if not evals or any(key not in e for e in evals):
        return np.zeros(0), np.zeros(0)
    n = min(len(e["timesteps"]) for e in evals)
    steps = evals[0]["timesteps"][:n]
    return steps, np.mean([e[key][:n].mean(axis=1) for e in evals], axis=0)


def summarize(experiment: Experiment, root: Path) -> tuple[np.ndarray, list[CellSummary]]:
    """Read every finished run of the experiment under ``root`` and summarise each cell."""
    every_run = experiment.runs()
    # A run whose greedy phase waits until it is ready may train past its budget, up to `extend` times it.
    end = max(int(r.config.steps * r.config.extend) if r.config.ready else r.config.steps for r in every_run)
    grid = np.linspace(end / GRID_POINTS, end, GRID_POINTS)
    # The area under the curve over the budget every run has: a run that stopped there (ready early) has no curve
    # past it, and counting that as zero would rank a faster learner lower.
    common = grid <= experiment.steps + grid[0] / 2
    summaries = []
    finished = [r for r in every_run if r.finished(root)]
    stored = read_training_curves(root, grid)
    for cell in experiment.cells:
        runs = [r for r in finished if r.cell == cell]
        if not runs:
            continue
        folders = [r.folder(root) for r in runs]
        records = [json.loads((f / RESULT).read_text()) for f in folders]
        # Nothing past a run's own end: a log's last value is not held beyond it.
        ended = [grid > record["steps"] + grid[0] / 2 for record in records]
        curves = []
        for run, folder, record, past in zip(runs, folders, records, ended):
            if has_monitors(folder):
                limit = run.config.env_kwargs.get("max_episode_steps", MAX_EPISODE_STEPS)
                legs = 2 if "from_steps" in record else 1  # a continued run lost an unfinished episode per env twice
                check_monitor_coverage(folder, record["steps"], run.config.n_envs, limit, legs=legs)
                curve = success_curve(folder, grid)
                curve[past] = np.nan
                curves.append(curve)
            elif (cell, run.seed) in stored:
                curves.append(stored[(cell, run.seed)])
            else:
                raise ValueError(f"{folder}: no monitor files, and {root / TRAINING_CURVES} has no curve of it; "
                                 "its training curve cannot be read")
        mean, low, high = mean_and_band(curves)
        usage = np.full(len(grid), np.nan)
        if runs[0].config.mode != "scratch":
            usages = [progress_curve(f, "prior/usage", grid, smooth=5) for f in folders]
            for u, past in zip(usages, ended):
                u[past] = np.nan
            usage = mean_and_band(usages)[0]
        at = {}
        for b in experiment.budgets:
            i = int(np.searchsorted(grid, b, side="right")) - 1
            at[b] = float(mean[i]) if i >= 0 else float("nan")
        alone = [r["final_alone"]["success_rate"] for r in records]
        alone_steps, alone_mean = alone_curve(folders)
        alone_greedy = alone_curve(folders, "successes_greedy")[1]
        greedy = [r["final_alone_greedy"]["success_rate"] for r in records if "final_alone_greedy" in r]
        summaries.append(CellSummary(
            cell=cell, seeds=[r.seed for r in runs], mean=mean, low=low, high=high, usage=usage,
            steps_to_50=steps_to(mean, grid, 0.5), steps_to_90=steps_to(mean, grid, 0.9), at_budgets=at,
            auc=float(np.mean(np.nan_to_num(mean[common], nan=0.0))), final_alone=float(np.mean(alone)),
            final_alone_seeds=alone, fps=float(np.mean([r["fps"] for r in records])),
            minutes=float(np.mean([r["seconds"] for r in records])) / 60, records=records,
            alone_steps=alone_steps, alone_mean=alone_mean, alone_greedy=alone_greedy,
            final_greedy_seeds=greedy if len(greedy) == len(records) else [], seed_final=[last_defined(c) for c in curves],
            seed_steps_to_90=[steps_to(c, grid, 0.9) for c in curves], seed_curves=curves))
    return grid, summaries


def _per_seed(values: list[float]) -> str:
    """The mean and, in brackets, each seed's value; "not measured" for none."""
    if not values:
        return "not measured"
    return f"{np.mean(values):.2f} ({', '.join(f'{v:.2f}' for v in values)})"


def _steps(value: Optional[float]) -> str:
    return f"{value / 1000:g}k" if value is not None else "not reached"


def table_markdown(experiment: Experiment, summaries: list[CellSummary]) -> str:
    """The report's table as Markdown."""
    budgets = "".join(f" success at {_steps(b)} |" for b in experiment.budgets)
    lines = [f"| cell | seeds | steps to 50% | steps to 90% |{budgets} AUC | new policy alone (final), greedy | "
             "new policy alone (final), sampled | env steps/s | minutes per run |",
             "|---" * (9 + len(experiment.budgets)) + "|"]
    for s in summaries:
        # "-" at a budget no run of the cell reached (a grid whose budget follows the goal)
        at = "".join(f" {s.at_budgets[b]:.2f} |" if np.isfinite(s.at_budgets[b]) else " - |" for b in experiment.budgets)
        lines.append(f"| {s.cell} | {len(s.seeds)} | {_steps(s.steps_to_50)} | {_steps(s.steps_to_90)} |{at} "
                     f"{s.auc:.2f} | {_per_seed(s.final_greedy_seeds)} | {_per_seed(s.final_alone_seeds)} | {s.fps:.0f} | "
                     f"{s.minutes:.1f} |")
    return "\n".join(lines)


def alone_markdown(summaries: list[CellSummary]) -> Optional[str]:
    """
    The new policy alone along the way (the runs' periodic evaluations, mean over seeds), greedy / sampled at
    each evaluation step; None when no cell measured greedy actions.
    """
    cells = [s for s in summaries if len(s.alone_greedy)]
    if not cells:
        return None
    steps = sorted({int(t) for s in cells for t in s.alone_steps[:len(s.alone_greedy)]})
    lines = ["| cell | " + " | ".join(f"{_steps(t)} greedy / sampled" for t in steps) + " |",
             "|---" * (len(steps) + 1) + "|"]
    for s in cells:
        at = {int(t): (g, m) for t, g, m in zip(s.alone_steps, s.alone_greedy, s.alone_mean)}
        lines.append(f"| {s.cell} | " + " | ".join(f"{at[t][0]:.2f} / {at[t][1]:.2f}" if t in at else "-"
                                                    for t in steps) + " |")
    return "\n".join(lines)


def seeds_markdown(summaries: list[CellSummary]) -> str:
    """Per seed: training success at the end of the run, and the step where it first reached 90%."""
    lines = ["| cell | seeds | training success at the end | steps to 90% |", "|---|---|---|---|"]
    for s in summaries:
        lines.append(f"| {s.cell} | {', '.join(map(str, s.seeds))} | {', '.join(f'{v:.2f}' for v in s.seed_final)} | "
                     f"{', '.join(_steps(v) for v in s.seed_steps_to_90)} |")
    return "\n".join(lines)


def _ratio(steps: Optional[float], baseline: Optional[float], end: float) -> str:
    """``steps / baseline``; a curve that never reached the level counts as the run's length, which bounds the ratio."""
    if steps is not None and baseline is not None:
        return f"{steps / baseline:.2f}"
    if steps is not None:
        return f"< {steps / end:.2f}"
    if baseline is not None:
        return f"> {end / baseline:.2f}"
    return "-"


def ratio_markdown(grid: np.ndarray, summaries: list[CellSummary], cell: str = "disagreement",
                   baseline: str = "scratch") -> Optional[str]:
    """
    Steps to 90% training success of ``cell`` over those of ``baseline``: per seed both ran, and from the
    mean curves. Where a curve never gets there the run's length stands in, so the ratio is a bound.

    :return: A Markdown table, or None when the experiment lacks one of the cells
    """
    by_name = {s.cell: s for s in summaries}
    if cell not in by_name or baseline not in by_name:
        return None
    ours, theirs = by_name[cell], by_name[baseline]
    lines = [f"| seed | {cell}: steps to 90% | {baseline}: steps to 90% | ratio |", "|---|---|---|---|"]
    for seed, steps in zip(ours.seeds, ours.seed_steps_to_90):
        if seed in theirs.seeds:
            other = theirs.seed_steps_to_90[theirs.seeds.index(seed)]
            lines.append(f"| {seed} | {_steps(steps)} | {_steps(other)} | {_ratio(steps, other, grid[-1])} |")
    lines.append(f"| mean curves | {_steps(ours.steps_to_90)} | {_steps(theirs.steps_to_90)} | "
                 f"{_ratio(ours.steps_to_90, theirs.steps_to_90, grid[-1])} |")
    return "\n".join(lines)


def chosen_priors(folder: Path) -> list[str]:
    """The priors a run used, as its ``config.yaml`` records them (empty where it records none)."""
    import yaml

    path = folder / "config.yaml"
    return list(yaml.safe_load(path.read_text()).get("chosen_priors") or []) if path.exists() else []


@dataclass
class GoalRow:
    """One goal of a goals table: its priors, and per base cell its summary (None where no seed finished)."""

    goal: str
    priors: list[str]
    cells: dict[str, Optional[CellSummary]]


def goal_rows(experiment: Experiment, summaries: list[CellSummary], root: Path) -> tuple[list[str], list[GoalRow]]:
    """A goals table's base cells (``CELL`` of ``CELL@GOAL``, in the grid's order) and one row per goal."""
    by_name = {s.cell: s for s in summaries}
    bases = list(dict.fromkeys(c.split("@")[0] for c in experiment.cells))
    rows = []
    for goal in experiment.goals:
        cells = {b: by_name.get(f"{b}@{goal}") for b in bases}
        done = [s for s in cells.values() if s is not None]
        priors = chosen_priors(root / done[0].cell / f"seed-{done[0].seeds[0]}") if done else []
        rows.append(GoalRow(goal, priors, cells))
    return bases, rows


def _run_steps(s: CellSummary) -> str:
    """The env steps a cell's runs trained (each seed's where they differ: a budget that grew)."""
    steps = [int(r["steps"]) for r in s.records]
    if not steps:
        return "-"
    steps = [round(v, -3) for v in steps]  # to the thousand: a grown budget ends at a segment's end
    return _steps(steps[0]) if len(set(steps)) == 1 else ", ".join(_steps(v) for v in steps)


def goals_markdown(experiment: Experiment, summaries: list[CellSummary], root: Path) -> str:
    """
    A goals table: per goal, its priors and per base cell the policy alone greedy and sampled (mean over seeds,
    each seed in brackets) and the step where the mean training curve first reaches 90%; then, per base cell, the
    mean over the goals measured and the lowest goal.
    """
    bases, rows = goal_rows(experiment, summaries, root)
    head = "| goal | priors |" + "".join(f" {b}: greedy | {b}: sampled | {b}: 90% training success | {b}: env steps |"
                                        for b in bases)
    lines = [head, "|---" * (2 + 4 * len(bases)) + "|"]
    for row in rows:
        line = f"| {row.goal} | {', '.join(row.priors) or '-'} |"
        for b in bases:
            s = row.cells[b]
            line += (" not run | not run | not run | |" if s is None else
                     f" {_per_seed(s.final_greedy_seeds)} | {_per_seed(s.final_alone_seeds)} | {_steps(s.steps_to_90)} | "
                     f"{_run_steps(s)} |")
        lines.append(line)
    for label, pick in (("mean over the goals run", np.mean), ("lowest goal", np.min)):
        line = f"| **{label}** | |"
        for b in bases:
            done = [r.cells[b] for r in rows if r.cells[b] is not None and r.cells[b].final_greedy_seeds]
            if not done:
                line += " - | - | | |"
                continue
            greedy = [float(np.mean(s.final_greedy_seeds)) for s in done]
            sampled = [float(np.mean(s.final_alone_seeds)) for s in done]
            which = ""
            if pick is np.min:  # the goals that are lowest
                goal_of = [s.cell.split("@")[1] for s in done]
                which = f" ({goal_of[int(np.argmin(greedy))]}; sampled: {goal_of[int(np.argmin(sampled))]})"
            line += f" **{pick(greedy):.2f}**{which} | **{pick(sampled):.2f}** | | |"
        lines.append(line)
    return "\n".join(lines)


def plot_goals(experiment: Experiment, summaries: list[CellSummary], out: Path, root: Path) -> None:
    """The policy alone per goal: a bar per base cell (greedy, mean over seeds), a tick where sampled reached, and
    each seed's greedy value as a dot."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    bases, rows = goal_rows(experiment, summaries, root)
    colors = cell_colors(len(bases))
    width = 0.8 / len(bases)
    fig, ax = plt.subplots(figsize=(max(8.0, 1.1 * len(rows)), 4.2))  # the title's width at least
    for j, b in enumerate(bases):
        label = f"{b}: greedy (bar, seeds as dots), sampled (black tick)"
        for i, row in enumerate(rows):
            s = row.cells[b]
            if s is None or not s.final_greedy_seeds:
                continue
            x = i - 0.4 + width * (j + 0.5)
            ax.bar(x, np.mean(s.final_greedy_seeds), width * 0.9, color=colors[j], label=label)
            label = None
            ax.plot([x] * len(s.final_greedy_seeds), s.final_greedy_seeds, "o", color="black", markersize=3)
            ax.plot([x - width * 0.45, x + width * 0.45], [np.mean(s.final_alone_seeds)] * 2, color="black", linewidth=2)
    ax.set_xticks(range(len(rows)), [f"{r.goal}\n({', '.join(r.priors)})" if r.priors else r.goal for r in rows],
                  fontsize=7)
    longest = max((int(r["steps"]) for s in summaries for r in s.records), default=experiment.steps)
    budget = f"{experiment.steps // 1000}k env steps" + (f" (up to {longest // 1000}k where the greedy phase waited)"
                                                         if longest > experiment.steps + 1000 else "")
    ax.set(ylabel="success of the policy alone (100 episodes)", ylim=(0, 1.05),
           title=f"{experiment.name}: the policy alone per goal, {budget}")
    ax.axhline(0.85, color="grey", linestyle=":", linewidth=1)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, fontsize=7, frameon=False)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100, bbox_inches="tight")  # the legend sits under the goals' names
    plt.close(fig)


def plot(experiment: Experiment, grid: np.ndarray, summaries: list[CellSummary], out: Path, root: Path) -> None:
    """Training success (mean and 95% band) and prior usage against env steps; recorded paths if asked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    n_paths = len(summaries) if experiment.trajectories else 0
    # Curves on the first row; with trajectories, one map per cell on a second row.
    legend_rows = -(-len(summaries) // 4)  # the legend sits under the figure, four cells a row
    legend_height = 0.35 + 0.22 * legend_rows
    fig = plt.figure(figsize=(11, 4.2 + legend_height + (3.6 if n_paths else 0)))
    grid_spec = fig.add_gridspec(2 if n_paths else 1, max(n_paths, 2) * 2 if n_paths else 2)
    half = grid_spec.ncols // 2
    ax1 = fig.add_subplot(grid_spec[0, :half])
    ax2 = fig.add_subplot(grid_spec[0, half:], sharex=ax1)  # the same steps, and their labels thinned alike
    path_axes = [fig.add_subplot(grid_spec[1, 2 * j:2 * j + 2]) for j in range(n_paths)]
    colors = cell_colors(len(summaries))
    for i, s in enumerate(summaries):
        # With two seeds the t-interval (t = 12.7) spans the whole axis and hides the curves: no band then.
        banded = len(s.seeds) >= MIN_SEEDS_FOR_BAND
        label = f"{s.cell} ({len(s.seeds)} seed{'s' if len(s.seeds) > 1 else ''}{'' if banded or len(s.seeds) == 1 else ', no band'})"
        ax1.plot(grid, s.mean, color=colors[i], label=label)
        if banded:
            ax1.fill_between(grid, np.clip(s.low, 0, 1), np.clip(s.high, 0, 1), color=colors[i], alpha=0.2)
        if len(s.alone_steps):
            ax1.plot(s.alone_steps, s.alone_mean, "--o", color=colors[i], markersize=3, linewidth=1)
        if len(s.alone_greedy):
            ax1.plot(s.alone_steps[:len(s.alone_greedy)], s.alone_greedy, ":s", color=colors[i], markersize=3,
                     linewidth=1)
        if not np.all(np.isnan(s.usage)):
            ax2.plot(grid, s.usage, color=colors[i], label=s.cell)
    priors = experiment.priors if isinstance(experiment.priors, str) else " + ".join(experiment.priors)
    ax1.set(xlabel="env steps", ylabel="training success rate (last 50 episodes)", ylim=(-0.02, 1.02),
            title=f"{experiment.name}: {experiment.goal}, priors {priors}")
    ax2.set(xlabel="env steps", ylabel="share of steps following the priors", ylim=(-0.02, 1.02),
            title="prior usage (mean over seeds)")
    for ax in (ax1, ax2):  # "150k", not "150000": six-digit labels run into each other
        ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda x, _: f"{x / 1000:g}k" if x else "0"))
    legend_title = None
    if any(len(s.alone_greedy) for s in summaries):
        legend_title = "solid: training; the new policy alone: dashed sampled, dotted greedy"
    elif any(len(s.alone_steps) for s in summaries):
        legend_title = "solid: training; dashed: the new policy alone (sampled)"
    handles, labels = ax1.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 4), fontsize=8, title=legend_title,
               title_fontsize=8, frameon=False)
    if ax2.lines:
        ax2.legend(loc="upper right", fontsize=8)
    else:
        ax2.text(0.5, 0.5, "no cell here follows the priors", ha="center", va="center", transform=ax2.transAxes)
    for ax, s in zip(path_axes, summaries):
        _draw_path(ax, experiment, root / s.cell / f"seed-{s.seeds[0]}", s.cell)
    fig.tight_layout(rect=(0, legend_height / fig.get_figheight(), 1, 1))
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100, bbox_inches="tight")  # long cell names widen the legend beyond the axes
    plt.close(fig)


def _draw_path(ax, experiment: Experiment, run_dir: Path, title: str) -> None:
    """The last complete recorded episode of a run, on the apartment's map, green where priors led."""
    from sb3_disagree.run.trajectories import draw_episode, read_episodes

    records = read_episodes(run_dir)
    complete = [r for r in records if r["complete"]] or records
    ax.axis("off")
    if not complete or not experiment.env_id.startswith("sb3_disagree/Apartment"):
        ax.set_title(f"{title}: no recorded episode")
        return
    record = complete[-1]
    ax.imshow(draw_episode(record, experiment.env_id, experiment.goal))
    tags = record["tags"][1:]
    ax.set_title(f"{title}: episode at {record['timesteps'] // 1000}k steps, "
                 f"{tags.count('prior')}/{len(tags)} on priors", fontsize=9)
