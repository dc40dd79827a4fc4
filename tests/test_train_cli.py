"""`dopt train` and `dopt eval` end to end on the state apartment with tiny budgets; interruption and resume."""

import pytest
import yaml
from envs import StopAt
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from typer.testing import CliRunner

import sb3_disagree.envs  # noqa: F401
from sb3_disagree import ACER
from sb3_disagree.cli.app import app
from sb3_disagree.options import MODES
from sb3_disagree.run import RunConfig, train

STATE_ID = "sb3_disagree/ApartmentState-v0"
runner = CliRunner()


@pytest.fixture(scope="module")
def zoo(tmp_path_factory):
    root = tmp_path_factory.mktemp("zoo")
    for goal in ("shower", "toilet", "bed"):
        r = runner.invoke(app, ["priors", "train", "--goal", goal, "--env", STATE_ID, "--zoo", str(root), "--rounds", "1",
                                "--steps-per-round", "200", "--epochs", "1", "--episodes", "2"])
        assert r.exit_code == 0, r.output
    return root


def _train_args(zoo, out, *extra):
    return ["train", "--goal", "bathtub", "--env", STATE_ID, "--zoo", str(zoo), "--out", str(out), "--steps", "400",
            "--n-envs", "2", *(() if "--mode" in extra else ("--mode", "disagreement", "--bare")), *extra]


@pytest.mark.parametrize("mode,bare", [(m, False) for m in MODES] + [("disagreement", True), ("kickstart", True)])
def test_train_writes_the_run_folder(zoo, tmp_path, mode, bare):
    # (a short card and validation: the finish's defaults themselves are RunConfig's, tested below)
    quick = ["--card-episodes", "2", *(["--bare"] if bare else ["--consistency-validation", "3"])]
    result = runner.invoke(app, _train_args(zoo, tmp_path, "--mode", mode, *quick))
    assert result.exit_code == 0, result.output
    run = tmp_path / "sb3_disagree__ApartmentState-v0" / "bathtub" / f"{mode}-0"
    for name in ["model.zip", "config.yaml", "progress.csv"]:
        assert (run / name).exists(), name
    assert list((run / "monitor").glob("*.monitor.csv")) and list(run.glob("events.out.tfevents*"))
    cfg = yaml.safe_load((run / "config.yaml").read_text())
    assert cfg["finished"] and cfg["num_timesteps"] >= 400
    # Every mode is finished unless bare: the harvest (all 400 steps here) acted greedily by the current weights,
    # its fit validated, the moving average acted with; ppo gets the harvest's validated fit, sampled as it trains.
    finished, acer = not bare, mode != "ppo"
    assert cfg["finish"] is finished
    assert (cfg["consistency_harvest"], cfg["greedy_phase"]) == ((30_000, 400 if acer else 0) if finished else (0, 0))
    assert cfg["consistency_validation"] == (3 if finished else 0)
    assert cfg["acer_kwargs"].get("ema_decay", 0.0) == (0.999 if finished and acer else 0.0)
    assert ("harvest" in (cfg.get("consistency") or {})) is finished
    # the replays' reference computed ahead: the overlapped loop's default in every ACER mode; ppo keeps no ACER setting
    assert cfg["acer_kwargs"].get("average_ahead", False) is acer and (acer or cfg["acer_kwargs"] == {})
    assert (cfg["frame_stack"], cfg["loop_flags"]) == (1, False)  # state observations: no frames to compare
    distilled = mode in ("kickstart", "disagreement-distill")
    assert cfg["acer_kwargs"].get("distill_coef", 0.0) == (1.0 if distilled else 0.0)
    if mode == "finetune":  # started from the nearest prior: its policy head, a Q head of its own
        prior = ACER.load(zoo / "sb3_disagree__ApartmentState-v0" / "shower" / "model.zip")
        assert ACER.load(run / "model.zip").policy.net_arch == prior.policy.net_arch
    if mode not in ("scratch", "finetune", "ppo"):
        assert "priors: shower" in result.output and cfg["chosen_priors"] == ["shower", "toilet"]
        header = (run / "progress.csv").read_text().splitlines()[0]
        assert ("prior/usage" in header) == (mode != "kickstart") and "behaviour/" in header
        assert ("prior/disagreement" in header) == mode.startswith("disagreement")
        assert ("train/distill_loss" in header) == distilled
        assert ("jsrl/horizon" in header) == (mode == "jsrl")
    # The trained model opens with plain SB3 tools, no priors or zoo needed.
    from sb3_disagree.run import algorithm_of

    model = algorithm_of(mode).load(run / "model.zip")
    env = make_vec_env(STATE_ID, n_envs=1, env_kwargs=dict(goal="bathtub"))
    evaluate_policy(model, env, n_eval_episodes=1)


