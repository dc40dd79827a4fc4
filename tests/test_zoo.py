"""The prior zoo and `dopt priors`: cards, checks, atomic writes, error cases, the CLI."""

import io
import json
import zipfile
from pathlib import Path

import gymnasium as gym
import pytest
import torch as th
from stable_baselines3 import DQN, PPO
from stable_baselines3.common.env_util import make_vec_env
from typer.testing import CliRunner

import sb3_disagree.envs  # noqa: F401
from sb3_disagree import ACER
from sb3_disagree.acer.policies import compact_averages
from sb3_disagree.cli.app import app
from sb3_disagree.envs.vec import make_vec
from sb3_disagree.priors.zoo import Zoo, ZooError, identify_algorithm

STATE_ID = "sb3_disagree/ApartmentState-v0"
LABELS = ["shower", "bathtub", "toilet", "bed", "wardrobe", "nightstand"]
runner = CliRunner()


def _state_env(goal="shower"):
    return make_vec_env(STATE_ID, n_envs=1, env_kwargs=dict(goal=goal))


@pytest.fixture(scope="module")
def model_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("models")
    ACER("MlpPolicy", _state_env(), seed=0).save(d / "acer.zip")
    PPO("MlpPolicy", _state_env(), seed=0, n_steps=64).save(d / "ppo.zip")
    DQN("MlpPolicy", _state_env(), seed=0).save(d / "dqn.zip")
    return d


@pytest.fixture()
def zoo(tmp_path, model_files):
    z = Zoo(tmp_path / "zoo")
    for goal in LABELS:
        z.add(model_files / "acer.zip", goal, STATE_ID, training={"method": "test", "steps": 0, "seed": 0},
              evaluation={"success_rate": 0.5}, command="test")
    return z


def test_cards_record_how_each_prior_was_made(zoo, model_files):
    entry = zoo.get("bed", STATE_ID)
    card = json.loads((entry.path / "card.json").read_text())
    for key in ["goal", "env_id", "env_kwargs", "observation_space", "action_space", "sb3_class", "training",
                "evaluation", "sha256", "created", "command"]:
        assert key in card, key
    assert card["sb3_class"] == "sb3_disagree.acer.ACER" and card["action_space"]["n"] == 3
    assert entry.path == zoo.root / "sb3_disagree__ApartmentState-v0" / "bed"


def test_any_sb3_model_with_a_distribution_and_not_dqn(tmp_path, model_files):
    assert identify_algorithm(model_files / "ppo.zip") == "stable_baselines3.PPO"
    assert identify_algorithm(model_files / "acer.zip") == "sb3_disagree.acer.ACER"
    z = Zoo(tmp_path)
    entry = z.add(model_files / "ppo.zip", "toilet", STATE_ID)
    model = z.load(entry, _state_env())
    assert isinstance(model, PPO) and not model.policy.training
    with pytest.raises(ZooError, match="discrete action distribution"):
        z.add(model_files / "dqn.zip", "stove", STATE_ID)
    assert [e.goal for e in z.entries()] == ["toilet"]  # nothing half-written remains


def test_corrupt_entry_is_listed_and_refused(zoo):
    entry = zoo.get("toilet", STATE_ID)
    entry.model_path.write_bytes(b"not a zip at all")
    listed = {e.goal: e for e in zoo.entries()}
    assert len(listed) == len(LABELS)
    assert "sha256" in listed["toilet"].problem and listed["shower"].problem is None
    with pytest.raises(ZooError, match="cannot be used"):
        zoo.load(listed["toilet"])
    (zoo.get("bed", STATE_ID).path / "card.json").write_text("{broken")
    assert "unreadable card" in {e.goal: e for e in zoo.entries()}["bed"].problem
    assert "toilet" not in zoo.labels(STATE_ID)


def test_mismatched_spaces_are_refused(zoo):
    entry = zoo.get("shower", STATE_ID)
    rgb_space_env = gym.make("sb3_disagree/Apartment-v0", goal="shower").unwrapped  # builds no renderer until a frame
    with pytest.raises(ZooError, match="expects observations"):
        zoo.load(entry, rgb_space_env)
    assert zoo.load(entry, _state_env()) is not None


def test_replace_and_remove(zoo, model_files):
    with pytest.raises(ZooError, match="already has"):
        zoo.add(model_files / "acer.zip", "bed", STATE_ID)
    zoo.add(model_files / "ppo.zip", "bed", STATE_ID, replace=True)
    assert zoo.get("bed", STATE_ID).card.sb3_class == "stable_baselines3.PPO"
    zoo.remove("bed", STATE_ID)
    assert "bed" not in [e.goal for e in zoo.entries()]
    assert not any(p.name.startswith(".") for p in (zoo.root / "sb3_disagree__ApartmentState-v0").iterdir())


