"""
An experiment's write-up: the figure and the markdown (commands, seeds, machine, table, per-seed numbers,
the policy alone along the way) as ``report.md`` beside its runs, and, when asked, as a named section of a
documentation page, so that a page's numbers are always the ones its runs give. Every run's training-success
curve is kept in the results folder's ``training-success.csv``, from which the report is made again once the
runs' per-episode monitor files are gone (they are not committed).
"""

import os
import platform
import re
from pathlib import Path
from typing import Optional

import yaml

from sb3_disagree.experiments.curves import write_training_curves
from sb3_disagree.experiments.report import (alone_markdown, goals_markdown, plot, plot_goals, ratio_markdown,
                                             seeds_markdown, summarize, table_markdown)
from sb3_disagree.experiments.spec import Experiment
from sb3_disagree.run.presets import acer_signature_defaults


def write_section(page: Path, name: str, title: str, body: str) -> None:
    """
    Replace the block between ``<!-- name:start -->`` and ``<!-- name:end -->`` in a markdown page, or append it
    under ``## title`` when the page does not have it yet; the rest of the page is left as it is.
    """
    page = Path(page)
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    block = f"{start}\n{body.strip()}\n{end}"
    text = page.read_text() if page.exists() else f"# {page.stem.capitalize()}\n"
    if start in text:
        head, rest = text.split(start, 1)
        text = head + block + rest.split(end, 1)[1]
    else:
        text = text.rstrip() + f"\n\n## {title}\n\n{block}\n"
    page.write_text(text)


def report_files(root: Path, experiment: Experiment, name: Optional[str] = None) -> tuple[Path, Path]:
    """The markdown and the figure that the report of this name (default: the experiment's own) writes in ``root``."""
    name = name or experiment.name
    return root / ("report.md" if name == experiment.name else f"{name}.md"), root / f"{name}.png"


def write_report(experiment: Experiment, root: Path, figure: Optional[Path] = None, note: str = "",
                 section: Optional[Path] = None, seeds: Optional[list[int]] = None,
                 cells: Optional[list[str]] = None, name: Optional[str] = None) -> str:
    """
    Write an experiment's figure and ``report.md`` into its results folder, and optionally its section of a page.

    :param experiment: The experiment (restricted to the seeds and cells to report, if any)
    :param root: Its results folder
    :param figure: Also write the figure here (the page links this one)
    :param note: What else ran on the machine meanwhile, said beside the machine
    :param section: A markdown page whose ``<!-- NAME:start/end -->`` block gets the write-up
    :param seeds: The ``--seeds`` the report was restricted to (said in the command)
    :param cells: The ``--cells`` the report was restricted to (said in the command)
    :param name: The report's own name, for a second report on some of the cells beside the full one: its
        figure ``NAME.png``, its markdown ``NAME.md`` and its page block (default: the experiment's name, its
        ``report.md``)
    :return: The markdown written
    """
    name = name or experiment.name
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", name):
        raise ValueError(f"a report's name is letters, digits, '-', '_' and '.', got {name!r}")
    grid, summaries = summarize(experiment, root)
    if not summaries:
        raise FileNotFoundError(f"no finished runs of {experiment.name} in {root}; run: dopt experiment run "
                                f"{experiment.name} --out {root}")
    write_training_curves(root, grid, {(s.cell, seed): c for s in summaries for seed, c in zip(s.seeds, s.seed_curves)})
    markdown, png = report_files(root, experiment, name)
    if experiment.goals:  # a goals table: the policy alone per goal (twenty curves would hide each other)
        plot_goals(experiment, summaries, png, root)
    else:
        plot(experiment, grid, summaries, png, root)
    if figure is not None:
        figure.parent.mkdir(parents=True, exist_ok=True)
        figure.write_bytes(png.read_bytes())
    command = _command(experiment, root, figure, section, seeds, cells, name, summaries)
    markdown.write_text(f"# {name}\n\n" + _body(experiment, grid, summaries, png.name, note, command, root) + "\n")
    if section is None:
        return markdown.read_text()
    link = os.path.relpath(figure or png, Path(section).parent)
    body = _body(experiment, grid, summaries, link, note, command, root)
    write_section(section, name, f"{name}: {experiment.goal}", body)
    return body