def test_the_default_harvest_gives_way_to_the_options_given(zoo, tmp_path):
    result = runner.invoke(app, _train_args(zoo, tmp_path, "--mode", "kickstart", "--consistency-harvest", "200",
                                            "--greedy-phase", "0", "--card-episodes", "0"))
    assert result.exit_code == 0, result.output
    assert "of its last 200 training steps" in result.output
    cfg = yaml.safe_load((tmp_path / "sb3_disagree__ApartmentState-v0" / "bathtub" / "kickstart-0" / "config.yaml")
                         .read_text())
    assert (cfg["consistency_harvest"], cfg["greedy_phase"]) == (200, 0)
    assert cfg["consistency"]["harvest"]["episodes"] >= 0


@pytest.mark.parametrize("given,mode,resume,expected", [
    ({}, "kickstart", None, (30_000, 30_000, 40)),  # dopt train's default: the harvest acted greedily, validated
    ({"steps": 20_000}, "kickstart", None, (30_000, 20_000, 40)),  # a harvest past the budget: all of it greedy
    ({"consistency_harvest": 200}, "kickstart", None, (200, 200, 40)),  # the harvest asked for, acted greedily
    ({"consistency_harvest": 0}, "kickstart", None, (0, 0, 0)),  # no harvest, no greedy phase, no fit to validate
    ({"greedy_phase": 0}, "kickstart", None, (30_000, 0, 40)),  # a harvest sampled as training samples
    ({"greedy_phase": 5_000}, "kickstart", None, (30_000, 5_000, 40)),
    ({"consistency_validation": 0}, "kickstart", None, (30_000, 30_000, 0)),  # the last epoch's weights
    ({}, "disagreement", None, (30_000, 30_000, 40)),  # every ACER mode is finished
    ({"finish": False}, "disagreement", None, (0, 0, 0)),  # bare: as the paper's figures ran
    ({"finish": False, "consistency_harvest": 200}, "scratch", None, (200, 0, 0)),  # a part of it asked for
    ({}, "ppo", None, (30_000, 0, 40)),  # SB3's PPO: the harvest's validated fit, no greedy phase
    ({}, "kickstart", "RUN", (0, 0, 0)),  # a resumed run keeps its saved settings
])
def test_the_default_harvest_gives_way_to_the_options_given_each(given, mode, resume, expected):
    """RunConfig resolves what it is not given from the mode's preset; a saved run keeps what it ran with."""
    config = (RunConfig(goal="bathtub", mode=mode, **given) if resume is None
              else RunConfig.of_saved({"goal": "bathtub", "mode": mode, **given}))
    assert (config.consistency_harvest, config.greedy_phase, config.consistency_validation) == expected