def test_cli_list_marks_the_two_chosen(zoo):
    result = runner.invoke(app, ["priors", "list", "--zoo", str(zoo.root), "--env", STATE_ID, "--goal", "bathtub"])
    assert result.exit_code == 0, result.output
    chosen = [line.split()[1] for line in result.output.splitlines() if "chosen" in line]
    assert chosen == ["shower", "toilet"]
    result = runner.invoke(app, ["priors", "list", "--zoo", str(zoo.root), "--env", STATE_ID, "--goal", "nightstand"])
    assert [line.split()[1] for line in result.output.splitlines() if "chosen" in line] == ["bed", "wardrobe"]


def test_cli_errors_are_messages_with_exit_code_2(zoo, model_files, tmp_path):
    args = ["--zoo", str(zoo.root), "--env", STATE_ID]
    result = runner.invoke(app, ["priors", "list", *args, "--goal", "xqzt"])
    assert result.exit_code == 2 and "does not know the word 'xqzt'" in result.output
    result = runner.invoke(app, ["priors", "show", "sofa", *args])
    assert result.exit_code == 2 and "no prior for 'sofa'" in result.output
    result = runner.invoke(app, ["priors", "add", str(model_files / "dqn.zip"), "--goal", "stove", *args])
    assert result.exit_code == 2 and "discrete action distribution" in result.output
    result = runner.invoke(app, ["priors", "add", str(tmp_path / "nope.zip"), "--goal", "stove", *args])
    assert result.exit_code == 2 and "does not exist" in result.output
    assert "Traceback" not in result.output


def test_cli_add_show_eval_remove(zoo, model_files):
    args = ["--zoo", str(zoo.root), "--env", STATE_ID]
    result = runner.invoke(app, ["priors", "add", str(model_files / "ppo.zip"), "--goal", "stove", "--episodes", "4", *args])
    assert result.exit_code == 0, result.output
    card = zoo.get("stove", STATE_ID).card
    assert card.evaluation["episodes"] == 4 and 0.0 <= card.evaluation["success_rate"] <= 1.0
    result = runner.invoke(app, ["priors", "show", "stove", *args])
    assert result.exit_code == 0 and "stable_baselines3.PPO" in result.output
    result = runner.invoke(app, ["priors", "eval", "stove", "--episodes", "2", *args])
    assert result.exit_code == 0 and "over 2 episodes" in result.output
    result = runner.invoke(app, ["priors", "remove", "stove", *args])
    assert result.exit_code == 0 and "stove" not in [e.goal for e in zoo.entries()]


def test_an_added_prior_with_memory_shows_it_on_its_card_and_in_the_list(zoo, tmp_path):
    # A model from outside has no training record; its memory is read off its policy for the card and the list.
    path = tmp_path / "stacked.zip"
    ACER("MlpPolicy", _state_env(), seed=0, policy_kwargs=dict(frame_stack=2)).save(path)
    args = ["--zoo", str(zoo.root), "--env", STATE_ID]
    result = runner.invoke(app, ["priors", "add", str(path), "--goal", "toaster", "--episodes", "0", "--replace", *args])
    assert result.exit_code == 0, result.output
    assert zoo.get("toaster", STATE_ID).card.training == {"frame_stack": 2, "loop_flags": False, "method": "external"}
    assert zoo.get("bed", STATE_ID).card.training == {"method": "test", "steps": 0, "seed": 0}  # single frame: nothing added
    rows = [line for line in runner.invoke(app, ["priors", "list", *args]).output.splitlines() if "toaster" in line]
    assert rows and rows[0].split("│")[5].strip() == "2"


