"""The greedy-consistency phase: loops cut by hand, a looping greedy policy made to reach the goal, dopt consistency."""

import json
import sys
from collections import deque

import numpy as np
import pytest
import torch as th
import yaml
from envs import StopAt, TurnEnv
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from typer.testing import CliRunner

from sb3_disagree import ACER
from stable_baselines3.common.callbacks import BaseCallback

from sb3_disagree.finish.consistency import (HarvestLabels, RoundStats, _Labels, _Rounds, collect_escapes,
                                          expert_loop_labels, fit_best_epoch, fit_labels, greedy_consistency,
                                          loop_free_labels)
from sb3_disagree.acer.memory import push_frames
from sb3_disagree.cli.app import app

runner = CliRunner()


@pytest.mark.parametrize("keys, actions, expected", [
    ("ABCD", [2, 2, 2, 2], [(0, 2), (1, 2), (2, 2), (3, 2)]),  # no loop: every step as taken
    ("ABAC", [1, 0, 2, 2], [(0, 2), (2, 2), (3, 2)]),  # A -> B -> A: B dropped, A labelled by what left it
    ("AAB", [2, 0, 2], [(0, 0), (1, 0), (2, 2)]),  # a blocked forward (the frame unchanged) relabelled
    ("ABCBAD", [1, 1, 0, 0, 2, 2], [(0, 2), (4, 2), (5, 2)]),  # a loop inside a loop: both cut
    ("ABCB", [0, 1, 2, 0], [(0, 0), (1, 0), (3, 0)]),  # the last action from B replaces the first
])
def test_loop_free_labels_by_hand(keys, actions, expected):
    assert loop_free_labels(list(keys), actions) == expected


@pytest.mark.parametrize("keys, actions, experts, success, expected", [
    ("ABAC", [1, 0, 2, 2], [2, 1, 0, 2], True, [(0, 2), (2, 0), (3, 2)]),  # A's two visits: the expert; C: the path
    ("ABAC", [1, 0, 2, 2], [2, 1, 0, 2], False, [(0, 2), (2, 0)]),  # a failure: only the loop's poses
    ("AAB", [2, 0, 2], [1, 1, 2], True, [(0, 1), (1, 1), (2, 2)]),  # a blocked forward: the expert at both visits
    ("ABCBAD", [1, 1, 0, 0, 2, 2], [0, 1, 2, 1, 0, 2], False, [(0, 0), (1, 1), (3, 1), (4, 0)]),  # C once: dropped
    ("ABCD", [2, 2, 0, 2], [1, 1, 1, 1], True, [(0, 2), (1, 2), (2, 0), (3, 2)]),  # no loop: the path as taken
    ("ABCD", [2, 2, 0, 2], [1, 1, 1, 1], False, []),
])
def test_expert_loop_labels_by_hand(keys, actions, experts, success, expected):
    assert expert_loop_labels(list(keys), actions, experts, success) == expected


def _episode_stacks(rng: np.random.Generator, steps: int, k: int) -> list[np.ndarray]:
    """The stacks a k-frame policy sees over an episode of random (3, 4, 5) frames, as push_frames builds them."""
    stacks, stack = [], None
    for t in range(steps):
        frame = rng.integers(1, 255, (1, 3, 4, 5), dtype=np.uint8)
        stack = push_frames(stack, frame, np.array([t == 0]), k)
        stacks.append(stack[0])
    return stacks