@pytest.mark.parametrize("given,env,mode,resume,expected", [
    ({}, "sb3_disagree/Apartment-v0", "kickstart", None, (3, True)),  # dopt train's default memory
    ({}, STATE_ID, "kickstart", None, (1, False)),  # no frames to compare
    ({}, "sb3_disagree/Apartment-v0", "disagreement", None, (3, True)),  # every ACER mode is finished
    ({"finish": False}, "sb3_disagree/Apartment-v0", "disagreement", None, (1, False)),  # bare
    ({}, "sb3_disagree/Apartment-v0", "kickstart", "RUN", (1, False)),  # a resumed run keeps its saved memory
    ({"frame_stack": 4}, "sb3_disagree/Apartment-v0", "kickstart", None, (4, False)),  # a plain stack asked for
    ({"loop_flags": False}, "sb3_disagree/Apartment-v0", "kickstart", None, (1, False)),
    ({"loop_flags": True}, "sb3_disagree/Apartment-v0", "disagreement", None, (3, True)),
    ({"frame_stack": 2, "loop_flags": True}, STATE_ID, "kickstart", None, (2, True)),  # validation refuses it later
])
def test_the_default_memory_gives_way_to_the_options_given(given, env, mode, resume, expected):
    config = (RunConfig(goal="bathtub", env_id=env, mode=mode, **given) if resume is None
              else RunConfig.of_saved({"goal": "bathtub", "env_id": env, "mode": mode, **given}))
    assert (config.frame_stack, config.loop_flags) == expected


@pytest.mark.parametrize("args", [[], ["--mode", "disagreement"], ["--mode", "kickstart", "--no-overlap"],
                                  ["--mode", "disagreement-distill", "--bare"],
                                  ["--env", STATE_ID, "--mode", "jsrl", "--steps", "20000"]])
def test_dopt_train_runs_exactly_what_runconfig_resolves(args, monkeypatch, tmp_path):
    """`dopt train --goal G ...` and `train(RunConfig(goal=G, ...))` are one configuration, field by field: the
    command line resolves nothing itself."""
    from dataclasses import asdict

    import sb3_disagree.run as run_package

    seen = {}

    def capture(config, out, **kwargs):
        seen["config"] = config
        raise KeyboardInterrupt  # nothing trains

    monkeypatch.setattr(run_package, "train", capture)
    runner.invoke(app, ["train", "--goal", "bathtub", "--out", str(tmp_path), *args])
    switches = {"--no-overlap": ("overlap", False), "--bare": ("finish", False)}
    given = dict(switches[a] for a in args if a in switches)
    rest = [a for a in args if a not in switches]
    for flag, value in zip(rest[::2], rest[1::2]):
        given["env_id" if flag == "--env" else flag[2:].replace("-", "_")] = int(value) if value.isdigit() else value
    library = RunConfig(goal="bathtub", **given)
    assert asdict(seen["config"]) == asdict(library)
    if not args:  # the default: kickstarting with the finish, on the RGB apartment
        assert (library.frame_stack, library.loop_flags, library.consistency_harvest, library.greedy_phase,
                library.consistency_validation, library.overlap) == (3, True, 30_000, 30_000, 40, True)
        assert library.acer_kwargs["average_ahead"] and library.acer_kwargs["reward_scale"] == 1.0


def test_greedy_phase_takes_the_end_of_the_budget(zoo, tmp_path):
    import pandas as pd

    # (--ready 0: the phase does not wait for the run to be ready, tested in test_consistency.py)
    result = runner.invoke(app, _train_args(zoo, tmp_path, "--mode", "kickstart", "--greedy-phase", "200", "--ready", "0"))
    assert result.exit_code == 0, result.output
    run = tmp_path / "sb3_disagree__ApartmentState-v0" / "bathtub" / "kickstart-0"
    log = pd.read_csv(run / "progress.csv").dropna(subset=["behaviour/greedy_phase"])
    steps, share = log["time/total_timesteps"].to_numpy(), log["behaviour/greedy_phase"].to_numpy()
    assert (share[steps <= 200] == 0).all() and (share[steps > 240] == 1).all()  # 2 envs x 20 steps per segment
    assert yaml.safe_load((run / "config.yaml").read_text())["greedy_phase"] == 200