def _command(experiment: Experiment, root: Path, figure: Optional[Path], section: Optional[Path],
             seeds: Optional[list[int]], cells: Optional[list[str]], name: str, summaries: list) -> str:
    ran = sorted({s for c in summaries for s in c.seeds})
    only = f" --cells {','.join(cells)}" if cells else ""
    report = (f"dopt experiment report {experiment.name} --out {root}"
              + (f" --seeds {','.join(map(str, seeds))}" if seeds else "") + only
              + (f" --name {name}" if name != experiment.name else "")
              + (f" --figure {figure}" if figure else "") + (f" --section {section}" if section else ""))
    # How many runs went at a time is the machine's business (said beside it), not the command's.
    return (f"`dopt experiment run {experiment.name} --seeds {','.join(map(str, ran))}{only} --out {root}` then "
            f"`{report}`")


def _goals(experiment: Experiment, summaries: list, root: Path) -> str:
    """A goals table's own table and how to read it (nothing for a grid on one goal)."""
    if not experiment.goals:
        return ""
    return (f"{goals_markdown(experiment, summaries, root)}\n\nPer goal: the priors the embedding chose for it "
            f"(its own entry excluded); the policy alone over {experiment.final_episodes} episodes each way (SB3's "
            "`evaluate_policy`, env seeds the run never trained on), mean over seeds and each seed in brackets; the step "
            "where the mean training curve first reaches 90%. Figure: greedy as bars, each seed a dot, sampled a black "
            "tick; the dotted line is 0.85. Per cell and goal:\n\n")


def acer_text(summaries: list) -> str:
    """ACER's settings as most cells have them, then each cell's own where it differs (a cell may set its own)."""
    from collections import Counter

    def flow(settings: dict) -> str:
        return yaml.safe_dump(settings, default_flow_style=True, width=200).strip()

    # a setting a cell's record does not name ran at ACER's default
    defaults = acer_signature_defaults()
    named = {k for c in summaries for k in c.records[0]["config"]["acer_kwargs"]}
    per_cell = {c.cell: {**{k: defaults[k] for k in named if k in defaults}, **c.records[0]["config"]["acer_kwargs"]}
                for c in summaries}
    common = {}
    for key in dict.fromkeys(k for a in per_cell.values() for k in a):
        (value, _), = Counter(repr(a.get(key, "<unset>")) for a in per_cell.values()).most_common(1)
        holder = next(a for a in per_cell.values() if repr(a.get(key, "<unset>")) == value)
        if key in holder:
            common[key] = holder[key]
    differs = {cell: {k: v for k, v in a.items() if k not in common or common[k] != v} for cell, a in per_cell.items()}
    # A goals table's cell on every goal (CELL@GOAL) is named once where its settings are the same on each.
    bases: dict[str, list[dict]] = {}
    for cell, d in differs.items():
        bases.setdefault(cell.split("@")[0], []).append(d)
    alike = {base: ds[0] for base, ds in bases.items() if all(d == ds[0] for d in ds)}
    own = [f"{base} {flow(d)}" for base, d in alike.items() if d]
    own += [f"{cell} {flow(d)}" for cell, d in differs.items() if d and cell.split("@")[0] not in alike]
    return flow(common) + (f"; the cells' own: {'; '.join(own)}" if own else "")


def header_list(command: str, grid: str, seeds: str, steps: int, machine: str, note: str, acer: str,
                more: str = "") -> str:
    """A report's header: a short list (what ran, the seeds, the budget, the machine and what ran beside, ACER)."""
    lines = [f"- Commands: {command}", f"- Grid: `{grid}`"]
    lines += [f"- Seeds: {seeds}"] if "; " not in seeds else ["- Seeds:", *(f"  - {s}" for s in seeds.split("; "))]
    lines += [f"- Budget: {steps:,} env steps per run", f"- Machine: {machine}"]
    lines += [f"  - {part.strip()}" for part in note.split("; ") if part.strip()]
    lines.append(f"- ACER: {acer}")
    if more.strip():
        lines.append(f"- {more.strip()}")
    return "\n".join(lines)