def test_cli_eval_record_rewrites_only_the_evaluation(zoo):
    args = ["--zoo", str(zoo.root), "--env", STATE_ID]
    before = zoo.get("bed", STATE_ID)
    result = runner.invoke(app, ["priors", "eval", "bed", "--episodes", "3", "--seed", "123", "--record", *args])
    assert result.exit_code == 0, result.output
    after = zoo.get("bed", STATE_ID)
    assert after.problem is None and after.card.sha256 == before.card.sha256
    assert after.card.evaluation["episodes"] == 3 and after.card.evaluation["seed"] == 123
    assert after.card.training == before.card.training and after.card.command == before.card.command
    assert [p.name for p in after.path.iterdir() if p.name.startswith(".")] == []  # no temporary file left
    # Both ways by default: greedy and sampled each on the card, side by side in the output.
    assert after.card.evaluation_greedy["episodes"] == 3 and after.card.evaluation_greedy["deterministic"]
    assert not after.card.evaluation["deterministic"]
    words = " ".join(result.output.split())
    assert "(greedy actions)" in words and "(sampled actions)" in words
    assert "evaluating bed: 3/3 |" in words  # not a terminal: a plain progress line, not a live bar
    result = runner.invoke(app, ["priors", "eval", "bed", "--episodes", "4", "--record", "--deterministic", *args])
    assert result.exit_code == 0, result.output
    card = zoo.get("bed", STATE_ID).card
    assert card.evaluation_greedy["episodes"] == 4 and card.evaluation["episodes"] == 3  # only the greedy one changed


def test_cli_train_dagger_tiny(tmp_path):
    result = runner.invoke(app, ["priors", "train", "--goal", "toilet", "--method", "dagger", "--env", STATE_ID,
                                 "--zoo", str(tmp_path), "--rounds", "2", "--steps-per-round", "200", "--epochs", "1",
                                 "--episodes", "4", "--validation-episodes", "3", "--frame-stack", "2"])
    assert result.exit_code == 0, result.output
    card = Zoo(tmp_path).get("toilet", STATE_ID).card
    assert card.training["method"] == "dagger" and card.training["steps"] == 400 and card.training["frame_stack"] == 2
    listed = runner.invoke(app, ["priors", "list", "--zoo", str(tmp_path)], env={"COLUMNS": "200"}).output
    row = next(line for line in listed.splitlines() if "toilet" in line)
    assert [c.strip() for c in row.split("│")][2:7] == ["ACER", "dagger", "400", "2", f"{card.evaluation_greedy['success_rate']:.2f}"]
    assert card.command.startswith("dopt ") and card.evaluation["episodes"] == 4
    # The kept policy is the last round with the best validation success.
    validation = card.training["validation_success"]
    assert len(validation) == 2 and card.training["validation_episodes"] == 3
    best = max(validation)
    assert card.training["selected_round"] == max(i + 1 for i, v in enumerate(validation) if v == best)
    assert f"kept round {card.training['selected_round']}" in result.output


@pytest.mark.parametrize("no_return", [False, True])
def test_dagger_labels_with_the_expert_asked_for(monkeypatch, no_return):
    """--expert-no-return makes every DAgger label the expert's that does not return (the env's
    ``expert_action(no_return=True)``), and the card says so; by default the memoryless expert labels, as before."""
    from sb3_disagree.envs.navigation import NavigationEnv
    from sb3_disagree.priors.make import train_dagger

    asked, expert_action = [], NavigationEnv.expert_action

    def spy(self, **kwargs):
        asked.append(kwargs.get("no_return", False))
        return expert_action(self, **kwargs)

    monkeypatch.setattr(NavigationEnv, "expert_action", spy)
    _, record = train_dagger(make_vec(STATE_ID, "toilet", n_envs=2), rounds=2, steps_per_round=40, epochs=1,
                             expert_no_return=no_return)
    assert len(asked) == 80 and set(asked) == {no_return}
    assert record.get("expert_no_return", False) == no_return


@pytest.mark.parametrize("method", ["acer", "ppo"])
def test_training_a_prior_by_rl_leaves_nothing_in_the_temp_dir(monkeypatch, tmp_path, method):
    """SB3's default logger makes a folder in the temp dir for every learn(); a prior's training writes nowhere."""
    import tempfile

    from sb3_disagree.priors.make import train_rl

    temp = tmp_path / "tmp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    monkeypatch.delenv("SB3_LOGDIR", raising=False)
    model, record = train_rl(make_vec(STATE_ID, "toilet", n_envs=2), method, steps=64)
    assert model.num_timesteps >= 64 and record["method"] == method
    assert list(temp.iterdir()) == []


def test_similarity_command_and_heatmap(tmp_path):
    out = tmp_path / "sim.png"
    result = runner.invoke(app, ["similarity", "shower", "bathtub", "toilet", "--plot", str(out)])
    assert result.exit_code == 0 and "0.57" in result.output and out.stat().st_size > 1000


