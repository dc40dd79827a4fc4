"""
Bad input and hostile files against the command line, as one table run in-process: each case ends with exit code 2,
one line on stderr and no traceback, runs no code a file carries, and leaves the target folder's neighbours as they
were. Property-based cases cover the experiment YAML and the goal and ``--priors`` words.
"""

import base64
import json
import os
import pickle
import shutil
import zipfile
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from sb3_disagree.cli.app import app

STATE = "sb3_disagree/ApartmentState-v0"
runner = CliRunner()


class Payload:
    """What a tampered file carries: unpickled, it creates the file ``marker`` (harmless, and seen)."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def tampered_model(clean: Path, out: Path, marker: Path, field: str = "extra_state") -> Path:
    """A copy of a model file whose pickled ``field`` runs the payload when SB3 unpickles it."""
    with zipfile.ZipFile(clean) as z:
        members = {name: z.read(name) for name in z.namelist()}
    data = json.loads(members["data"])
    data[field] = {":type:": "<class 'function'>",
                   ":serialized:": base64.b64encode(pickle.dumps(Payload(marker))).decode()}
    members["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(out, "w") as z:
        for name, content in members.items():
            z.writestr(name, content)
    return out


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """A finished tiny run and an interrupted one (with a replay buffer in its checkpoint), made once."""
    root = tmp_path_factory.mktemp("made")
    base = ["train", "--env", STATE, "--mode", "scratch", "--n-envs", "2", "--card-episodes", "0"]
    assert runner.invoke(app, [*base, "--goal", "bathtub", "--steps", "200", "--out", str(root / "runs")]).exit_code == 0
    finished = root / "runs" / "sb3_disagree__ApartmentState-v0" / "bathtub" / "scratch-0"
    from stable_baselines3.common.callbacks import BaseCallback

    from sb3_disagree.run import RunConfig, train

    class Interrupt(BaseCallback):  # Ctrl-C at 300 steps: a checkpoint with the replay buffer
        def _on_step(self):
            if self.num_timesteps >= 300:
                raise KeyboardInterrupt
            return True

    run_dir, _, done = train(RunConfig(goal="bed", env_id=STATE, mode="scratch", n_envs=2, steps=600,
                                       checkpoint_every=0), root / "runs", callbacks=[Interrupt()])
    assert not done
    return {"finished": finished, "interrupted": run_dir}


def _case_dir(tmp_path: Path, made: dict) -> dict:
    """The case's own copies of the made runs, and the marker a payload would create."""
    for name, folder in made.items():
        shutil.copytree(folder, tmp_path / name)
    return {"run": tmp_path / "finished", "stopped": tmp_path / "interrupted", "marker": tmp_path / "RAN",
            "tmp": tmp_path}


def _grid(tmp: Path, text: str) -> str:
    (tmp / "grid.yaml").write_text(text)
    return str(tmp / "grid.yaml")


def _evil_model(c: dict) -> str:
    return str(tampered_model(c["run"] / "model.zip", c["tmp"] / "evil.zip", c["marker"]))


def _evil_run(c: dict) -> str:
    tampered_model(c["run"] / "model.zip", c["run"] / "model.zip", c["marker"])
    return str(c["run"])


def _evil_resume(c: dict) -> str:
    for model in c["stopped"].glob("checkpoints/*/model.zip"):
        tampered_model(model, model, c["marker"])
        state = json.loads((model.parent / "state.json").read_text())
        from sb3_disagree.loading import sha256_of

        state["files"]["model.zip"] = sha256_of(model)  # the tamperer rewrites the hashes too
        (model.parent / "state.json").write_text(json.dumps(state))
    return str(c["stopped"])


def _evil_embedding(c: dict) -> str:
    path = c["tmp"] / "evil.kv"
    path.write_bytes(pickle.dumps(Payload(c["marker"])))
    return str(path)


def _damaged_buffer(c: dict) -> str:
    (buffer,) = c["stopped"].glob("checkpoints/*/replay_buffer.npz")
    with open(buffer, "r+b") as f:
        f.truncate(1000)
    return str(c["stopped"])


def _config(c: dict, text: str) -> str:
    (c["run"] / "config.yaml").write_text(text)
    return str(c["run"])


