"""What a run survives and what the command line refuses: overwrites, signals, kills, damaged checkpoints,
paths that leave their folder, zoo writes that would leave a half-made entry."""

import hashlib
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch as th
import yaml
from envs import ChainEnv
from stable_baselines3.common.env_util import make_vec_env
from typer.testing import CliRunner

from sb3_disagree import ACER
from sb3_disagree.checkpoints import latest_checkpoint, save_checkpoint
from sb3_disagree.cli.app import app

STATE_ID = "sb3_disagree/ApartmentState-v0"  # the shipped zoo has its priors
runner = CliRunner()


def _args(out, *extra, goal="bathtub"):
    return ["train", "--goal", goal, "--env", STATE_ID, "--mode", "disagreement", "--out", str(out), "--n-envs", "2",
            "--card-episodes", "0", "--bare", *extra]


def _tree(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()} if root.exists() else {}


def test_an_existing_run_is_never_overwritten_without_force(tmp_path):
    assert runner.invoke(app, _args(tmp_path, "--steps", "1000", "--record-trajectories")).exit_code == 0
    run = tmp_path / "sb3_disagree__ApartmentState-v0" / "bathtub" / "disagreement-0"
    before = _tree(run)
    episodes = (run / "trajectories.jsonl").read_text()
    result = runner.invoke(app, _args(tmp_path, "--steps", "1000"))
    assert result.exit_code == 2 and "--resume" in result.output and "--force" in result.output
    assert _tree(run) == before
    result = runner.invoke(app, _args(tmp_path, "--steps", "1000", "--force", "--record-trajectories"))
    assert result.exit_code == 0, result.output
    # A fresh run of the same seed: the same episodes, not two runs' mixed.
    assert (run / "trajectories.jsonl").read_text() == episodes
    assert pd.read_csv(run / "progress.csv")["time/total_timesteps"].is_monotonic_increasing


def test_resume_refuses_flags_it_would_ignore_and_a_budget_below_its_count(tmp_path):
    assert runner.invoke(app, _args(tmp_path, "--steps", "400")).exit_code == 0
    run = tmp_path / "sb3_disagree__ApartmentState-v0" / "bathtub" / "disagreement-0"
    for extra, words in ((["--beta", "0.5"], "drop --beta"), (["--steps", "200"], "below"),
                         (["--force"], "choose one")):
        result = runner.invoke(app, ["train", "--goal", "bathtub", "--resume", str(run), *extra])
        assert result.exit_code == 2 and words in " ".join(result.output.split()), (extra, result.output)


def _start(tmp_path, *extra):
    """`dopt train` in its own process, printing a progress line every 0.2 s."""
    cmd = [sys.executable, "-m", "sb3_disagree.cli.app", *_args(tmp_path, "--progress-every", "0.2", *extra)]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=tmp_path)


def _wait_for_steps(proc, steps: int) -> None:
    for line in proc.stdout:
        if line.startswith("steps ") and int(line.split()[1].split("/")[0].replace(",", "")) >= steps:
            return
    raise AssertionError("the run ended before it got there")


def test_sigterm_saves_like_ctrl_c_and_the_run_resumes(tmp_path):
    proc = _start(tmp_path, "--steps", "100000", "--checkpoint-every", "0")
    _wait_for_steps(proc, 600)
    proc.send_signal(signal.SIGTERM)
    proc.communicate(timeout=120)
    assert proc.returncode == 130
    run = tmp_path / "sb3_disagree__ApartmentState-v0" / "bathtub" / "disagreement-0"
    saved = yaml.safe_load((run / "config.yaml").read_text())
    folder, state = latest_checkpoint(run)
    assert not saved["finished"] and state["num_timesteps"] == saved["num_timesteps"] >= 600
    assert (folder / "replay_buffer.npz").exists()
    target = saved["num_timesteps"] + 200
    result = runner.invoke(app, ["train", "--goal", "bathtub", "--resume", str(run), "--steps", str(target),
                                 "--card-episodes", "0"])
    assert result.exit_code == 0, result.output
    assert target <= yaml.safe_load((run / "config.yaml").read_text())["num_timesteps"] < target + 40