def test_dagger_keeps_the_best_validated_round(monkeypatch):
    """With validation, the returned policy is the best round's, not the last one's."""
    import numpy as np
    import torch as th

    from sb3_disagree.priors import make as prior_training

    scores = iter([0.2, 0.9, 0.4])  # round 2 is the best
    snapshots = []

    def fake_evaluate(model, env, episodes, deterministic=False, progress=None):
        snapshots.append({k: v.clone() for k, v in model.policy.net.state_dict().items()})
        return prior_training.Evaluation(next(scores), 1.0, 0.0, episodes, deterministic)

    monkeypatch.setattr(prior_training, "evaluate", fake_evaluate)
    model, record = prior_training.train_dagger(_state_env("toilet"), seed=0, rounds=3, steps_per_round=40, epochs=1,
                                                validation_env=_state_env("toilet"), validation_episodes=2)
    assert record["selected_round"] == 2 and record["validation_success"] == [0.2, 0.9, 0.4]
    kept = model.policy.net.state_dict()
    assert all(th.equal(kept[k], snapshots[1][k]) for k in kept)
    assert not all(th.equal(kept[k], snapshots[2][k]) for k in kept)  # the last round's policy differs
    assert all(th.equal(v, model.policy.average_net.state_dict()[k]) for k, v in kept.items())
    assert np.isfinite(record["final_loss"])


def test_dagger_with_memory_fits_the_stacks_the_learner_saw(monkeypatch):
    """With ``frame_stack`` k, every label is fitted on the last k observations (zeros before an episode's start)."""
    import numpy as np

    from sb3_disagree.priors import make as prior_training

    fitted = {}
    real_fit = prior_training._fit

    def spy_fit(policy, optimizer, x, y, *args):
        fitted["x"], fitted["y"] = x[np.arange(len(y))], y.copy()  # the stacks, rebuilt from linked frames
        return real_fit(policy, optimizer, x, y, *args)

    monkeypatch.setattr(prior_training, "_fit", spy_fit)
    env = _state_env("toilet")
    model, record = prior_training.train_dagger(env, seed=0, rounds=2, steps_per_round=40, epochs=1, frame_stack=3)
    d = env.observation_space.shape[0]
    x = fitted["x"]
    assert x.shape == (80, 3 * d) and record["frame_stack"] == 3 and model.policy.frame_stack == 3
    n = env.num_envs
    assert np.all(x[:n, : 2 * d] == 0) and np.any(x[:n, 2 * d :] != 0)  # the first stacks: only the reset frame
    # Within an episode each stack is the previous one shifted by a frame (the second step of every env).
    assert np.array_equal(x[n : 2 * n, d : 2 * d], x[:n, 2 * d :]) and np.all(x[n : 2 * n, :d] == 0)
    # The saved policy carries its stack through predict's state, as SB3's evaluate_policy passes it.
    obs = env.reset()
    actions, state = model.predict(obs, state=None, episode_start=np.ones(n, dtype=bool), deterministic=True)
    assert actions.shape == (n,) and state[0].shape == (n, 3 * d)


