"""The README cannot drift: every block in it runs, on the state apartment with small budgets substituted."""

import re
import shlex
import subprocess
import warnings
from pathlib import Path

import pytest
from typer.testing import CliRunner

from readme import README, blocks, commands
from sb3_disagree.cli.app import app

REPO = README.parent
STATE = "sb3_disagree/ApartmentState-v0"
# What each block would run for minutes, made small: the state apartment, a few hundred env steps, a few episodes.
SUBSTITUTIONS = [
    (r"(dopt train --goal \w+)", rf"\1 --env {STATE} --steps 400 --n-envs 2 --card-episodes 1"),
    (r"sb3_disagree__Apartment-v0", "sb3_disagree__ApartmentState-v0"),
    (r"--episodes \d+", "--episodes 2"),
    (r"(--video \S+)", r"\1 --video-episodes 1"),
    (r'"sb3_disagree/Apartment-v0"', f'"{STATE}"'),
    (r'RunConfig\(goal="bathtub"\)', f'RunConfig(goal="bathtub", env_id="{STATE}", steps=400, n_envs=2)'),
    (r"n_eval_episodes=100", "n_eval_episodes=2"),
    (r"episodes=20\)", "episodes=1)"),
    (r"learn\(100_000\)", "learn(1_000)"),
]
# Blocks other tests run as the README writes them: the wheel's (tests/test_package.py builds and installs it) and
# rl-zoo3's (tests/test_package.py trains and tunes through it).
ELSEWHERE = ("pip wheel", "python -m sb3_disagree.rl_zoo")
runner = CliRunner()


def small(text: str, used: set) -> str:
    for i, (pattern, replacement) in enumerate(SUBSTITUTIONS):
        text, n = re.subn(pattern, replacement, text)
        if n:
            used.add(i)
    return text


def test_every_block_of_the_readme_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    used: set = set()
    ran = 0
    for language, text in blocks():
        text = small(text, used)
        if language == "python":  # in this process (the imports are paid once), warnings as errors
            with warnings.catch_warnings():
                warnings.simplefilter("error", UserWarning)
                exec(compile(text, str(README), "exec"), {"__name__": "readme"})
        elif language == "bash" and commands(text)[0].startswith(ELSEWHERE):
            continue
        elif language == "bash":
            for command in commands(text):
                args = shlex.split(command)
                if args[0] == "make":  # the set-up: the targets exist and say what they would do
                    done = subprocess.run(["make", "-n", *args[1:]], cwd=REPO, capture_output=True, text=True)
                    assert done.returncode == 0, done.stderr
                    assert args[1:] != ["run"] or "dopt train --goal bathtub" in done.stdout, done.stdout
                    continue
                assert args[0] == "dopt", command
                result = runner.invoke(app, args[1:])
                assert result.exit_code == 0, (command, result.output[-3000:])
        else:
            pytest.fail(f"a {language} block in the README that no test runs")
        ran += 1
    assert ran >= 5
    unused = [SUBSTITUTIONS[i][0] for i in range(len(SUBSTITUTIONS)) if i not in used]
    assert not unused, f"substitutions that no block needs any more: {unused}"
    assert (tmp_path / "agent.gif").stat().st_size > 10_000


def test_every_block_run_elsewhere_is_run_there():
    """The blocks this file leaves to tests/test_package.py are read there from the README."""
    source = (Path(__file__).parent / "test_package.py").read_text()
    assert source.count("block_with(") >= len(ELSEWHERE)
    assert sum(commands(t)[0].startswith(ELSEWHERE) for lang, t in blocks() if lang == "bash") == len(ELSEWHERE)