def _body(experiment: Experiment, grid, summaries: list, figure_link: str, note: str, command: str,
          root: Path) -> str:
    name = experiment.name
    continued = ""
    if experiment.continues:
        begun = sorted({r.get("from_steps", 0) for c in summaries for r in c.records})
        continued = (f"Each run continues `{experiment.continues}`'s finished run of the same cell and seed (`continues:` "
                     f"in the YAML): its first {', '.join(f'{b:,}' for b in begun)} env steps are that run's, and the "
                     "replay buffer starts empty where it continues; env steps/s is the continuation's. ")
    copied = [f"{c.cell} = `{experiment.cells[c.cell]['same_as']}`" for c in summaries
              if any("copied_from" in r for r in c.records)]
    if copied:
        continued += (f"Runs taken from another experiment (`same_as:` in the YAML; the same configuration and seed, "
                      f"and runs are deterministic): {', '.join(copied)}. ")
    by_seeds: dict[str, list[str]] = {}
    for c in summaries:
        by_seeds.setdefault(", ".join(map(str, sorted(c.seeds))), []).append(c.cell)
    seeds_text = (next(iter(by_seeds)) if len(by_seeds) == 1
                  else "; ".join(f"{seeds} ({', '.join(cells)})" for seeds, cells in by_seeds.items()))
    run_cfg = summaries[0].records[0]["config"]
    alone_every = (f"{run_cfg.get('eval_episodes', 20)} episodes every {run_cfg.get('eval_every', 0) // 1000}k steps"
                   if run_cfg.get("eval_every") else "not evaluated along the way")
    greedy_curve = ("; dotted: the same with greedy actions, SB3's default" if any(len(c.alone_greedy) for c in summaries)
                    else "")
    final_how = (" with SB3's `evaluate_policy` from env seeds the run never trained on, greedy and sampled"
                 if any(c.final_greedy_seeds for c in summaries) else "")
    waits = any(r["config"].get("ready") for c in summaries for r in c.records)
    auc_over = f"the first {experiment.steps // 1000}k env steps, which every run has" if waits else "the run"
    how = "two runs at a time, one torch thread each"
    threads = {r.get("torch_threads") for c in summaries for r in c.records}
    overlapped = [c.cell for c in summaries if c.records[0]["config"].get("overlap")]
    if None not in threads:  # recorded by each run
        how = f"torch threads per run: {', '.join(map(str, sorted(threads)))}"
    elif overlapped:
        how += (f" (the overlapped cells, {', '.join(overlapped)}: one run at a time, two torch threads for the on-policy "
                "update and one in each of its two threads while the replay updates overlap the rollouts)")
    machine = f"{platform.machine()}, {os.cpu_count()} cores, {how}"
    body = (header_list(command, f"sb3_disagree/data/experiments/{name}.yaml", seeds_text, experiment.steps, machine,
                        note, acer_text(summaries), continued) + "\n\n"
            f"![{Path(figure_link).stem}]({figure_link})\n\n{_goals(experiment, summaries, root)}"
            f"{table_markdown(experiment, summaries)}\n\n"
            + ("" if experiment.goals else
               "Solid lines: training success (the last 50 episodes over all envs, priors included where they were "
               "followed), mean over seeds with a 95% t-interval (none with fewer than 3 seeds); dashed: the new policy "
               f"alone (no priors, sampled actions, {alone_every}){greedy_curve}. ") +
            "Table: steps to 50%/90% and success at "
            f"the budgets read from the mean training curve; AUC is the mean of that curve over {auc_over}; the new policy "
            f"alone (final) is evaluated over {experiment.final_episodes} episodes after training{final_how}, per seed "
            "in brackets.\n")
    if not experiment.goals:  # a goals table gives each seed's numbers already
        body += ("\nPer seed, read from each seed's own training curve (the same 50-episode window):\n\n"
                 f"{seeds_markdown(summaries)}\n")
    alone = alone_markdown(summaries)
    if alone is not None:
        body += ("\nThe new policy alone along the way (each run's periodic evaluation, "
                 f"{run_cfg.get('eval_episodes', 20)} episodes each way, mean over the seeds), greedy / sampled:\n\n"
                 f"{alone}\n")
    ratio = ratio_markdown(grid, summaries)
    if ratio is not None:
        body += ("\nSteps to 90% training success with disagreement options over those from scratch, per seed and "
                 f"from the mean curves (a curve that never gets there counts as the run's {experiment.steps:,} "
                 f"steps, which bounds the ratio):\n\n{ratio}\n")
    return body