def test_cli_train_dagger_with_loop_flags(tmp_path):
    """An RGB prior with loop flags: its CNN sees the newest frame and two flags, its card and list say so, and it
    acts in the method's loop with its own stack."""
    import numpy as np
    import torch as th

    from sb3_disagree.acer.torch_layers import LoopFlagsCNN
    from sb3_disagree.options.priors import PriorSet

    base = ["priors", "train", "--goal", "toilet", "--zoo", str(tmp_path), "--rounds", "2", "--steps-per-round", "40",
            "--epochs", "1", "--episodes", "2"]
    for bad in (["--loop-flags"], ["--loop-flags", "--frame-stack", "3", "--env", STATE_ID]):
        result = runner.invoke(app, [*base, *bad])
        assert result.exit_code == 2 and "loop flags" in result.output and not list(tmp_path.iterdir())
    result = runner.invoke(app, [*base, "--frame-stack", "3", "--loop-flags"])
    assert result.exit_code == 0, result.output
    entry = Zoo(tmp_path).get("toilet", "sb3_disagree/Apartment-v0")
    assert entry.card.training["loop_flags"] and entry.card.training["frame_stack"] == 3
    listed = runner.invoke(app, ["priors", "list", "--zoo", str(tmp_path)], env={"COLUMNS": "200"}).output
    row = next(line for line in listed.splitlines() if "toilet" in line)
    assert [c.strip() for c in row.split("│")][5] == "3+flags"
    prior = Zoo(tmp_path).load(entry, device="cpu")
    extractor = prior.policy.net.features_extractor
    assert isinstance(extractor, LoopFlagsCNN) and extractor.features_dim == 128 + 2 and prior.policy.frame_stack == 3
    priors = PriorSet([prior, prior])
    obs = np.random.default_rng(0).integers(0, 256, (2, 60, 80, 3), dtype=np.uint8)
    priors.probs(obs)
    probs = priors.probs(obs, episode_starts=np.zeros(2, dtype=bool))  # the same frame again: pressed to a wall
    frame = prior.policy.obs_to_tensor(obs)[0].numpy()  # channels first
    stack = th.as_tensor(np.concatenate([np.zeros_like(frame), frame, frame], axis=1))
    with th.no_grad():
        expected = prior.policy.get_distribution(stack).distribution.probs
        assert th.equal(extractor.flags(stack), th.tensor([[1.0, 0.0]] * 2))
    assert probs.shape == (2, 2, 3) and th.allclose(probs[0], expected) and th.allclose(probs[1], expected)
    # --flags-cnn stack: the CNN reads all three frames, the flags on top; refused without --loop-flags.
    for bad in (["--frame-stack", "3", "--flags-cnn", "stack"], ["--frame-stack", "3", "--loop-flags", "--flags-cnn", "x"]):
        result = runner.invoke(app, [*base, "--goal", "bed", *bad])
        assert result.exit_code == 2 and "--flags-cnn must be one of" in result.output, result.output
    assert "bed" not in [e.goal for e in Zoo(tmp_path).entries()]
    result = runner.invoke(app, [*base, "--goal", "bed", "--frame-stack", "3", "--loop-flags", "--flags-cnn", "stack"])
    assert result.exit_code == 0, result.output
    entry = Zoo(tmp_path).get("bed", "sb3_disagree/Apartment-v0")
    assert entry.card.training["flags_cnn"] == "stack"
    listed = runner.invoke(app, ["priors", "list", "--zoo", str(tmp_path)], env={"COLUMNS": "200"}).output
    row = next(line for line in listed.splitlines() if "bed" in line)
    assert [c.strip() for c in row.split("│")][5] == "3 all+flags"
    extractor = Zoo(tmp_path).load(entry, device="cpu").policy.net.features_extractor
    assert extractor.cnn.cnn[0].in_channels == 9 and extractor.features_dim == 128 + 2


def test_cli_train_prior_with_consistency_phase(tmp_path):
    """--consistency-rounds refines the trained prior by the greedy-consistency phase on env seeds of its own and
    records the phase on the card; bad settings are refused before anything is written."""
    base = ["priors", "train", "--goal", "toilet", "--env", STATE_ID, "--zoo", str(tmp_path), "--rounds", "2",
            "--steps-per-round", "200", "--epochs", "1", "--episodes", "2"]
    for bad, words in ((["--consistency-rounds", "-1"], "--consistency-rounds"),
                       (["--consistency-rounds", "1", "--consistency-steps", "3"], "--consistency-steps"),
                       (["--consistency-rounds", "1", "--consistency-loop-uniform", "1.5"], "[0, 1]"),
                       (["--consistency-rounds", "1", "--method", "ppo"], "not PPO")):
        result = runner.invoke(app, [*base, *bad])
        assert result.exit_code == 2 and words in result.output and not list(tmp_path.iterdir()), result.output
    result = runner.invoke(app, [*base, "--consistency-rounds", "2", "--consistency-steps", "800"])
    assert result.exit_code == 0, result.output
    phase = Zoo(tmp_path).get("toilet", STATE_ID).card.training["consistency"]
    assert phase["rounds"] == 2 and phase["steps_per_round"] == 800 and len(phase["per_round"]) == 2
    assert phase["loop_uniform"] == 0.5  # the default: a prior is sharp
    assert [r["env_steps"] for r in phase["per_round"]] == [800, 800]
    assert all(r["successes"] <= r["episodes"] for r in phase["per_round"])
    assert " ".join(result.output.split()).count("consistency round:") == 2