def test_periodic_evaluation_of_the_policy_alone(zoo, tmp_path):
    import numpy as np

    result = runner.invoke(app, _train_args(zoo, tmp_path, "--eval-every", "200", "--eval-episodes", "2"))
    assert result.exit_code == 0, result.output
    run = tmp_path / "sb3_disagree__ApartmentState-v0" / "bathtub" / "disagreement-0"
    evals = np.load(run / "evaluations.npz")
    assert list(evals["timesteps"]) == [200, 400] and evals["successes"].shape == (2, 2)
    assert "eval/success_rate" in (run / "progress.csv").read_text().splitlines()[0]
    assert "the new policy alone" in result.output


def test_subprocess_envs_train_like_in_process_ones(zoo, tmp_path):
    result = runner.invoke(app, _train_args(zoo, tmp_path, "--vec-env", "subproc", "--mode", "scratch"))
    assert result.exit_code == 0, result.output
    run = tmp_path / "sb3_disagree__ApartmentState-v0" / "bathtub" / "scratch-0"
    assert yaml.safe_load((run / "config.yaml").read_text())["vec_env"] == "subproc"
    assert len(list((run / "monitor").glob("*.monitor.csv"))) == 2


def test_overlap_is_the_default_and_can_be_turned_off(zoo, tmp_path):
    for flag, overlap in [((), True), (("--no-overlap",), False)]:
        out = tmp_path / str(overlap)
        result = runner.invoke(app, _train_args(zoo, out, *flag))
        assert result.exit_code == 0, result.output
        run = out / "sb3_disagree__ApartmentState-v0" / "bathtub" / "disagreement-0"
        assert yaml.safe_load((run / "config.yaml").read_text())["overlap"] is overlap
        assert ACER.load(run / "model.zip").overlap is overlap


def test_average_ahead_reaches_acer_and_needs_the_overlapped_loop(zoo, tmp_path):
    result = runner.invoke(app, _train_args(zoo, tmp_path / "bad", "--no-overlap", "--average-ahead"))
    assert result.exit_code == 2 and "needs the overlapped loop" in result.output
    assert len(result.output.strip().splitlines()) == 1 and not (tmp_path / "bad").exists()
    result = runner.invoke(app, _train_args(zoo, tmp_path, "--average-ahead"))
    assert result.exit_code == 0, result.output
    run = tmp_path / "sb3_disagree__ApartmentState-v0" / "bathtub" / "disagreement-0"
    assert yaml.safe_load((run / "config.yaml").read_text())["acer_kwargs"]["average_ahead"] is True
    assert ACER.load(run / "model.zip").average_ahead
    # on by default for kickstarting; off when asked, and off by itself without the overlapped loop
    for extra in (("--no-average-ahead",), ("--no-overlap",)):
        out = tmp_path / extra[0]
        result = runner.invoke(app, _train_args(zoo, out, "--mode", "kickstart", *extra))
        assert result.exit_code == 0, result.output
        run = out / "sb3_disagree__ApartmentState-v0" / "bathtub" / "kickstart-0"
        assert yaml.safe_load((run / "config.yaml").read_text())["acer_kwargs"].get("average_ahead", False) is False
        assert not ACER.load(run / "model.zip").average_ahead


def test_reward_scale_and_ema_decay_reach_acer_and_keep_the_other_defaults(zoo, tmp_path):
    from sb3_disagree.run import ACER_KWARGS, KICKSTART

    result = runner.invoke(app, _train_args(zoo, tmp_path, "--mode", "kickstart", "--reward-scale", "1",
                                            "--ema-decay", "0.99", "--collision-penalty", "0.1",
                                            "--reward-distance", "geodesic"))
    assert result.exit_code == 0, result.output
    run = tmp_path / "sb3_disagree__ApartmentState-v0" / "bathtub" / "kickstart-0"
    saved = yaml.safe_load((run / "config.yaml").read_text())
    assert saved["acer_kwargs"] == {**ACER_KWARGS, **KICKSTART, "reward_scale": 1.0, "ema_decay": 0.99,
                                   "average_ahead": True}  # kickstarting's preset, saved whole
    assert saved["env_kwargs"] == {"collision_penalty": 0.1, "reward_distance": "geodesic"}
    model = ACER.load(run / "model.zip")
    assert model.reward_scale == 1.0 and model.ema_decay == 0.99 and model.policy.ema_net is not None
    # A resumed run keeps the settings it was trained with.
    for flag, value in (("--reward-scale", "0.5"), ("--ema-decay", "0.5"), ("--collision-penalty", "0.5"),
                        ("--reward-distance", "euclidean")):
        result = runner.invoke(app, ["train", "--goal", "bathtub", "--resume", str(run), flag, value])
        assert result.exit_code == 2 and f"drop {flag}" in result.output, result.output