def test_kill_9_loses_at_most_the_steps_since_the_last_checkpoint_and_the_history_stays_one_run(tmp_path):
    proc = _start(tmp_path, "--steps", "100000", "--checkpoint-every", "400")
    _wait_for_steps(proc, 1300)
    proc.kill()
    proc.communicate(timeout=60)
    run = tmp_path / "sb3_disagree__ApartmentState-v0" / "bathtub" / "disagreement-0"
    folder, state = latest_checkpoint(run)
    assert 800 <= state["num_timesteps"] < 1300 + 400
    result = runner.invoke(app, ["train", "--goal", "bathtub", "--resume", str(run), "--steps", "2400",
                                 "--card-episodes", "0"])
    assert result.exit_code == 0, result.output
    final = yaml.safe_load((run / "config.yaml").read_text())["num_timesteps"]
    assert 2400 <= final < 2440 and ACER.load(run / "model.zip").num_timesteps == final
    steps = pd.read_csv(run / "progress.csv")["time/total_timesteps"].dropna()
    assert steps.is_monotonic_increasing and steps.iloc[-1] <= final  # nothing from after the checkpoint is left
    episodes = sum(len(pd.read_csv(f, skiprows=1)["l"]) and pd.read_csv(f, skiprows=1)["l"].sum()
                   for f in (run / "monitor").glob("*.monitor.csv"))
    assert episodes <= final  # the monitors' episodes fit in the steps of one run


def test_a_damaged_checkpoint_is_skipped_for_the_one_before(tmp_path):
    model = ACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=2), n_steps=5, seed=0)
    model.learn(100)
    first = save_checkpoint(model, tmp_path)
    model.learn(100, reset_num_timesteps=False)
    second = save_checkpoint(model, tmp_path)
    assert latest_checkpoint(tmp_path)[0] == second
    with open(second / "model.zip", "r+b") as f:
        f.truncate(100)
    assert latest_checkpoint(tmp_path)[0] == first
    (first / "state.json").unlink()  # an interrupted write: no state, not complete
    assert latest_checkpoint(tmp_path) is None


def test_paths_built_from_a_users_words_stay_in_their_folder(tmp_path):
    out = tmp_path / "a" / "b"
    out.mkdir(parents=True)
    result = runner.invoke(app, _args(out, "--steps", "100", goal="../../x"))
    assert result.exit_code == 2 and "cannot name a folder" in result.output
    assert _tree(tmp_path) == {}
    zoo = tmp_path / "zoo"
    model = ACER("MlpPolicy", make_vec_env(STATE_ID, n_envs=1, env_kwargs=dict(goal="bed")))
    model.save(tmp_path / "m.zip")
    result = runner.invoke(app, ["priors", "add", str(tmp_path / "m.zip"), "--goal", "./../../evil", "--env", STATE_ID,
                                 "--zoo", str(zoo), "--episodes", "0"])
    assert result.exit_code == 2 and not zoo.exists() and not (tmp_path.parent / "evil").exists()
    grid = tmp_path / "g.yaml"
    grid.write_text(yaml.safe_dump({"goal": "bathtub", "env_id": STATE_ID, "steps": 100,
                                    "cells": {"../../escape": {"mode": "scratch"}}}))
    result = runner.invoke(app, ["experiment", "run", str(grid), "--out", str(tmp_path / "res")])
    assert result.exit_code == 2 and "cannot name a folder" in result.output and not (tmp_path / "res").exists()


def test_adding_a_prior_that_does_not_fit_leaves_the_zoo_byte_identical(tmp_path):
    zoo = tmp_path / "zoo"
    good = ACER("MlpPolicy", make_vec_env(STATE_ID, n_envs=1, env_kwargs=dict(goal="bed")))
    good.save(tmp_path / "good.zip")
    assert runner.invoke(app, ["priors", "add", str(tmp_path / "good.zip"), "--goal", "bed", "--env", STATE_ID,
                               "--zoo", str(zoo), "--episodes", "0"]).exit_code == 0
    before = _tree(zoo)
    ACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=1)).save(tmp_path / "chain.zip")
    for args in (["--goal", "toilet", "--env", STATE_ID], ["--goal", "toilet", "--env", "sb3_disagree/Nowhere-v0"],
                 ["--goal", "nothing-here", "--env", STATE_ID]):
        result = runner.invoke(app, ["priors", "add", str(tmp_path / "chain.zip"), *args, "--zoo", str(zoo),
                                     "--episodes", "0"])
        assert result.exit_code == 2, (args, result.output)
        assert _tree(zoo) == before