def test_a_validated_phase_ends_on_its_best_round(tmp_path):
    """A phase with validation episodes validates every epoch greedily from DAgger's validation starts; each round
    keeps its best epoch and the phase its best round (ties: the later), whose weights the prior ends with (validated
    again, it scores what was recorded); a negative count is refused by both commands before anything is written."""
    from sb3_disagree.defaults import PRIOR_VALIDATION_SEED
    from sb3_disagree.evaluation import evaluate
    from sb3_disagree.priors.make import refine_prior

    for bad in (["train", "--goal", "toilet", "--consistency-rounds", "1", "--consistency-validation-episodes", "-1"],
                ["refine", "--goal", "toilet", "--rounds", "1", "--validation-episodes", "-1"]):
        result = runner.invoke(app, ["priors", *bad, "--env", STATE_ID, "--zoo", str(tmp_path)])
        assert result.exit_code == 2 and "validation-episodes >= 0" in result.output, result.output
    assert not list(tmp_path.iterdir())
    greedy = Zoo("greedy")
    model = greedy.load(greedy.get("toilet", STATE_ID), device="cpu")
    lines: list[str] = []
    phase = refine_prior(model, STATE_ID, "toilet", rounds=3, steps=800, seed=1, progress=lines.append,
                         validation_episodes=8)
    kept = [r["validation"][int(r["epoch"]) - 1] for r in phase["per_round"]]
    assert [len(r["validation"]) for r in phase["per_round"]] == [3, 3, 3]  # three epochs a round
    assert all(k == max(r["validation"]) for k, r in zip(kept, phase["per_round"]))
    assert phase["selected_round"] == max(i + 1 for i, k in enumerate(kept) if k == max(kept))
    assert phase["validation_episodes"] == 8 and phase["validation_seed"] == PRIOR_VALIDATION_SEED
    assert lines[-1].startswith(f"kept consistency round {phase['selected_round']}")
    env = make_vec(STATE_ID, "toilet", n_envs=4, seed=PRIOR_VALIDATION_SEED)
    assert evaluate(model, env, 8, deterministic=True).success_rate == max(kept)


def test_a_validated_phase_keeps_the_best_epoch_and_then_the_best_round(monkeypatch):
    """With scripted validation scores, the phase keeps each round's best epoch (ties: the shorter episodes, then the
    earlier epoch) and ends on the weights of its best round (ties: the later), not on its last round's."""
    import types

    import sb3_disagree.priors.make as make

    scores = iter([0.5, 0.75, 0.25,  # round 1 keeps epoch 2
                   0.25, 0.5, 0.5,  # round 2: epoch 2 (a tie, the same lengths)
                   0.75, 0.25, 0.75,  # round 3: epoch 1, tied with round 1: round 3 is kept
                   0.5, 0.25, 0.5])  # round 4: below, so the phase ends on round 3's weights
    monkeypatch.setattr(make, "evaluate", lambda *args, **kwargs: types.SimpleNamespace(success_rate=next(scores),
                                                                                         mean_length=100.0))
    greedy = Zoo("greedy")
    model = greedy.load(greedy.get("toilet", STATE_ID), device="cpu")
    net, after = model.policy.acting_net, []
    phase = make.refine_prior(model, STATE_ID, "toilet", rounds=4, steps=400, seed=1, validation_episodes=8,
                              progress=lambda line: after.append({k: v.clone() for k, v in net.state_dict().items()}))
    assert [r["epoch"] for r in phase["per_round"]] == [2, 2, 1, 1] and phase["selected_round"] == 3
    final = net.state_dict()
    assert all(th.equal(final[k], after[2][k]) for k in final)
    assert not all(th.equal(final[k], after[3][k]) for k in final)


def test_refine_is_the_second_half_of_training_with_the_phase(tmp_path):
    """DAgger into the zoo, then refine_entry with the same seed, gives the very prior (weights and the phase's
    record) that make_prior with --consistency-rounds gives in one go."""
    from sb3_disagree.priors.make import make_prior, refine_entry

    dagger = dict(rounds=2, steps_per_round=200, epochs=1)
    one, two = Zoo(tmp_path / "one"), Zoo(tmp_path / "two")
    make_prior(one, "toilet", STATE_ID, seed=3, episodes=0, consistency_rounds=2, consistency_steps=800, **dagger)
    make_prior(two, "toilet", STATE_ID, seed=3, episodes=0, **dagger)
    refine_entry(two, "toilet", STATE_ID, rounds=2, steps=800, seed=3, episodes=0)
    a, b = (z.load(z.get("toilet", STATE_ID), device="cpu").policy.state_dict() for z in (one, two))
    assert a.keys() == b.keys() and all(th.equal(a[k], b[k]) for k in a)
    phases = [z.get("toilet", STATE_ID).card.training["consistency"] for z in (one, two)]
    assert phases[0]["per_round"] == phases[1]["per_round"] and len(phases[0]["per_round"]) == 2