def test_overlap_trains_evaluates_and_resumes(zoo, tmp_path):
    import numpy as np

    result = runner.invoke(app, _train_args(zoo, tmp_path, "--eval-every", "200", "--eval-episodes", "2"))
    assert result.exit_code == 0, result.output
    run = tmp_path / "sb3_disagree__ApartmentState-v0" / "bathtub" / "disagreement-0"
    assert yaml.safe_load((run / "config.yaml").read_text())["overlap"] is True
    assert list(np.load(run / "evaluations.npz")["timesteps"]) == [200, 400]
    assert ACER.load(run / "model.zip").overlap
    # An interrupted overlapped run saves what it learned and resumes overlapped.
    config = RunConfig(goal="bathtub", env_id=STATE_ID, steps=600, n_envs=2, zoo=str(zoo), overlap=True, seed=1)
    run, model, finished = train(config, tmp_path, callbacks=[StopAt(200)])
    assert not finished and (_checkpoint(run) / "replay_buffer.npz").exists()
    result = runner.invoke(app, ["train", "--goal", "bathtub", "--resume", str(run)])
    assert result.exit_code == 0, result.output
    cfg = yaml.safe_load((run / "config.yaml").read_text())
    assert cfg["finished"] and cfg["overlap"] is True and ACER.load(run / "model.zip").num_timesteps >= 600


def test_eval_draws_and_records_the_policy_alone(zoo, tmp_path):
    """--trajectory and --video show the evaluated policy's own episodes (no recorded training episode needed)."""
    from PIL import Image

    from sb3_disagree.run import load_run
    from sb3_disagree.run.video import play, write_video

    assert runner.invoke(app, _train_args(zoo, tmp_path, "--card-episodes", "0")).exit_code == 0
    run = tmp_path / "sb3_disagree__ApartmentState-v0" / "bathtub" / "disagreement-0"
    saved = yaml.safe_load((run / "config.yaml").read_text())
    saved["env_kwargs"] = {"max_episode_steps": 12}  # short episodes: an untrained policy rarely ends one sooner
    (run / "config.yaml").write_text(yaml.safe_dump(saved))
    png, gif, mp4 = tmp_path / "path.png", tmp_path / "agent.gif", tmp_path / "agent.mp4"
    assert not (run / "trajectories.jsonl").exists()
    result = runner.invoke(app, ["eval", str(run), "--episodes", "3", "--trajectory", str(png), "--episode", "2",
                                 "--video", str(gif), "--video-episodes", "2"])
    assert result.exit_code == 0, result.output
    assert "over 3 episodes" in result.output and png.stat().st_size > 10_000
    assert "episode 2 of the policy alone (greedy)" in result.output
    # One frame per observation: each episode's first, then one per step; the GIF holds every one of them.
    config, model = load_run(run)
    played = play(model, config, episodes=2, frames=True)
    expected = sum(e.length + 1 for e in played)
    assert all(1 <= e.length <= 12 for e in played) and expected == sum(len(e.frames) for e in played)
    assert f"{expected} frames of 2 episodes" in " ".join(result.output.split())
    with Image.open(gif) as image:
        assert image.n_frames == expected and image.size == (played[0].frames[0].shape[1], played[0].frames[0].shape[0])
    assert write_video(played, mp4) == expected and mp4.stat().st_size > 1_000
    result = runner.invoke(app, ["eval", str(run), "--episodes", "2", "--video", str(tmp_path / "agent.avi")])
    assert result.exit_code == 2 and ".gif or .mp4" in result.output
    result = runner.invoke(app, ["eval", str(run / "model.zip"), "--episodes", "2", "--stochastic"])
    assert result.exit_code == 0 and "sampled actions" in result.output and "greedy actions" not in result.output