def _zoo_with_bathtub(c: dict) -> str:
    from sb3_disagree.priors.zoo import DEFAULT_ZOO

    zoo = c["tmp"] / "zoo"
    shutil.copytree(DEFAULT_ZOO / "sb3_disagree__ApartmentState-v0" / "bathtub",
                    zoo / "sb3_disagree__ApartmentState-v0" / "bathtub")
    return str(zoo)


def _trust_folder(c: dict) -> str:
    os.environ["SB3_DISAGREE_TRUSTED"] = str(c["tmp"])
    return str(c["run"])


# (case, command as a function of the case's folders, words the one line says)
CASES = [
    ("tampered model, dopt eval", lambda c: ["eval", _evil_run(c), "--episodes", "2"], "--trust"),
    ("tampered model, resume", lambda c: ["train", "--resume", _evil_resume(c)], "--trust"),
    ("tampered model, dopt consistency", lambda c: ["consistency", _evil_run(c), "--rounds", "1", "--steps", "8"],
     "--trust"),
    ("tampered model, priors add", lambda c: ["priors", "add", _evil_model(c), "--goal", "bed", "--env", STATE,
                                              "--zoo", str(c["tmp"] / "z"), "--episodes", "0"], "--trust"),
    ("priors add to a goal the zoo has", lambda c: ["priors", "add", _evil_model(c), "--goal", "bathtub", "--env",
                                                    STATE, "--zoo", _zoo_with_bathtub(c)], "already has"),
    ("pickled embedding, priors list", lambda c: ["priors", "list", "--goal", "bathtub", "--embedding",
                                                  _evil_embedding(c)], "--trust"),
    ("pickled embedding, similarity", lambda c: ["similarity", "bed", "bathtub", "--embedding", _evil_embedding(c)],
     "--trust"),
    ("pickled embedding, train", lambda c: ["train", "--goal", "bathtub", "--env", STATE, "--embedding",
                                            _evil_embedding(c), "--out", str(c["tmp"] / "out")], "--trust"),
    ("write into the shipped zoo, priors train", lambda c: ["priors", "train", "--goal", "bed", "--zoo",
                                                            _shipped(), "--replace"], "read-only"),
    ("write into the shipped zoo, priors eval --record", lambda c: ["priors", "eval", "microwave", "--episodes", "3",
                                                                    "--record"], "read-only"),
    ("write into the shipped zoo, priors remove", lambda c: ["priors", "remove", "bed", "--zoo", "greedy"],
     "read-only"),
    ("resume whose only checkpoint is damaged", lambda c: ["train", "--resume", _damaged_buffer(c)], "--force"),
    ("--steps 0", lambda c: ["train", "--goal", "bathtub", "--env", STATE, "--steps", "0", "--out",
                             str(c["tmp"] / "out")], "--steps"),
    ("absurd --steps", lambda c: ["train", "--goal", "bathtub", "--env", STATE, "--steps", "100000000000000000000",
                                  "--out", str(c["tmp"] / "out")], "--steps"),
    ("eval --episodes 0", lambda c: ["eval", str(c["run"]), "--episodes", "0"], "--episodes"),
    ("eval --episodes -3", lambda c: ["eval", str(c["run"]), "--episodes", "-3"], "--episodes"),
    ("experiment run --jobs -1", lambda c: ["experiment", "run", "fig3-bathtub", "--jobs", "-1", "--out",
                                            str(c["tmp"] / "out")], "--jobs"),
    ("--seed -1", lambda c: ["train", "--goal", "bathtub", "--env", STATE, "--seed", "-1", "--out",
                             str(c["tmp"] / "out")], "--seed"),
    ("--out on a read-only place", lambda c: ["train", "--goal", "bathtub", "--env", STATE, "--steps", "100",
                                              "--out", "/proc/dopt-out"], "/proc/dopt-out"),
    ("--out naming a file", lambda c: ["train", "--goal", "bathtub", "--env", STATE, "--steps", "100", "--out",
                                       str(c["run"] / "config.yaml")], "config.yaml"),
    ("a 300-character goal", lambda c: ["train", "--goal", "g" * 300, "--env", STATE, "--out",
                                        str(c["tmp"] / "out")], "at most"),
    ("a YAML syntax error", lambda c: ["experiment", "run", _grid(c["tmp"], "goal: [bathtub\n"), "--out",
                                       str(c["tmp"] / "out")], "YAML"),
    ("a YAML list", lambda c: ["experiment", "run", _grid(c["tmp"], "- goal: bathtub\n"), "--out",
                               str(c["tmp"] / "out")], "mapping"),
    ("an unknown key under acer", lambda c: ["experiment", "run", _grid(c["tmp"], (
        "goal: bathtub\nenv_id: sb3_disagree/ApartmentState-v0\nsteps: 100\nacer: {nonsense: 1}\n"
        "cells: {a: {mode: scratch}}\n")), "--out", str(c["tmp"] / "out")], "nonsense"),
    ("name: 5", lambda c: ["experiment", "run", _grid(c["tmp"], (
        "name: 5\ngoal: bathtub\nenv_id: sb3_disagree/ApartmentState-v0\nsteps: 100\ncells: {a: {mode: scratch}}\n"
    ))], "name"),
    ("an experiment named ../../x", lambda c: ["experiment", "run", _grid(c["tmp"], (
        "name: ../../escaped\ngoal: bathtub\nenv_id: sb3_disagree/ApartmentState-v0\nsteps: 100\n"
        "cells: {a: {mode: scratch}}\n"))], "name"),
    ("an experiment named by an absolute path", lambda c: ["experiment", "run", _grid(c["tmp"], (
        f"name: {c['tmp'] / 'escaped'}\ngoal: bathtub\nenv_id: sb3_disagree/ApartmentState-v0\nsteps: 100\n"
        "cells: {a: {mode: scratch}}\n"))], "name"),
    ("a run whose config.yaml is a list, resume", lambda c: ["train", "--resume", _config(c, "- 1\n")], "mapping"),
    ("a run whose env_id is a list, eval", lambda c: ["eval", _config(c, "env_id: [1]\ngoal: bathtub\n")], "env_id"),
    ("a run without env_id, eval", lambda c: ["eval", _config(c, "goal: bathtub\n")], "env_id"),
    ("SB3_DISAGREE_TRUSTED naming a folder", lambda c: ["eval", _trust_folder(c), "--episodes", "2"],
     "SB3_DISAGREE_TRUSTED"),
    # Held by the crash-safety tests too, here in the same table.
    ("a non-navigation env", lambda c: ["train", "--goal", "bathtub", "--env", "CartPole-v1", "--out",
                                        str(c["tmp"] / "out")], "not a goal-navigation environment"),
    ("--priors naming a goal twice", lambda c: ["train", "--goal", "bathtub", "--env", STATE, "--priors",
                                                "shower,shower", "--out", str(c["tmp"] / "out")], "twice"),
    ("--priors naming the goal itself", lambda c: ["train", "--goal", "bathtub", "--env", STATE, "--priors",
                                                   "bathtub,shower", "--out", str(c["tmp"] / "out")], "itself"),
    ("--embedding a folder", lambda c: ["train", "--goal", "bathtub", "--env", STATE, "--embedding", ".", "--out",
                                        str(c["tmp"] / "out")], "not a file"),
    ("--goal ..", lambda c: ["train", "--goal", "..", "--env", STATE, "--out", str(c["tmp"] / "out")],
     "cannot name a folder"),
    ("--resume with --force", lambda c: ["train", "--resume", str(c["run"]), "--force"], "choose one"),
    ("--resume below the steps trained", lambda c: ["train", "--resume", str(c["stopped"]), "--steps", "100"],
     "below"),
    ("--resume changing a saved setting", lambda c: ["train", "--resume", str(c["stopped"]), "--beta", "0.5"],
     "--beta"),
    ("a run folder taken", lambda c: ["train", "--goal", "bathtub", "--env", STATE, "--mode", "scratch", "--n-envs",
                                      "2", "--out", str(c["tmp"] / "runs-taken"), "--steps", "100"], "--resume"),
]