def test_cli_refine_replaces_the_prior_and_keeps_its_history(tmp_path):
    """dopt priors refine runs the phase on a zoo's prior in place: the card keeps the training, adds the phase and
    the command, and records new evaluations; a second refinement is kept apart; bad input changes nothing."""
    made = runner.invoke(app, ["priors", "train", "--goal", "toilet", "--env", STATE_ID, "--zoo", str(tmp_path),
                               "--rounds", "1", "--steps-per-round", "200", "--epochs", "1", "--episodes", "0"])
    assert made.exit_code == 0, made.output
    before = Zoo(tmp_path).get("toilet", STATE_ID).card
    base = ["priors", "refine", "--env", STATE_ID, "--zoo", str(tmp_path), "--steps", "400", "--episodes", "2"]
    for bad, words in ((["--goal", "toilet", "--rounds", "0"], "--rounds must be >= 1"),
                       (["--goal", "toilet", "--rounds", "1", "--loop-uniform", "2"], "[0, 1]"),
                       (["--goal", "bathtub", "--rounds", "1"], "no prior for 'bathtub'")):
        result = runner.invoke(app, [*base, *bad])
        assert result.exit_code == 2 and words in " ".join(result.output.split()), result.output
        assert Zoo(tmp_path).get("toilet", STATE_ID).card == before
    result = runner.invoke(app, [*base, "--goal", "toilet", "--rounds", "2", "--seed", "1"])
    assert result.exit_code == 0, result.output
    card = Zoo(tmp_path).get("toilet", STATE_ID).card
    assert card.sha256 != before.sha256 and card.training["rounds"] == before.training["rounds"] == 1
    assert card.training["consistency"]["rounds"] == 2 and len(card.training["consistency"]["per_round"]) == 2
    assert card.command == f"{before.command}; then {before.command}"  # both the test runner's argv here
    assert card.evaluation["episodes"] == card.evaluation_greedy["episodes"] == 2
    assert card.training["consistency"]["before"] == {}  # the DAgger prior had no evaluation on its card
    again = runner.invoke(app, [*base, "--goal", "toilet", "--rounds", "1", "--episodes", "0", "--expert-in-loops"])
    assert again.exit_code == 0 and "from the expert" in again.output, again.output
    card = Zoo(tmp_path).get("toilet", STATE_ID).card
    assert [p["rounds"] for p in card.training["consistency_more"]] == [1] and not card.evaluation
    assert card.training["consistency_more"][0]["expert_in_loops"] and "expert_in_loops" not in card.training[
        "consistency"]
    assert card.training["consistency_more"][0]["before"]["greedy"]["episodes"] == 2  # what the second phase replaced


def test_cli_refine_only_if_better_keeps_a_prior_the_phase_would_not_improve(tmp_path):
    """--only-if-better replaces the prior only if the refined one's lower success (greedy or sampled, the card's env
    seeds and episodes) beats the card's; it needs such a pair on the card, and refuses before training otherwise."""
    from sb3_disagree.defaults import PRIOR_CARD_SEED
    from sb3_disagree.priors.make import evaluate_entry

    made = runner.invoke(app, ["priors", "train", "--goal", "toilet", "--env", STATE_ID, "--zoo", str(tmp_path),
                               "--rounds", "1", "--steps-per-round", "200", "--epochs", "1", "--episodes", "4"])
    assert made.exit_code == 0, made.output
    zoo = Zoo(tmp_path)
    base = ["priors", "refine", "--goal", "toilet", "--env", STATE_ID, "--zoo", str(tmp_path), "--rounds", "1",
            "--steps", "400", "--only-if-better"]
    before = zoo.get("toilet", STATE_ID).card
    result = runner.invoke(app, [*base, "--episodes", "3"])  # the card's evaluations are over 4 episodes
    assert result.exit_code == 2 and "no such pair" in " ".join(result.output.split()), result.output
    assert zoo.get("toilet", STATE_ID).card == before

    def card_says(rate: float) -> None:  # the card's evaluations, both ways, as if the prior were this good
        entry = zoo.get("toilet", STATE_ID)
        for greedy in (True, False):
            entry = zoo.record_evaluation(entry, dict(success_rate=rate, episodes=4, mean_length=1.0, mean_return=0.0,
                                                      deterministic=greedy, seed=PRIOR_CARD_SEED))

    card_says(1.0)  # nothing beats it: the zoo is left as it was
    before = zoo.get("toilet", STATE_ID).card
    result = runner.invoke(app, [*base, "--episodes", "4"])
    assert result.exit_code == 0 and "kept the prior" in result.output, result.output
    assert zoo.get("toilet", STATE_ID).card == before
    card_says(-1.0)  # anything beats it: replaced, with the refined prior's own evaluations
    result = runner.invoke(app, [*base, "--episodes", "4"])
    assert result.exit_code == 0 and "kept the prior" not in result.output, result.output
    card = zoo.get("toilet", STATE_ID).card
    assert card.sha256 != before.sha256 and card.training["consistency"]["before"]["greedy"]["success_rate"] == -1.0
    assert card.evaluation["episodes"] == card.evaluation_greedy["episodes"] == 4
    assert card.evaluation_greedy["seed"] == PRIOR_CARD_SEED
    again = evaluate_entry(zoo, zoo.get("toilet", STATE_ID), 4, True, PRIOR_CARD_SEED)  # the saved weights, reloaded
    assert again.success_rate == card.evaluation_greedy["success_rate"]
    assert again.mean_length == card.evaluation_greedy["mean_length"]