def _checkpoint(run):
    """The run's newest complete checkpoint folder."""
    from sb3_disagree.checkpoints import latest_checkpoint

    return latest_checkpoint(run)[0]


def test_interrupt_saves_and_resume_continues_the_step_count(zoo, tmp_path):
    config = RunConfig(goal="bathtub", env_id=STATE_ID, steps=600, n_envs=2, zoo=str(zoo), overlap=False, ready=0)
    run, model, finished = train(config, tmp_path, callbacks=[StopAt(200)])
    assert not finished and (_checkpoint(run) / "replay_buffer.npz").exists() and (run / "model.zip").exists()
    stopped_at = model.num_timesteps
    assert 200 <= stopped_at < 600
    result = runner.invoke(app, ["train", "--goal", "bathtub", "--resume", str(run)])
    assert result.exit_code == 0, result.output
    cfg = yaml.safe_load((run / "config.yaml").read_text())
    assert cfg["finished"] and cfg["num_timesteps"] >= 600
    assert cfg["overlap"] is False  # the saved run's loop, whatever the command line's default
    assert ACER.load(run / "model.zip").num_timesteps == cfg["num_timesteps"]
    assert not (_checkpoint(run) / "replay_buffer.npz").exists()  # a finished run keeps no buffer
    assert len(list((run / "checkpoints").iterdir())) == 1  # nor older checkpoints
    # A finished run continues to a larger budget on request.
    result = runner.invoke(app, ["train", "--goal", "bathtub", "--resume", str(run), "--steps", "1000"])
    assert result.exit_code == 0, result.output
    cfg = yaml.safe_load((run / "config.yaml").read_text())
    assert cfg["steps"] == 1000 and 1000 <= cfg["num_timesteps"] < 1100 and "/1,000 | " in result.output


def test_resumed_run_appends_to_its_history(zoo, tmp_path):
    """Monitor files, progress.csv and evaluations.npz of a continued run hold both legs, in order."""
    import numpy as np
    import pandas as pd

    def episodes(run):
        return [pd.read_csv(f, skiprows=1) for f in sorted((run / "monitor").glob("*.monitor.csv"))]

    config = RunConfig(goal="bathtub", env_id=STATE_ID, steps=1000, n_envs=2, zoo=str(zoo), eval_every=500,
                       eval_episodes=1, ready=0)
    run, _, _ = train(config, tmp_path)  # episodes last at most 500 steps: each env ends one at least
    first = episodes(run)
    assert all(len(m) for m in first)
    run, model, finished = train(config, resume=run, steps=2000)
    assert finished and model.num_timesteps == 2000
    both = episodes(run)
    for before, after in zip(first, both):
        assert len(after) > len(before) and after.iloc[:len(before)].equals(before)
    assert sum(int(m["l"].sum()) for m in first) < sum(int(m["l"].sum()) for m in both) <= 2000
    steps = pd.read_csv(run / "progress.csv")["time/total_timesteps"].dropna().to_numpy()
    assert steps[0] <= 1000 < steps[-1] and np.all(np.diff(steps) > 0)
    evals = np.load(run / "evaluations.npz")
    assert list(evals["timesteps"]) == [500, 1000, 1500, 2000] and evals["successes"].shape == (4, 1)