def _shipped() -> str:
    from sb3_disagree.priors.zoo import DEFAULT_ZOO

    return str(DEFAULT_ZOO)


def _snapshot(root: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in sorted(root.rglob("*"))
            if p.is_file()}


@pytest.mark.parametrize("case, command, words", CASES, ids=[c[0] for c in CASES])
def test_red_team(case, command, words, made, tmp_path, monkeypatch):
    from sb3_disagree.priors.zoo import DEFAULT_ZOO, SHIPPED

    monkeypatch.delenv("SB3_DISAGREE_TRUSTED", raising=False)
    monkeypatch.setenv("SB3_DISAGREE_ZOO", str(tmp_path / "user-zoo"))
    monkeypatch.chdir(tmp_path)
    c = _case_dir(tmp_path, made)
    if case == "a run folder taken":
        (tmp_path / "runs-taken" / "sb3_disagree__ApartmentState-v0" / "bathtub").mkdir(parents=True)
        shutil.copytree(c["run"], tmp_path / "runs-taken" / "sb3_disagree__ApartmentState-v0" / "bathtub" / "scratch-0")
    args = command(c)
    before, shipped = _snapshot(tmp_path), _snapshot(SHIPPED)
    try:
        result = runner.invoke(app, args)
    finally:
        os.environ.pop("SB3_DISAGREE_TRUSTED", None)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == 2, (args, result.stdout[-2000:], result.stderr[-2000:])
    assert len(lines) == 1 and lines[0].startswith("error:") and "Traceback" not in result.output, result.stderr
    assert words in lines[0], lines[0]
    assert not c["marker"].exists(), "the file's payload ran"
    assert _snapshot(SHIPPED) == shipped and not (tmp_path.parent / "escaped").exists()
    after = _snapshot(tmp_path)
    aside = {k.rsplit("/", 1)[-1]: v for k, v in after.items() if "/.damaged-" in k}  # a damaged checkpoint moves
    gone = {k for k in before.keys() - after.keys() if aside.get(k.rsplit("/", 1)[-1]) != before[k]}
    new = {k for k in after.keys() - before.keys() if "/.damaged-" not in k}
    assert not gone and not new and all(after[k] == before[k] for k in after.keys() & before.keys()), (gone, new)
    assert DEFAULT_ZOO.is_dir()