def test_a_shipped_zoo_by_name_unless_a_folder_has_that_name(tmp_path, monkeypatch):
    """--zoo greedy names the zoo shipped beside the default one; a folder called greedy where the name is read wins;
    the shipped zoos need no trust list."""
    from sb3_disagree.priors import zoo as zoo_module

    shipped = tmp_path / "shipped"
    monkeypatch.setitem(zoo_module.SHIPPED_ZOOS, "greedy", shipped)
    monkeypatch.chdir(tmp_path)
    assert Zoo().root == zoo_module.DEFAULT_ZOO and Zoo("greedy").root == shipped
    assert Zoo("other").root == Path("other")
    trust = tmp_path / "trusted.txt"
    trust.write_text("0" * 64 + "\n")
    model = ACER("MlpPolicy", make_vec_env(STATE_ID, n_envs=1, env_kwargs=dict(goal="bed")), seed=0)
    model.save(tmp_path / "bed.zip")
    with pytest.raises(ZooError, match="read-only"):  # the shipped zoos are the package's own
        Zoo(shipped).add(tmp_path / "bed.zip", "bed", STATE_ID, training={"method": "test"})
    Zoo(shipped, write_shipped=True).add(tmp_path / "bed.zip", "bed", STATE_ID, training={"method": "test"})
    assert Zoo("greedy", trusted=trust).get("bed", STATE_ID).problem is None
    listed = runner.invoke(app, ["priors", "list", "--zoo", "greedy", "--env", STATE_ID])
    assert listed.exit_code == 0 and "bed" in listed.output, listed.output
    (tmp_path / "greedy").mkdir()
    assert Zoo("greedy").root == Path("greedy") and Zoo("greedy").entries() == []


def test_the_shipped_greedy_zoo_meets_its_bar():
    """Every prior of the shipped greedy zoo is usable and its card records it alone over at least 300 episodes each
    way with success >= 0.95 greedy and sampled, made by DAgger and the greedy-consistency phase, with loop flags where
    it sees frames; it has the ten goals of the apartment, by frames and by pose, and the office's three, as the default
    zoo has them."""
    from sb3_disagree.envs import OFFICE_ID
    from sb3_disagree.envs.layout import default_layout

    zoo, office = Zoo("greedy"), sorted(e.goal for e in Zoo().entries(OFFICE_ID))
    assert office == ["desk", "fridge", "sofa"]
    for env_id, goals in (("sb3_disagree/Apartment-v0", sorted(default_layout().object_names)),
                          (STATE_ID, sorted(default_layout().object_names)), (OFFICE_ID, office)):
        entries = zoo.entries(env_id)
        assert sorted(e.goal for e in entries) == goals, env_id
        for e in entries:
            assert e.problem is None, (e.goal, e.problem)
            for ev in (e.card.evaluation, e.card.evaluation_greedy):
                assert ev["episodes"] >= 300 and round(ev["success_rate"] * ev["episodes"]) >= 0.95 * ev["episodes"], e
            assert e.card.evaluation_greedy["deterministic"] and not e.card.evaluation["deterministic"]
            assert e.card.training["method"] == "dagger" and e.card.training["consistency"]["rounds"] >= 10
            assert e.card.training.get("loop_flags") or env_id == STATE_ID  # the pose does not alias


@pytest.mark.parametrize("name", [None, "greedy"])
def test_shipped_priors_store_their_network_once(name):
    """A shipped prior's file holds ``net`` alone (its averages equal it, and ``ACER.save`` leaves such copies out);
    loaded, its average network is ``net`` again, entry for entry."""
    entries = Zoo(name).entries()
    assert entries
    for e in entries:
        with zipfile.ZipFile(e.model_path) as archive:
            stored = th.load(io.BytesIO(archive.read("policy.pth")), weights_only=True)
        assert not any(k.startswith("average_net.") for k in stored), e.model_path
        assert compact_averages(stored).keys() == stored.keys()
    policy = Zoo(name).load(entries[0], device="cpu").policy
    assert all(th.equal(v, policy.net.state_dict()[k]) for k, v in policy.average_net.state_dict().items())
