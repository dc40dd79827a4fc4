"""The pages a newcomer reads: short, current, and about the package only."""

import re
import subprocess
from pathlib import Path

from typing import Any

import typer
import typer.testing

from sb3_disagree.cli.app import app

REPO = Path(__file__).resolve().parents[1]
# How the package was built is no part of it: no work sessions, no tracker's tickets (the words are split so that
# this file does not name them itself).
PROCESS = re.compile(r"\b(" + "sess" + r"ions? \d+|" + "the is" + r"sue\b|" + "is" + r"sue #?\d+)", re.I)


def _tracked_text() -> list[Path]:
    files = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True, check=True).stdout.split()
    out = []
    for name in files:
        path = REPO / name
        if path.suffix in (".png", ".gif", ".zip", ".glb", ".npz", ".pkl") or not path.is_file():
            continue
        out.append(path)
    return out


def test_no_tracked_file_speaks_of_how_the_project_was_built():
    found = []
    for path in _tracked_text():
        try:
            text = path.read_text()
        except UnicodeDecodeError:
            continue
        found += [f"{path.relative_to(REPO)}:{text.count(chr(10), 0, m.start()) + 1}: {m[0]}" for m in PROCESS.finditer(text)]
    assert not found, "\n".join(found[:40])


def test_the_readme_is_short_and_its_prose_lines_fit():
    lines = (REPO / "README.md").read_text().splitlines()
    assert len(lines) <= 200
    fenced, long = False, []
    for number, line in enumerate(lines, 1):
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced and not line.startswith("|") and len(line) > 120:
            long.append(number)
    assert not long, long


def test_the_results_page_and_the_ledger_are_short():
    for page, most in (("results.md", 300), ("paper.md", 400), ("history.md", 300)):
        assert len((REPO / "docs" / page).read_text().splitlines()) <= most, page
    for report in (REPO / "benchmarks" / "results" / "experiments").glob("*/*.md"):  # a header is a list of lines
        assert max(map(len, report.read_text().splitlines())) <= 2000, report


def test_every_help_text_shows_whole():
    """Rich reads "[...]" in a help text as markup and drops it: no help text holds one."""
    swallowed = []

    def walk(command: Any, path: str) -> None:
        for name, sub in getattr(command, "commands", {}).items():
            walk(sub, f"{path} {name}")
        swallowed.extend(f"{path} {p.name}" for p in command.params if "[" in (getattr(p, "help", None) or ""))

    walk(typer.main.get_command(app), "dopt")
    assert not swallowed, swallowed
    result = typer.testing.CliRunner().invoke(app, ["eval", "--help"], terminal_width=100)
    assert "(default: both, side by side;" in " ".join(result.output.replace("│", " ").split())


def test_dopt_trains_help_is_in_panels_and_each_option_fits_two_lines():
    """At 100 columns, every option of dopt train says what it does in at most two lines, in panels by purpose with
    the run's essentials first."""
    result = typer.testing.CliRunner().invoke(app, ["train", "--help"], terminal_width=100, env={"COLUMNS": "100"})
    panels = [line.strip("╭─ ").split(" ─")[0] for line in result.output.splitlines() if line.startswith("╭─")]
    assert panels[:2] in (["Run", "Method"], ["Options", "Run"]) and {"Memory", "Finish", "ACER"} <= set(panels)
    rows, option = {}, None
    for line in result.output.splitlines():
        body = line.strip("│ ").rstrip()
        if line.startswith("│") and body.startswith("--"):
            option = body.split()[0]
            rows[option] = 1
        elif line.startswith("│") and option is not None and body:
            rows[option] += 1
        elif not line.startswith("│"):
            option = None
    assert len(rows) >= 35 and max(rows.values()) <= 2, {k: v for k, v in rows.items() if v > 2}