def test_the_overlapped_trainers_optimizer_state_is_copied_not_shared():
    model = ACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=2), n_steps=5, replay_start=10, overlap=True, seed=0)
    model.learn(200)
    import copy

    from sb3_disagree.acer.overlap import copy_learner

    learner = copy.deepcopy(model.policy)
    learner.optimizer.load_state_dict(model.policy.optimizer.state_dict())
    copy_learner(learner, model.policy)
    acting = [s for s in model.policy.optimizer.state.values()]
    theirs = [s for s in learner.optimizer.state.values()]
    assert acting and all(a[k] is not b[k] for a, b in zip(acting, theirs) for k in a if isinstance(a[k], th.Tensor))
    before = [{k: v.clone() for k, v in s.items() if isinstance(v, th.Tensor)} for s in acting]
    for s in theirs:  # the learner goes on updating in place
        for v in s.values():
            if isinstance(v, th.Tensor) and v.is_floating_point():
                v.add_(1.0)
    assert all(th.equal(a[k], b[k]) for a, b in zip(acting, before) for k in b)


def test_a_trust_list_outside_the_zoo_refuses_what_is_not_on_it(tmp_path, monkeypatch):
    from sb3_disagree.priors.zoo import Zoo, ZooError

    zoo = tmp_path / "zoo"
    ACER("MlpPolicy", make_vec_env(STATE_ID, n_envs=1, env_kwargs=dict(goal="bed"))).save(tmp_path / "m.zip")
    entry = Zoo(zoo).add(tmp_path / "m.zip", "bed", STATE_ID)
    trust = tmp_path / "trusted.txt"
    trust.write_text("# hashes of priors I made\n" + "0" * 64 + "\n")
    monkeypatch.setenv("SB3_DISAGREE_TRUSTED", str(trust))
    untrusted = Zoo(zoo).get("bed", STATE_ID)
    assert untrusted.problem == "model.zip is not on the trust list"
    with pytest.raises(ZooError, match="trust list"):
        Zoo(zoo).load(untrusted)
    trust.write_text(entry.card.sha256 + "\n")
    assert Zoo(zoo).get("bed", STATE_ID).problem is None


@pytest.mark.parametrize("args, words", [
    (["--env", "CartPole-v1"], "not a goal-navigation environment"),
    (["--priors", "shower,shower"], "names a goal twice"),
    (["--priors", "bathtub,shower"], "the new goal 'bathtub' itself"),
    (["--embedding", "."], "is not a file"),
    (["--goal", "..", "--steps", "100"], "cannot name a folder"),
])
def test_bad_input_is_one_line_and_exit_2_with_nothing_written(tmp_path, args, words):
    base = ["train", "--goal", "bathtub", "--env", STATE_ID, "--out", str(tmp_path / "out"), "--steps", "100"]
    for flag in args[::2]:  # the case's own value replaces the default one
        if flag in base:
            i = base.index(flag)
            del base[i:i + 2]
    result = runner.invoke(app, [*base, *args])
    assert result.exit_code == 2 and words in " ".join(result.output.split()), result.output
    assert "Traceback" not in result.output and not (tmp_path / "out").exists()


def test_a_grid_with_wrongly_typed_or_negative_values_is_refused(tmp_path):
    for bad, words in (({"steps": "lots"}, "steps must be a positive integer"),
                       ({"final_episodes": -5}, "final_episodes must be a positive integer"),
                       ({"budgets": [-5]}, "budgets must be a list of positive"),
                       ({"cells": {"a": {"mode": "scratch", "alpha": "x"}}}, "alpha must be an integer")):
        grid = tmp_path / "g.yaml"
        grid.write_text(yaml.safe_dump({"goal": "bathtub", "env_id": STATE_ID, "steps": 100,
                                        "cells": {"a": {"mode": "scratch"}}, **bad}))
        result = runner.invoke(app, ["experiment", "run", str(grid), "--out", str(tmp_path / "res")])
        assert result.exit_code == 2 and words in " ".join(result.output.split()), result.output
        assert not (tmp_path / "res").exists()