@pytest.mark.parametrize("extra,message", [
    (["--greedy-phase", "500"], "--greedy-phase must be between 0 and --steps"),
    (["--greedy-phase", "100", "--mode", "ppo"], "--greedy-phase is a behaviour of ACER"),
    (["--beta", "-0.5"], "--beta must be >= 0"),
    (["--mode", "greedy"], "--mode must be one of"),
    (["--priors", "shower"], "at least two"),
    (["--priors", "shower,sofa"], "no usable prior for sofa"),
    (["--vec-env", "threads"], "--vec-env must be dummy or subproc"),
    (["--env", "sb3_disagree/Castle-v0"], "unknown environment"),
    (["--eval-every", "-5"], "--eval-every must be >= 0"),
    (["--reward-scale", "0"], "--reward-scale must be a number > 0"),
    (["--reward-scale", "1", "--mode", "ppo"], "--reward-scale: settings of ACER; --mode ppo trains SB3's PPO"),
    (["--ema-decay", "1"], "--ema-decay must be a number in [0, 1)"),
    (["--ema-decay", "0.9", "--mode", "ppo"], "--ema-decay: settings of ACER; --mode ppo trains SB3's PPO"),
    (["--collision-penalty", "-1"], "--collision-penalty must be a number >= 0"),
    (["--reward-distance", "manhattan"], "--reward-distance must be euclidean or geodesic"),
    (["--loop-flags", "--frame-stack", "1"], "--loop-flags compares the newest frame with older ones: give --frame-stack 2"),
    (["--loop-flags", "--frame-stack", "2"], "--loop-flags compares frames: the env's observations must be images"),
])
def test_bad_input_is_a_message_and_exit_code_2(zoo, tmp_path, extra, message):
    result = runner.invoke(app, _train_args(zoo, tmp_path, *extra))
    assert result.exit_code == 2 and message in result.output, result.output


def test_unknown_goal_word_and_too_few_priors(zoo, tmp_path):
    result = runner.invoke(app, ["train", "--goal", "xqzt", "--env", STATE_ID, "--zoo", str(zoo), "--out", str(tmp_path)])
    assert result.exit_code == 2 and "unknown goal object 'xqzt'" in result.output
    lonely = tmp_path / "lonely"
    (lonely / "sb3_disagree__ApartmentState-v0").mkdir(parents=True)
    import shutil

    shutil.copytree(zoo / "sb3_disagree__ApartmentState-v0" / "shower", lonely / "sb3_disagree__ApartmentState-v0" / "shower")
    result = runner.invoke(app, ["train", "--goal", "bathtub", "--env", STATE_ID, "--zoo", str(lonely), "--out", str(tmp_path)])
    assert result.exit_code == 2 and "2 priors are needed" in result.output
    result = runner.invoke(app, ["train", "--goal", "bathtub", "--resume", str(tmp_path / "nothing")])
    assert result.exit_code == 2 and "not a run folder" in result.output
    out = tmp_path / "out-missing-zoo"
    result = runner.invoke(app, ["train", "--goal", "bathtub", "--env", STATE_ID, "--zoo", str(tmp_path / "no-zoo"),
                                 "--out", str(out)])
    assert result.exit_code == 2 and "no-zoo does not exist" in " ".join(result.output.split()), result.output
    assert not out.exists() and not (tmp_path / "no-zoo").exists()  # nothing written, no zoo made up


def test_the_ppo_modes_settings_are_the_published_hyperparameters_file():
    from pathlib import Path

    from sb3_disagree.run import PPO_KWARGS

    published = yaml.safe_load((Path(__file__).parents[1] / "sb3_disagree/hyperparams/ppo.yml").read_text())
    entry = dict(published["sb3_disagree/Apartment-v0"])
    assert entry.pop("n_envs") == RunConfig(goal="x").n_envs and entry.pop("policy") == "CnnPolicy"
    entry.pop("n_timesteps")
    for key in ("learning_rate", "clip_range"):
        entry[key] = float(entry[key].removeprefix("lin_"))
    assert entry == PPO_KWARGS