def test_a_damaged_checkpoint_is_moved_aside_and_the_logs_kept(made, tmp_path):
    c = _case_dir(tmp_path, made)
    _damaged_buffer(c)
    logs = (c["stopped"] / "progress.csv").read_bytes()
    result = runner.invoke(app, ["train", "--resume", str(c["stopped"])])
    assert result.exit_code == 2
    (aside,) = (c["stopped"] / "checkpoints").glob(".damaged-*")
    assert (aside / "replay_buffer.npz").exists() and (c["stopped"] / "progress.csv").read_bytes() == logs


def test_a_payload_in_a_field_the_package_rebuilds_never_runs(made, tmp_path):
    c = _case_dir(tmp_path, made)
    tampered_model(c["run"] / "model.zip", c["run"] / "model.zip", c["marker"], field="lr_schedule")
    result = runner.invoke(app, ["eval", str(c["run"]), "--episodes", "1"])
    assert result.exit_code == 0 and "success" in result.stdout and not c["marker"].exists()


def test_trust_opens_what_the_package_cannot_rebuild(made, tmp_path):
    c = _case_dir(tmp_path, made)
    run = _evil_run(c)
    result = runner.invoke(app, ["eval", run, "--episodes", "1", "--trust"])
    assert c["marker"].exists()  # trusted: SB3 unpickled it, as asked
    assert result.exit_code != 0 or "success" in result.stdout


def test_resume_without_goal_reads_the_runs_own(made, tmp_path):
    c = _case_dir(tmp_path, made)
    result = runner.invoke(app, ["train", "--resume", str(c["stopped"]), "--card-episodes", "0"])
    assert result.exit_code == 0, result.output
    assert yaml.safe_load((c["stopped"] / "config.yaml").read_text())["finished"]