@pytest.mark.parametrize("k", [1, 3, 6])
def test_labels_rebuild_each_stack_from_one_frame_a_step(k):
    rng = np.random.default_rng(k)
    labels = _Labels(k)
    whole = _episode_stacks(rng, 12, k)
    for stacks in (whole, whole[5:], whole[:1]):  # from the episode's start, from under way (a harvest), one step
        keys = [x[len(x) - 3:].tobytes() for x in stacks]
        keys[len(keys) // 2:] = keys[:len(keys) - len(keys) // 2]  # a loop back to the start, cut by the labels
        path = loop_free_labels(keys, list(rng.integers(0, 3, len(stacks))))
        before = len(labels.actions)
        labels.add_episode(stacks, path)
        assert np.array_equal(labels.inputs[before:], np.stack([stacks[t] for t, _ in path]))
        assert labels.actions[before:] == [a for _, a in path]
    assert len(labels.frames) == 12 + 7 + 1 + 3 * (k - 1)  # one frame a step, k - 1 more at each first step


def test_rounds_index_as_one_array():
    rng = np.random.default_rng(0)
    rounds, parts = _Rounds(), []
    for steps in (5, 1, 7):
        labels = _Labels(3)
        stacks = _episode_stacks(rng, steps, 3)
        labels.add_episode(stacks, [(t, t % 3) for t in range(steps)])
        rounds.add(labels)
        parts.append(np.stack(stacks))
    rounds.add(_Labels(3))  # a round without labels adds nothing
    whole = np.concatenate(parts)
    index = rng.permutation(len(whole))
    assert len(rounds) == 13 and np.array_equal(rounds[index], whole[index])
    assert np.array_equal(rounds[np.array([12, 0, 5])], whole[[12, 0, 5]])


def _spinning_model(frame_stack: int = 1) -> ACER:
    """A policy whose argmax everywhere is turn left (a loop), its samples turning or moving."""
    env = make_vec_env(TurnEnv, n_envs=4, seed=0)
    model = ACER("MlpPolicy", env, seed=0, policy_kwargs=dict(net_arch=[32], frame_stack=frame_stack))
    with th.no_grad():
        head = model.policy.net.action_net
        head.weight.zero_()
        head.bias.copy_(th.tensor([1.0, 0.0, 0.0]))
    return model


def _greedy_success(model: ACER, seed: int = 100) -> float:
    env = make_vec_env(TurnEnv, n_envs=4, seed=seed)
    successes = []
    evaluate_policy(model, env, n_eval_episodes=40, deterministic=True,
                    callback=lambda local, _: successes.append(local["info"]["is_success"]) if local["done"] else None)
    return float(np.mean(successes))


def test_collect_escapes_labels_only_successful_loop_free_paths():
    model = _spinning_model()
    labels, counts = collect_escapes(model, make_vec_env(TurnEnv, n_envs=4, seed=1), 800, np.random.default_rng(0))
    assert counts["env_steps"] == 800 and 0 < counts["successes"] <= counts["episodes"]
    inputs = np.stack(labels.inputs)
    assert inputs.shape[1:] == (20,) and len(inputs) == len(labels.actions)
    # Greedy is turn left; a loop-free path that reaches the east end must also move, and never at a wall.
    actions = np.asarray(labels.actions)
    assert (actions == 2).any()
    heading = inputs.argmax(1) % 4
    assert not ((actions == 2) & np.isin(heading, [1, 3])).any()


def test_a_sharp_looping_policy_escapes_only_with_a_uniform_share_in_loops():
    """pi = 1 on turning left: sampling from pi in a loop turns left again, forever; a uniform share escapes."""
    model = _spinning_model()
    with th.no_grad():
        model.policy.net.action_net.bias.copy_(th.tensor([30.0, 0.0, 0.0]))
    env = make_vec_env(TurnEnv, n_envs=4, seed=1)
    _, counts = collect_escapes(model, env, 800, np.random.default_rng(0))
    assert counts["episodes"] > 0 and counts["successes"] == 0
    labels, counts = collect_escapes(model, env, 800, np.random.default_rng(0), loop_uniform=0.5)
    assert counts["successes"] > 0 and (np.asarray(labels.actions) == 2).any()


def test_the_expert_labels_the_loops_that_a_sharp_policy_cannot_escape():
    """pi = 1 on turning left, no uniform share: no episode escapes, so the plain phase has no label at all; with
    the expert in loops every spin is labelled by the expert, and the phase makes the spinner reach the goal."""
    model = _spinning_model()
    with th.no_grad():
        model.policy.net.action_net.bias.copy_(th.tensor([30.0, 0.0, 0.0]))
    env = make_vec_env(TurnEnv, n_envs=4, seed=1)
    labels, counts = collect_escapes(model, env, 800, np.random.default_rng(0), expert_in_loops=True)
    assert counts["successes"] == 0 and counts["expert_labels"] == len(labels.actions) > 0
    heading = np.stack(labels.inputs).argmax(1) % 4
    assert np.array_equal(labels.actions, [{0: 2, 1: 1, 2: 0, 3: 0}[h] for h in heading])
    assert _greedy_success(model) == 0.0
    history = greedy_consistency(model, env, rounds=2, steps=800, epochs=20, learning_rate=3e-3, seed=0,
                                 expert_in_loops=True)
    assert history[0].expert_labels > 0 and history[0].as_dict()["expert_labels"] == history[0].expert_labels
    assert _greedy_success(model) >= 0.95
    assert "expert_labels" not in RoundStats(1, 1, 1, 1, 0.0, 1.0).as_dict()  # none: the card as before


@pytest.mark.parametrize("frame_stack", [1, 2])
def test_phase_turns_a_looping_greedy_policy_into_one_that_reaches_the_goal(frame_stack):
    model = _spinning_model(frame_stack)
    assert _greedy_success(model) == 0.0  # spins in place
    history = greedy_consistency(model, make_vec_env(TurnEnv, n_envs=4, seed=1), rounds=3, steps=2000, epochs=20,
                                 learning_rate=3e-3, seed=0)
    assert [r.env_steps for r in history] == [2000] * 3 and all(r.labels > 0 for r in history)
    assert _greedy_success(model) >= 0.95


class _RecordSteps(BaseCallback):
    """Every env step of training as (observation before it, action, done, success, the network's input), from what
    the env returned and what ACER fed the network."""

    def _on_training_start(self) -> None:
        self.before, self.steps = self.model._last_obs.copy(), []

    def _on_step(self) -> bool:
        infos = self.locals["infos"]
        net_input = self.locals["observations"][self.locals["step"]] if "observations" in self.locals else self.before
        self.steps.append((self.before, self.locals["actions"].copy(), self.locals["dones"].copy(),
                           [bool(info.get("is_success")) for info in infos], net_input.copy()))
        self.before = self.locals["new_obs"].copy()
        return True


@pytest.mark.parametrize("algorithm", ["acer", "ppo"])
def test_harvest_keeps_the_loop_free_paths_of_training_episodes_after_its_start(algorithm):
    """ACER's own training episodes, or SB3's PPO's (the finish's fit acts through the policy's distribution)."""
    from stable_baselines3 import PPO

    env = make_vec_env(TurnEnv, n_envs=4, seed=3)
    model = (ACER("MlpPolicy", env, seed=0, n_steps=10, policy_kwargs=dict(net_arch=[32])) if algorithm == "acer" else
             PPO("MlpPolicy", env, seed=0, n_steps=50, batch_size=50, policy_kwargs=dict(net_arch=[32])))
    record, harvest = _RecordSteps(), HarvestLabels(start=800)
    model.learn(2000, callback=[record, harvest])
    # The same labels computed here from the recorded steps: env by env, from step 200 (800 env steps / 4 envs) on,
    # an episode's loop-free path when it reached the goal.
    expected = []
    for i in range(4):
        trail = []
        for before, actions, dones, successes, _ in record.steps[200:]:
            trail.append((before[i], int(actions[i])))
            if dones[i]:
                if successes[i]:
                    labels = loop_free_labels([o.tobytes() for o, _ in trail], [a for _, a in trail])
                    expected += [(trail[t][0].tobytes(), a) for t, a in labels]
                trail = []
    got = [(x.tobytes(), a) for x, a in zip(harvest.trails.labels.inputs, harvest.trails.labels.actions)]
    assert len(expected) > 50 and sorted(got) == sorted(expected)
    assert 0 < harvest.trails.successes <= harvest.trails.episodes
    # Fitted alone (no round, no env step): where a pose's labels have a strict majority, the argmax is it.
    history = greedy_consistency(model, None, rounds=0, epochs=200, learning_rate=3e-3, harvest=harvest)
    assert history[0].env_steps == 0 and history[0].labels == len(expected)
    votes: dict[bytes, list[int]] = {}
    for key, action in expected:
        votes.setdefault(key, []).append(action)
    majority = {k: np.bincount(v, minlength=3).argmax() for k, v in votes.items()
                if np.bincount(v).max() * 2 > len(v)}
    obs = np.stack([np.frombuffer(k, dtype=np.float32) for k in majority])
    assert len(majority) >= 5 and (_probs(model, obs).argmax(1) == np.array(list(majority.values()))).all()


def test_harvest_keeps_the_stacks_a_memory_policy_saw():
    # Three frames, the harvest starting in the middle of episodes: each label's input, rebuilt from single
    # frames, is the stack ACER fed the network at that step, the frames from before the harvest's start included.
    env = make_vec_env(TurnEnv, n_envs=4, seed=3)
    model = ACER("MlpPolicy", env, seed=0, n_steps=10, policy_kwargs=dict(net_arch=[32], frame_stack=3))
    record, harvest = _RecordSteps(), HarvestLabels(start=1602)  # from the 401st step of the 4 envs on
    model.learn(3000, callback=[record, harvest])
    expected, under_way = [], 0
    for i in range(4):
        trail, first = [], not record.steps[399][2][i]
        for before, actions, dones, successes, net_input in record.steps[400:]:
            trail.append((net_input[i], before[i].tobytes(), int(actions[i])))
            if dones[i]:
                if successes[i]:
                    labels = loop_free_labels([key for _, key, _ in trail], [a for _, _, a in trail])
                    expected += [(trail[t][0].tobytes(), a) for t, a in labels]
                    under_way += first
                trail, first = [], False
    got = [(x.tobytes(), a) for x, a in zip(harvest.trails.labels.inputs, harvest.trails.labels.actions)]
    assert under_way >= 1 and len(expected) > 50 and sorted(got) == sorted(expected)
    assert harvest.trails.labels.inputs.shape[1:] == (60,)


@pytest.mark.parametrize("scores, kept", [
    ([(0.5, 10.0), (0.9, 10.0), (0.7, 10.0)], 2),  # the best success
    ([(0.9, 20.0), (0.9, 10.0), (0.5, 1.0)], 2),  # a tie: the shorter episodes
    ([(0.9, 10.0), (0.9, 10.0), (0.9, 10.0)], 1),  # a full tie: the earliest
    ([(0.1, 10.0), (0.2, 10.0), (0.3, 10.0)], 3),  # rising: the last, as the unvalidated fit
])
def test_the_validated_fit_keeps_the_weights_of_its_best_epoch(scores, kept):
    model = _spinning_model()
    rng = np.random.default_rng(0)
    inputs = rng.uniform(-1, 1, (300, *model.policy.net_observation_space.shape)).astype(np.float32)
    actions = rng.integers(0, 3, 300)
    start = {k: v.clone() for k, v in model.policy.acting_net.state_dict().items()}
    calls = iter(scores)
    epoch, loss, accuracy, validation = fit_best_epoch(model.policy, inputs, actions, 3, 1e-2, 32,
                                                       np.random.default_rng(7), lambda: next(calls))
    assert epoch == kept and validation == [s for s, _ in scores]
    fitted = _probs(model, inputs)
    # The same fit stopped after the kept epoch: the same minibatches in the same order, so the same weights.
    model.policy.acting_net.load_state_dict(start)
    expected = fit_labels(model.policy, inputs, actions, kept, 1e-2, 32, np.random.default_rng(7))
    assert (loss, accuracy) == pytest.approx(expected)
    np.testing.assert_allclose(fitted, _probs(model, inputs), atol=1e-6)


def test_phase_refuses_bad_settings():
    with pytest.raises(ValueError, match="rounds and epochs"):
        greedy_consistency(_spinning_model(), make_vec_env(TurnEnv, n_envs=4), rounds=0)


def test_dopt_consistency_writes_beside_the_run_and_never_over_it(tmp_path):
    run = tmp_path / "run"
    result = runner.invoke(app, ["train", "--goal", "bathtub", "--env", "sb3_disagree/ApartmentState-v0", "--mode",
                                 "scratch", "--steps", "200", "--n-envs", "2", "--out", str(tmp_path / "runs"), "--bare"])
    assert result.exit_code == 0, result.output
    (run_dir,) = (tmp_path / "runs").glob("*/bathtub/scratch-0")
    before = (run_dir / "model.zip").read_bytes()
    args = ["consistency", str(run_dir), "--rounds", "1", "--steps", "200", "--epochs", "1", "--episodes", "2"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    out = json.loads((run_dir / "consistent" / "result.json").read_text())
    assert out["env_steps"] == 200 and out["final_alone_greedy"]["episodes"] == 2 and out["final_alone"]["episodes"] == 2
    assert yaml.safe_load((run_dir / "consistent" / "config.yaml").read_text())["goal"] == "bathtub"
    assert (run_dir / "model.zip").read_bytes() == before  # the run's own model untouched
    ACER.load(run_dir / "consistent" / "model.zip")
    again = runner.invoke(app, args)
    assert again.exit_code == 2 and "--force" in again.output
    assert runner.invoke(app, [*args, "--force"]).exit_code == 0
    bad = runner.invoke(app, ["consistency", str(run_dir), "--rounds", "0", "--force"])
    assert bad.exit_code == 2 and "--rounds" in bad.output and "Traceback" not in bad.output
    assert runner.invoke(app, ["consistency", str(tmp_path / "nothing")]).exit_code == 2
    damaged = tmp_path / "damaged"
    damaged.mkdir()
    (damaged / "model.zip").write_bytes(b"not a zip")
    (damaged / "config.yaml").write_text((run_dir / "config.yaml").read_text())
    result = runner.invoke(app, ["consistency", str(damaged)])
    assert result.exit_code == 2 and "could not be loaded" in result.output and not (damaged / "consistent").exists()
    assert runner.invoke(app, [*args, "--name", "../elsewhere"]).exit_code == 2 and not (tmp_path / "elsewhere").exists()
    assert runner.invoke(app, [*args, "--name", "short"]).exit_code == 0 and (run_dir / "short" / "model.zip").exists()


def test_dopt_train_refines_model_zip_when_asked_and_resume_keeps_it(tmp_path, monkeypatch):
    # The phase's learning is tested above; here what dopt train does with it, on a phase that shifts the logits.
    def shifting_phase(model, env, rounds, steps, epochs=3, seed=0, on_round=None, harvest=None, validate=None):
        with th.no_grad():
            for p in model.policy.acting_net.parameters():
                p.add_(0.1)
        history = [RoundStats(0, 3, 2, 10, 0.5, 0.9)]  # the harvest's fit: no env step more
        for stats in history:
            on_round(stats)
        return history

    import sb3_disagree.run  # noqa: F401  (the module, shadowed on the package by its train function)

    monkeypatch.setattr(sys.modules["sb3_disagree.run.train"], "greedy_consistency", shifting_phase)
    base = ["train", "--goal", "bathtub", "--env", "sb3_disagree/ApartmentState-v0", "--mode", "scratch", "--steps",
            "200", "--n-envs", "2", "--card-episodes", "2", "--out", str(tmp_path), "--bare"]
    result = runner.invoke(app, [*base, "--consistency-harvest", "200"])
    assert result.exit_code == 0, result.output
    assert result.output.count("greedy consistency, the training's last episodes") == 1
    (run_dir,) = tmp_path.glob("*/bathtub/scratch-0")
    phase = yaml.safe_load((run_dir / "config.yaml").read_text())["consistency"]
    assert phase["num_timesteps"] == 200 and phase["env_steps"] == 0 and len(phase["per_round"]) == 1
    (checkpoint,) = (run_dir / "checkpoints").iterdir()
    trained, refined = ACER.load(checkpoint / "model.zip"), ACER.load(run_dir / "model.zip")
    obs = np.random.default_rng(0).uniform(-1, 1, (64, 4)).astype(np.float32)
    assert not np.allclose(_probs(trained, obs), _probs(refined, obs), atol=1e-4)
    # Resuming the finished run redoes nothing: the refined model stays (no phase on the trained one again).
    before = (run_dir / "model.zip").read_bytes()
    again = runner.invoke(app, ["train", "--goal", "bathtub", "--resume", str(run_dir), "--card-episodes", "0"])
    assert again.exit_code == 0, again.output
    assert "greedy consistency" not in again.output and (run_dir / "model.zip").read_bytes() == before


def test_an_interrupted_fit_leaves_the_trained_model(tmp_path, monkeypatch):
    import sb3_disagree.run  # noqa: F401

    module = sys.modules["sb3_disagree.run.train"]
    calls = []

    def interrupted(model, env, rounds, steps, epochs=3, seed=0, on_round=None, harvest=None, validate=None):
        calls.append("interrupted")
        raise KeyboardInterrupt

    monkeypatch.setattr(module, "greedy_consistency", interrupted)
    args = ["train", "--goal", "bathtub", "--env", "sb3_disagree/ApartmentState-v0", "--mode", "scratch", "--steps",
            "200", "--n-envs", "2", "--card-episodes", "0", "--out", str(tmp_path), "--consistency-harvest", "200",
            "--bare"]
    result = runner.invoke(app, args)
    (run_dir,) = tmp_path.glob("*/bathtub/scratch-0")
    assert result.exit_code == 130 and "interrupted in the greedy-consistency phase" in result.output
    saved = yaml.safe_load((run_dir / "config.yaml").read_text())
    assert saved["finished"] and "consistency" not in saved
    (checkpoint,) = (run_dir / "checkpoints").iterdir()
    assert (checkpoint / "model.zip").read_bytes() == (run_dir / "model.zip").read_bytes()  # the trained policy
    assert calls == ["interrupted"]


def _probs(model, obs):
    with th.no_grad():
        return model.policy.get_distribution(th.as_tensor(obs)).distribution.probs.numpy()


def test_dopt_train_fits_model_zip_to_the_harvest_of_its_own_episodes(tmp_path):
    base = ["train", "--goal", "bathtub", "--env", "sb3_disagree/ApartmentState-v0", "--mode", "scratch", "--steps",
            "600", "--n-envs", "2", "--card-episodes", "0", "--out", str(tmp_path), "--bare"]  # each part as asked
    for bad in (["--consistency-harvest", "-1"], ["--consistency-validation", "5"],
                ["--consistency-harvest", "100", "--consistency-epochs", "0"]):
        result = runner.invoke(app, [*base, *bad])
        assert result.exit_code == 2 and "--consistency-" in result.output and not list(tmp_path.iterdir())
    result = runner.invoke(app, [*base, "--consistency-harvest", "900"])  # more than the budget: all of it
    assert result.exit_code == 0, result.output
    assert "greedy consistency, the training's last episodes" in result.output
    assert "done: 600 steps (model.zip fitted to the loop-free paths of the successful episodes of its last 600" \
        in result.output
    (run_dir,) = tmp_path.glob("*/bathtub/scratch-0")
    phase = yaml.safe_load((run_dir / "config.yaml").read_text())["consistency"]
    assert phase["env_steps"] == 0 and phase["per_round"][0]["labels"] == phase["harvest"]["labels"]
    (checkpoint,) = (run_dir / "checkpoints").iterdir()
    trained, refined = ACER.load(checkpoint / "model.zip"), ACER.load(run_dir / "model.zip")
    obs = np.random.default_rng(0).uniform(-1, 1, (64, 4)).astype(np.float32)
    changed = not np.allclose(_probs(trained, obs), _probs(refined, obs), atol=1e-4)
    assert changed == (phase["harvest"]["labels"] > 0)


def test_dopt_train_says_so_when_its_harvest_has_nothing_to_fit(tmp_path):
    """No episode ends within 200 steps (the cut is 500): no labels, no fit, and no nan in what the user reads."""
    result = runner.invoke(app, ["train", "--goal", "bathtub", "--env", "sb3_disagree/ApartmentState-v0", "--mode",
                                 "scratch", "--steps", "200", "--n-envs", "2", "--card-episodes", "0", "--out",
                                 str(tmp_path), "--consistency-harvest", "200", "--bare"])
    assert result.exit_code == 0, result.output
    words = " ".join(result.output.split())
    assert "0/0 episodes reached the goal, 0 labels; nothing to fit, the policy stays as trained" in words
    assert "(no episode of its last 200 training steps reached the goal: model.zip is the trained policy)" in words
    assert "nan" not in words and "fitted" not in words
    (run_dir,) = tmp_path.glob("*/bathtub/scratch-0")
    (checkpoint,) = (run_dir / "checkpoints").iterdir()
    obs = np.random.default_rng(0).uniform(-1, 1, (64, 4)).astype(np.float32)
    assert np.array_equal(_probs(ACER.load(checkpoint / "model.zip"), obs), _probs(ACER.load(run_dir / "model.zip"), obs))


def test_dopt_train_validates_the_harvest_fit_epoch_by_epoch(tmp_path):
    base = ["train", "--goal", "bathtub", "--env", "sb3_disagree/ApartmentState-v0", "--mode", "scratch", "--steps",
            "600", "--n-envs", "2", "--card-episodes", "0", "--out", str(tmp_path), "--bare"]  # each part as asked
    for bad in (["--consistency-harvest", "600", "--consistency-validation", "-1"],
                ["--consistency-validation", "4"]):  # nothing to validate without a fit
        result = runner.invoke(app, [*base, *bad])
        assert result.exit_code == 2 and "--consistency-validation" in result.output and not list(tmp_path.iterdir())
    result = runner.invoke(app, [*base, "--consistency-harvest", "600", "--consistency-validation", "4",
                                 "--consistency-epochs", "2"])
    assert result.exit_code == 0, result.output
    (run_dir,) = tmp_path.glob("*/bathtub/scratch-0")
    saved = yaml.safe_load((run_dir / "config.yaml").read_text())
    (fit,) = saved["consistency"]["per_round"]
    assert saved["consistency_validation"] == 4
    if saved["consistency"]["harvest"]["labels"]:
        assert len(fit["validation"]) == 2 and fit["epoch"] in (1, 2) and "kept epoch" in result.output
        assert fit["validation"][int(fit["epoch"]) - 1] == max(fit["validation"])
    else:  # no episode reached the goal: nothing was fitted, nothing validated
        assert "validation" not in fit


def test_dopt_train_fits_the_harvest_for_the_epochs_asked(tmp_path, monkeypatch):
    import importlib

    run_train = importlib.import_module("sb3_disagree.run.train")  # the module (the package exports its train())
    calls, phase = [], run_train.greedy_consistency

    def recorded(model, env, rounds, steps, epochs, **kwargs):
        calls.append(epochs)
        return phase(model, env, rounds, steps, epochs, **kwargs)

    monkeypatch.setattr(run_train, "greedy_consistency", recorded)
    result = runner.invoke(app, ["train", "--goal", "bathtub", "--env", "sb3_disagree/ApartmentState-v0", "--mode",
                                 "scratch", "--steps", "400", "--n-envs", "2", "--card-episodes", "0", "--out",
                                 str(tmp_path), "--consistency-harvest", "400", "--consistency-epochs", "2", "--bare"])
    assert result.exit_code == 0, result.output
    (run_dir,) = tmp_path.glob("*/bathtub/scratch-0")
    assert yaml.safe_load((run_dir / "config.yaml").read_text())["consistency_epochs"] == 2 and calls == [2]


class _Model:
    """What StartWhenReady reads of a model: the success buffer and the budget it may end sooner."""

    def __init__(self) -> None:
        self.ep_success_buffer, self.num_timesteps, self._total_timesteps = deque(maxlen=100), 0, 1000

    def end_at(self, timesteps: int) -> None:
        self._total_timesteps = min(self._total_timesteps, timesteps)


@pytest.mark.parametrize("successes, started", [
    ({}, 400),                    # ready on time: the planned start, the planned end
    ({400: 0.5, 560: 0.95}, 560),  # not yet at 400: training goes on until 560
    ({400: 0.0}, 704),            # never ready: at the first step at or past the latest start (700)
])
def test_the_greedy_phase_waits_until_the_run_is_ready(successes, started):
    from sb3_disagree.finish.greedy_phase import GreedyPhase
    from sb3_disagree.finish.ready import NEVER, StartWhenReady

    phase, harvest, model = GreedyPhase(object(), start=400), HarvestLabels(start=350), _Model()
    model.ep_success_buffer.extend([1.0] * 99)  # 99 episodes: not yet judged
    ready = StartWhenReady(phase, harvest, planned=400, latest=700, length=100, harvest_length=150, ready=0.9)
    ready.init_callback(model)
    starts = []
    for t in range(8, 1000, 8):
        model.num_timesteps = t
        if t in successes:
            model.ep_success_buffer.extend([1.0] * int(100 * successes[t]) + [0.0] * (100 - int(100 * successes[t])))
        if t == 392 and not successes:
            model.ep_success_buffer.append(1.0)  # the hundredth
        assert ready.on_step()
        starts.append(phase.start)
        if t == 400 and started > 400:
            assert phase.start == NEVER and harvest.start == NEVER  # neither acts while the run is not ready
    assert ready.started == started and phase.start == started and harvest.start == started + 100 - 150
    assert model._total_timesteps == started + 100  # the phase's 100 steps, then the end
    assert set(starts) <= {400, NEVER, started}


def test_dopt_train_extends_a_run_whose_greedy_phase_waits_for_it(tmp_path):
    base = ["train", "--goal", "bathtub", "--env", "sb3_disagree/ApartmentState-v0", "--mode", "scratch", "--steps",
            "480", "--n-envs", "2", "--card-episodes", "0", "--out", str(tmp_path), "--greedy-phase", "160",
            "--consistency-harvest", "160", "--consistency-validation", "0", "--ready", "1", "--extend", "1.5"]
    result = runner.invoke(app, base)
    assert result.exit_code == 0, result.output
    (run_dir,) = tmp_path.glob("*/bathtub/scratch-0")
    saved = yaml.safe_load((run_dir / "config.yaml").read_text())
    # never ready (not 100 episodes at this budget): the phase at 1.5 * 480 - 160, for 160 steps
    assert saved["greedy_start"] == 560 and saved["num_timesteps"] == 720 and saved["steps"] == 480
    assert "done: 720 steps (the greedy phase waited for 1.0 training success: it began at 560)" in " ".join(
        result.output.split())
    for bad in (["--ready", "1.5"], ["--extend", "0.5"], ["--greedy-phase", "0", "--ready", "0.9"]):
        result = runner.invoke(app, [*base, "--force", *bad])
        assert result.exit_code == 2 and ("--ready" in result.output or "--extend" in result.output), result.output


@pytest.mark.parametrize("stop", [400, 640])  # before the phase began (at 560), and in it
def test_a_resumed_run_keeps_the_start_of_its_greedy_phase(tmp_path, stop):
    from sb3_disagree.run import RunConfig, train

    config = RunConfig(goal="bathtub", env_id="sb3_disagree/ApartmentState-v0", mode="scratch", steps=480, n_envs=2,
                       greedy_phase=160, consistency_harvest=160, consistency_validation=0, ready=1.0, extend=1.5)
    run, model, finished = train(config, tmp_path, callbacks=[StopAt(stop)])
    assert not finished and model.num_timesteps < 720
    result = runner.invoke(app, ["train", "--goal", "bathtub", "--resume", str(run)])
    assert result.exit_code == 0, result.output
    saved = yaml.safe_load((run / "config.yaml").read_text())
    # Never ready (not 100 episodes): the phase at 1.5 * 480 - 160 either way, for its 160 steps.
    assert saved["finished"] and saved["greedy_start"] == 560 and saved["num_timesteps"] == 720