def test_a_run_whose_output_is_not_a_terminal_prints_plain_progress_lines(zoo, tmp_path):
    result = runner.invoke(app, _train_args(zoo, tmp_path, "--progress-every", "0"))  # bare: the priors act
    assert result.exit_code == 0, result.output
    lines = [line for line in result.output.splitlines() if line.startswith("steps ")]
    assert len(lines) >= 2 and lines[-1].startswith("steps 400/400 | ")
    assert all("env steps/s" in line and "spent" in line for line in lines)
    assert "prior usage" in lines[-1] and "success" in lines[-1]


def test_a_model_card_beside_the_model_and_priors_add_reads_it(zoo, tmp_path):
    from sb3_disagree.model_card import read_model_card

    result = runner.invoke(app, _train_args(zoo, tmp_path, "--card-episodes", "2"))
    assert result.exit_code == 0, result.output
    run = tmp_path / "sb3_disagree__ApartmentState-v0" / "bathtub" / "disagreement-0"
    header = read_model_card(run / "README.md")
    assert header["library_name"] == "stable-baselines3" and STATE_ID in header["tags"] and header["license"] == "mit"
    # The card's usage block runs as written (fewer episodes), prints success, and SB3 warns of nothing.
    text = (run / "README.md").read_text()
    usage = text.split("```python\n")[1].split("```")[0].replace("n_eval_episodes=100", "n_eval_episodes=2")
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-W", "always", "-c", usage], cwd=run, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0 and done.stdout.startswith("success "), done.stderr[-2000:]
    assert "Warning" not in done.stderr, done.stderr[-2000:]
    metrics = {m["name"]: m["value"] for m in header["model-index"][0]["results"][0]["metrics"]}
    assert set(metrics) == {"success_rate (greedy)", "mean_reward (greedy)", "success_rate (sampled)",
                            "mean_reward (sampled)"}
    ours = header["sb3_disagree"]
    assert ours["goal"] == "bathtub" and [p["goal"] for p in ours["priors"]] == ["shower", "toilet"]
    assert ours["evaluation"]["greedy"]["episodes"] == 2 and ours["command"].startswith("dopt ")
    assert "the new policy alone, greedy" in result.output and "the new policy alone, sampled" in result.output
    # The card names the goal for the zoo.
    other = tmp_path / "zoo"
    result = runner.invoke(app, ["priors", "add", str(run / "model.zip"), "--env", STATE_ID, "--zoo", str(other),
                                 "--episodes", "0"])
    assert result.exit_code == 0, result.output
    from sb3_disagree.priors.zoo import Zoo

    card = Zoo(other).get("bathtub", STATE_ID).card
    assert card.training["model_card"]["mode"] == "disagreement"
    result = runner.invoke(app, ["priors", "add", str(run / "model.zip"), "--zoo", str(other), "--episodes", "0",
                                 "--replace"])
    assert result.exit_code == 2 and "--env sb3_disagree/ApartmentState-v0" in " ".join(result.output.split())


def test_evaluations_along_the_way_leave_training_unchanged(zoo, tmp_path):
    """The periodic evaluations draw from their own random stream: a run that evaluates trains the same weights."""
    import torch as th

    weights = []
    for eval_every in (0, 250):
        config = RunConfig(goal="bathtub", env_id=STATE_ID, steps=600, overlap=False, n_envs=2, zoo=str(zoo), eval_every=eval_every,
                           eval_episodes=2, acer_kwargs={"replay_start": 100})
        _, model, _ = train(config, tmp_path / str(eval_every))
        weights.append(th.nn.utils.parameters_to_vector(model.policy.net.parameters()).detach())
    assert th.equal(weights[0], weights[1])


def test_an_unknown_features_dtype_is_refused_before_anything_is_written(tmp_path):
    result = runner.invoke(app, ["train", "--goal", "bathtub", "--features-dtype", "float16", "--out", str(tmp_path)])
    assert result.exit_code == 2 and "--features-dtype must be float32 or bfloat16" in result.output
    assert not any(tmp_path.iterdir())