def test_dopt_eval_refuses_a_model_from_another_env_or_algorithm(tmp_path):
    assert runner.invoke(app, _args(tmp_path, "--steps", "200")).exit_code == 0
    run = tmp_path / "sb3_disagree__ApartmentState-v0" / "bathtub" / "disagreement-0"
    other = tmp_path / "other"
    other.mkdir()
    (other / "config.yaml").write_text((run / "config.yaml").read_text())
    from stable_baselines3 import PPO

    ACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=1)).save(other / "model.zip")
    result = runner.invoke(app, ["eval", str(other), "--episodes", "2"])
    assert result.exit_code == 2 and "trained elsewhere" in result.output
    PPO("MlpPolicy", make_vec_env(STATE_ID, n_envs=1, env_kwargs=dict(goal="bed"))).save(other / "model.zip")
    result = runner.invoke(app, ["eval", str(other), "--episodes", "2"])
    assert result.exit_code == 2 and "could not be loaded as ACER" in " ".join(result.output.split())


def test_after_load_the_behaviours_first_infos_describe_the_reset_observations(tmp_path):
    from sb3_disagree.behaviour import BehaviourPolicy, BehaviourStep

    class Infos(BehaviourPolicy):
        def __init__(self):
            self.first = None

        def __call__(self, observations, probs, infos, episode_starts):
            if self.first is None:
                self.first = [dict(i) for i in infos]
            return BehaviourStep(th.multinomial(probs, 1).squeeze(-1), probs)

    env = make_vec_env(STATE_ID, n_envs=2, env_kwargs=dict(goal="bathtub"))
    ACER("MlpPolicy", env, n_steps=5).learn(20)
    ACER("MlpPolicy", env, n_steps=5).save(tmp_path / "m.zip")
    behaviour = Infos()
    model = ACER.load(tmp_path / "m.zip", env=env, behaviour=behaviour)
    model.learn(10, reset_num_timesteps=False)
    assert all("room" in info for info in behaviour.first), behaviour.first


def test_a_stale_temporary_folder_in_the_zoo_trips_nothing(tmp_path):
    from sb3_disagree.priors.zoo import Zoo

    zoo = tmp_path / "zoo"
    ACER("MlpPolicy", make_vec_env(STATE_ID, n_envs=1, env_kwargs=dict(goal="bed"))).save(tmp_path / "m.zip")
    Zoo(zoo).add(tmp_path / "m.zip", "bed", STATE_ID)
    (zoo / "sb3_disagree__ApartmentState-v0" / ".bed-x1y2").mkdir()  # an add killed between its writes
    (zoo / ".sb3_disagree__Nowhere-v0-tmp").mkdir()
    (zoo / "sb3_disagree__ApartmentState-v0" / ".bed-x1y2" / "model.zip").write_bytes(b"half")
    result = runner.invoke(app, ["priors", "list", "--zoo", str(zoo)])
    assert result.exit_code == 0 and [e.goal for e in Zoo(zoo).entries()] == ["bed"]


def test_resuming_a_run_whose_every_save_is_damaged_is_one_line_and_exit_2(tmp_path):
    assert runner.invoke(app, _args(tmp_path, "--steps", "200")).exit_code == 0
    run = tmp_path / "sb3_disagree__ApartmentState-v0" / "bathtub" / "disagreement-0"
    for model in [run / "model.zip", *run.glob("checkpoints/*/model.zip")]:
        with open(model, "r+b") as f:
            f.truncate(64)
    result = runner.invoke(app, ["train", "--goal", "bathtub", "--resume", str(run), "--steps", "400"])
    assert result.exit_code == 2 and "damaged" in result.output and "Traceback" not in result.output