def test_the_shipped_zoo_stays_as_shipped_when_a_prior_is_written_by_default(tmp_path, monkeypatch):
    from sb3_disagree.priors.zoo import SHIPPED

    monkeypatch.setenv("SB3_DISAGREE_ZOO", str(tmp_path / "mine"))
    shipped = _snapshot(SHIPPED)
    result = runner.invoke(app, ["priors", "train", "--goal", "bed", "--env", STATE, "--rounds", "1",
                                 "--steps-per-round", "200", "--epochs", "1", "--episodes", "2"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "mine" / "sb3_disagree__ApartmentState-v0" / "bed" / "model.zip").exists()
    assert _snapshot(SHIPPED) == shipped


WORDS = st.text(alphabet=st.characters(blacklist_categories=("Cs",)), min_size=0, max_size=40)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(goal=WORDS, priors=WORDS)
def test_any_goal_and_priors_words_end_cleanly(goal, priors, tmp_path):
    """Whatever the words, dopt train either refuses them in one line with exit code 2 or would train: nothing is
    written outside the output folder (checked with --steps 0, which is refused after the words are)."""
    out = tmp_path / "out"
    result = runner.invoke(app, ["train", "--goal", goal, "--priors", priors or "auto", "--env", STATE, "--steps", "0",
                                 "--out", str(out)])
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == 2 and len(lines) == 1 and "Traceback" not in result.output, (goal, priors, result.stderr)
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) in ([], ["out"])


YAML_VALUES = st.recursive(st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | WORDS,
                           lambda inner: st.lists(inner, max_size=3) | st.dictionaries(WORDS, inner, max_size=3),
                           max_leaves=8)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(grid=st.dictionaries(st.sampled_from(["name", "goal", "env_id", "steps", "seeds", "cells", "acer", "run",
                                             "budgets", "final_episodes", "priors", "continues"]), YAML_VALUES,
                            max_size=6))
def test_any_experiment_yaml_is_listed_refused_or_run_in_one_line(grid, tmp_path):
    """A grid of any shape is read or refused in one line with exit code 2, and nothing is written (reporting on a
    results folder without runs: a valid grid is read, then refused for want of runs)."""
    path = tmp_path / "grid.yaml"
    path.write_text(yaml.safe_dump(grid))
    result = runner.invoke(app, ["experiment", "report", str(path), "--out", str(tmp_path / "res")])
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == 2 and len(lines) == 1 and lines[0].startswith("error:"), (grid, result.output)
    assert "Traceback" not in result.output and sorted(p.name for p in tmp_path.iterdir()) == ["grid.yaml"]


def test_ctrl_c_while_the_command_starts_is_one_line():
    """SIGINT half a second into ``dopt priors list`` (its imports take about two): one line, exit code 130."""
    import signal
    import subprocess
    import sys
    import time

    # A shell's background job inherits SIGINT ignored; the child gets the default back, as a terminal's command has.
    process = subprocess.Popen([sys.executable, "-c", "from sb3_disagree.cli import main; main()", "priors", "list"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    time.sleep(0.5)
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=120)
    lines = [line for line in err.splitlines() if line.strip()]
    assert process.returncode == 130 and lines == ["error: interrupted"], (process.returncode, err[-2000:])


def test_a_budget_cut_on_resume_keeps_the_greedy_phase_inside_it(tmp_path):
    """A run whose greedy phase covered its whole budget, resumed to a smaller one, is greedy throughout it."""
    from stable_baselines3.common.callbacks import BaseCallback

    from sb3_disagree.run import RunConfig, train

    class Interrupt(BaseCallback):
        def _on_step(self):
            if self.num_timesteps >= 200:
                raise KeyboardInterrupt
            return True

    config = RunConfig(goal="bed", env_id=STATE, mode="scratch", n_envs=2, steps=600, greedy_phase=600,
                       checkpoint_every=0)
    run_dir, _, done = train(config, tmp_path, callbacks=[Interrupt()])
    assert not done
    result = runner.invoke(app, ["train", "--resume", str(run_dir), "--steps", "400", "--card-episodes", "0"])
    assert result.exit_code == 0, result.output
    saved = yaml.safe_load((run_dir / "config.yaml").read_text())
    assert saved["finished"] and saved["steps"] == 400 and saved["greedy_phase"] == 400
