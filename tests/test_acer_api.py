"""ACER in the SB3 API: save/load, replay buffer I/O, images, callbacks, logging, learning."""

import copy
import io
import threading
import time
import zipfile

import numpy as np
import pytest
import torch as th
from envs import ChainEnv, ImageEnv
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import VecTransposeImage

from sb3_disagree import ACER

HYPER = dict(n_steps=7, gamma=0.95, buffer_size=700, replay_ratio=2.5, replay_start=14, q_coef=0.3, ent_coef=0.02,
             max_grad_norm=3.0, c=5.0, trust_region=False, alpha=0.95, delta=0.5)


def test_save_load_gives_same_actions_and_hyperparameters(tmp_path):
    env = make_vec_env(ChainEnv, n_envs=2, seed=0)
    model = ACER("MlpPolicy", env, seed=0, policy_kwargs=dict(net_arch=[16]), **HYPER)
    model.learn(300)
    model.save(tmp_path / "model.zip")
    loaded = ACER.load(tmp_path / "model.zip")
    for key, value in HYPER.items():
        assert getattr(loaded, key) == value, key
    assert loaded.policy.net_arch == [16] and loaded.num_timesteps == model.num_timesteps
    obs = np.eye(5, dtype=np.float32)
    assert np.array_equal(model.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0])
    with th.no_grad():
        obs_t = th.as_tensor(obs)
        assert th.allclose(model.policy.action_probs(obs_t), loaded.policy.action_probs(obs_t))
        assert th.allclose(model.policy.average_logits(obs_t), loaded.policy.average_logits(obs_t))
    assert not th.allclose(loaded.policy.average_logits(obs_t), loaded.policy.net.logits(obs_t))
    params = loaded.get_parameters()
    assert {"policy", "policy.optimizer"} <= set(params)
    assert any(k.startswith("average_net.") for k in params["policy"])


def test_ema_is_the_policy_predict_acts_with_and_round_trips(tmp_path):
    env = make_vec_env(ChainEnv, n_envs=2, seed=0)
    model = ACER("MlpPolicy", env, seed=0, policy_kwargs=dict(net_arch=[16]), ema_decay=0.9,
                 **{**HYPER, "replay_start": 10_000})
    policy = model.policy
    before = [p.clone() for p in policy.ema_net.parameters()]
    model.learn(14)  # one segment of 7 steps in 2 envs, no replay yet: a single on-policy update
    net, ema = list(policy.net.parameters()), list(policy.ema_net.parameters())
    assert model._n_updates == 1
    for b, n, e in zip(before, net, ema):  # theta_ema = 0.9 * theta_ema + 0.1 * theta after the one update
        assert th.allclose(e, 0.9 * b + 0.1 * n.detach(), atol=1e-6)
    model.learn(300, reset_num_timesteps=False)
    obs = th.eye(5)
    with th.no_grad():
        ema_probs = th.softmax(policy.ema_net.logits(obs), -1)
        assert th.allclose(policy.get_distribution(obs).distribution.probs, ema_probs)
        assert not th.allclose(policy.action_probs(obs), ema_probs)  # the rollouts act with the current weights
    greedy = model.predict(obs.numpy(), deterministic=True)[0]
    assert np.array_equal(greedy, ema_probs.argmax(-1).numpy())
    model.save(tmp_path / "model.zip")
    loaded = ACER.load(tmp_path / "model.zip")
    assert loaded.ema_decay == 0.9 and loaded.policy.ema
    with th.no_grad():
        assert th.allclose(loaded.policy.get_distribution(obs).distribution.probs, ema_probs)
    assert ACER("MlpPolicy", env, **HYPER).policy.ema_net is None  # none kept by default
    with pytest.raises(ValueError, match="ema_decay"):
        ACER("MlpPolicy", env, ema_decay=1.0)


def _saved_policy(path) -> dict:
    with zipfile.ZipFile(path) as archive:
        return th.load(io.BytesIO(archive.read("policy.pth")), weights_only=True)


def test_save_stores_average_copies_of_net_once_and_load_restores_them(tmp_path):
    env = make_vec_env(ChainEnv, n_envs=2, seed=0)
    model = ACER("MlpPolicy", env, seed=0, ema_decay=0.9, policy_kwargs=dict(net_arch=[16]),
                 **{**HYPER, "replay_start": 10_000})
    full = {k: v.clone() for k, v in model.policy.state_dict().items()}
    model.save(tmp_path / "fresh.zip")  # both averages start at net: neither is stored
    stored = _saved_policy(tmp_path / "fresh.zip")
    assert sorted(stored) == sorted(k for k in full if k.startswith("net."))
    loaded = ACER.load(tmp_path / "fresh.zip").policy
    assert list(loaded.state_dict()) == list(full) and all(th.equal(full[k], v) for k, v in loaded.state_dict().items())
    assert all(a.data_ptr() != n.data_ptr() for a, n in zip(loaded.average_net.parameters(), loaded.net.parameters()))
    model.policy.average_net.q_net.bias.data += 1.0  # one average entry apart from net: only it is stored
    model.save(tmp_path / "one.zip")
    assert set(_saved_policy(tmp_path / "one.zip")) - set(stored) == {"average_net.q_net.bias"}
    assert th.equal(ACER.load(tmp_path / "one.zip").policy.average_net.q_net.bias, model.policy.average_net.q_net.bias)
    model.learn(14)  # an update moves net and both averages apart
    model.save(tmp_path / "trained.zip")
    assert set(_saved_policy(tmp_path / "trained.zip")) == set(full)
    assert all(th.equal(model.policy.state_dict()[k], v)
               for k, v in ACER.load(tmp_path / "trained.zip").policy.state_dict().items())


def test_replay_buffer_round_trip_and_continued_learning(tmp_path):
    env = make_vec_env(ChainEnv, n_envs=2, seed=0)
    model = ACER("MlpPolicy", env, n_steps=5, seed=0)
    model.learn(100)
    model.save_replay_buffer(tmp_path / "buffer.pkl")
    model.save(tmp_path / "model.zip")
    loaded = ACER.load(tmp_path / "model.zip", env=env)
    loaded.load_replay_buffer(tmp_path / "buffer.pkl")
    assert loaded.replay_buffer.n_stored == model.replay_buffer.n_stored == 10
    assert np.array_equal(loaded.replay_buffer.mu, model.replay_buffer.mu)
    loaded.learn(50, reset_num_timesteps=False)
    assert loaded.num_timesteps == 150 and loaded.replay_buffer.n_stored == 15


def test_load_replay_buffer_rejects_a_mismatched_buffer(tmp_path):
    a = ACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=2), n_steps=5)
    a.learn(20)
    a.save_replay_buffer(tmp_path / "buffer.pkl")
    b = ACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=3), n_steps=5)
    with pytest.raises(ValueError, match="n_envs"):
        b.load_replay_buffer(tmp_path / "buffer.pkl")


def test_cnn_policy_wraps_images_and_learns_the_colour_task():
    env = make_vec_env(ImageEnv, n_envs=4, seed=0)
    model = ACER("CnnPolicy", env, n_steps=5, seed=0, replay_start=100, learning_rate=1e-3)
    assert isinstance(model.get_env(), VecTransposeImage)
    assert model.policy.net.features_extractor.__class__.__name__ == "NatureCNN"
    model.learn(6_000)
    mean, _ = evaluate_policy(model, make_vec_env(ImageEnv, n_envs=1, seed=1), n_eval_episodes=30)
    assert mean >= 0.9


def test_set_env_predict_and_callbacks_and_logger(tmp_path):
    model = ACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=2, seed=0), n_steps=5, seed=0)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    events = []

    class Record(BaseCallback):
        def _on_rollout_start(self):
            events.append("start")

        def _on_step(self):
            events.append("step")
            return self.num_timesteps < 40  # stops training after 20 vectorised steps

    model.learn(1_000, callback=Record(), log_interval=1)
    assert events.count("start") == 4 and events.count("step") == 20 and model.num_timesteps == 40
    model.set_env(make_vec_env(ChainEnv, n_envs=2, seed=1))
    model.learn(20, log_interval=1)
    header = (tmp_path / "progress.csv").read_text().splitlines()[0].split(",")
    for key in ["train/policy_loss", "train/value_loss", "train/entropy_loss", "train/bias_correction_loss",
                "rollout/ep_rew_mean", "time/fps", "train/trust_region_active_fraction"]:
        assert key in header, key
    action, _ = model.predict(np.eye(5, dtype=np.float32)[0])
    assert action.shape == () and 0 <= int(action) < 2


def test_rejects_continuous_actions():
    with pytest.raises(AssertionError, match="Discrete"):
        ACER("MlpPolicy", "Pendulum-v1")


@pytest.mark.parametrize("overlap", [False, True])
def test_learns_the_chain_with_a_fixed_seed(overlap):
    """A tiny learning test: the deterministic policy walks right to the goal of a 6-cell chain."""
    env = make_vec_env(lambda: ChainEnv(length=6, n_actions=3), n_envs=4, seed=3)
    model = ACER("MlpPolicy", env, n_steps=10, seed=3, replay_start=200, gamma=0.9, overlap=overlap)
    model.learn(6_000)
    eval_env = make_vec_env(lambda: __import__("gymnasium").wrappers.TimeLimit(ChainEnv(6, 3), 20), n_envs=1)
    mean, _ = evaluate_policy(model, eval_env, n_eval_episodes=5, deterministic=True)
    assert mean == 1.0


def test_progress_bar_and_tensorboard_run_name(tmp_path):
    model = ACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=2, seed=0), n_steps=5, tensorboard_log=str(tmp_path))
    model.learn(40, progress_bar=True, tb_log_name="chain", log_interval=1)
    model.learn(20, tb_log_name="chain", reset_num_timesteps=False, log_interval=1)
    runs = sorted(p.name for p in tmp_path.iterdir())
    assert runs == ["chain_1"] and list((tmp_path / "chain_1").glob("events.out.tfevents*"))
    assert model.num_timesteps == 60


class Snapshots(BaseCallback):
    """The acting policy's weights at the start of every rollout; raises KeyboardInterrupt at ``stop_at`` steps."""

    def __init__(self, stop_at: int = 0) -> None:
        super().__init__()
        self.weights, self.stop_at = [], stop_at

    def _on_rollout_start(self) -> None:
        self.weights.append(th.cat([p.detach().flatten().clone() for p in self.model.policy.net.parameters()]))

    def _on_step(self) -> bool:
        if self.stop_at and self.num_timesteps >= self.stop_at:
            raise KeyboardInterrupt
        return True


def _optimizer_steps(model: ACER) -> set:
    return {int(state["step"]) for state in model.policy.optimizer.state_dict()["state"].values()}


def _update_threads() -> list:
    import threading

    return [t for t in threading.enumerate() if t.name.startswith("acer-replay")]


def test_overlap_without_replay_is_the_sequential_loop():
    """Only the replay updates run in the second thread: with none, every segment is collected with the same
    weights as in the sequential loop."""
    threads = th.get_num_threads()
    th.set_num_threads(1)  # the same intra-op threads in both loops, for bit-equal sums
    try:
        weights = {}
        for overlap in (False, True):
            model = ACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=2, seed=0), n_steps=5, seed=0, replay_ratio=0,
                         overlap=overlap)
            snapshots = Snapshots()
            model.learn(100, callback=snapshots)
            weights[overlap] = th.stack(snapshots.weights)
        assert th.equal(weights[False], weights[True])
    finally:
        th.set_num_threads(threads)


def test_overlap_replays_one_segment_behind_and_ends_synchronised(tmp_path):
    snapshots = {}
    for overlap in (False, True):
        env = make_vec_env(ChainEnv, n_envs=2, seed=0)
        model = ACER("MlpPolicy", env, n_steps=5, seed=0, replay_start=20, overlap=overlap)
        threads = th.get_num_threads()
        snapshots[overlap] = Snapshots()
        model.learn(100, callback=snapshots[overlap])
        assert th.get_num_threads() == threads and not _update_threads()
        # Every collected segment was learned, and the policy that predict/save see holds the learner's
        # final weights and optimizer state.
        assert model.replay_buffer.n_stored == 10 and _optimizer_steps(model) == {model._n_updates}
    sync, overlapped = snapshots[False].weights, snapshots[True].weights
    # Segment 1 follows segment 0's on-policy update in both loops (the replays start at 20 transitions,
    # after segment 1); segment 2 follows segment 1's on-policy update but, overlapped, not its replays yet.
    assert th.equal(sync[1], overlapped[1]) and not th.equal(sync[0], sync[1])
    assert not th.equal(sync[2], overlapped[2])
    model.save(tmp_path / "model.zip")
    loaded = ACER.load(tmp_path / "model.zip")
    obs = np.eye(5, dtype=np.float32)
    assert loaded.overlap and np.array_equal(loaded.predict(obs, deterministic=True)[0],
                                             model.predict(obs, deterministic=True)[0])


def test_overlap_is_deterministic():
    weights = []
    for _ in range(2):
        model = ACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=2, seed=0), n_steps=5, seed=0, replay_start=10,
                     overlap=True)
        model.learn(200)
        weights.append(th.cat([p.detach().flatten() for p in model.policy.parameters()]))
    assert th.equal(weights[0], weights[1])


class SlowWorkerACER(ACER):
    """Records the entropy weight of each on-policy update and of each replay update; the worker's updates start
    late, so that the rollouts have moved the progress on by then."""

    def _update(self, segment, policy=None, reference=None, coefs=None):
        replaying = threading.current_thread().name.startswith("acer-replay")
        if replaying:
            time.sleep(0.02)
        stats = super()._update(segment, policy, reference, coefs)
        self.events = [*getattr(self, "events", []), ("replay" if replaying else "own", stats["ent_coef"])]
        return stats


def test_overlapped_replays_use_the_weights_of_their_hand_over():
    model = SlowWorkerACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=2, seed=0), n_steps=5, seed=0, replay_start=10,
                           overlap=True, ent_coef="lin_0.5")
    model.learn(300)
    replays = 0
    for i, (kind, coef) in enumerate(model.events):
        if kind == "replay":
            # The latest on-policy update before it is its segment's hand-over (the next waits for the worker).
            own = next(c for k, c in reversed(model.events[:i]) if k == "own")
            assert coef == own
            replays += 1
    assert replays > 10 and len({c for _, c in model.events}) > 10  # the weight moved while replays ran


def test_overlap_interrupted_learns_what_was_collected():
    model = ACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=2, seed=0), n_steps=5, seed=0, replay_start=10,
                 overlap=True)
    with pytest.raises(KeyboardInterrupt):
        model.learn(1_000, callback=Snapshots(stop_at=42))  # in the fifth segment
    assert model.replay_buffer.n_stored == 4 and _optimizer_steps(model) == {model._n_updates}
    assert not _update_threads()
    model.learn(60, reset_num_timesteps=False)  # and continues
    assert model.replay_buffer.n_stored == 10


class CountingACER(ACER):
    """Records the Poisson draws and the replay batches handed to the worker."""

    def replay_count(self, rng):
        n = super().replay_count(rng)
        self.draws = [*getattr(self, "draws", []), n]
        return n

    def replay(self, policy, n_replay, rng=None, batches=None, coefs=None):
        self.batches = [*getattr(self, "batches", []), n_replay]
        return super().replay(policy, n_replay, rng, batches, coefs)


def test_overlap_caps_the_replays_per_segment_and_carries_the_rest():
    model = CountingACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=2, seed=0), n_steps=5, seed=0, replay_start=10,
                         replay_ratio=4, overlap=True)
    model.learn(600)
    cap = 5  # ceil(replay_ratio) + 1
    segments = 60
    assert len(model.draws) == segments and max(model.draws) > cap  # the carry is exercised
    # One batch per segment, then what is still owed when learn ends.
    assert len(model.batches) == segments + 1 and max(model.batches[:-1]) <= cap
    # Every update that was drawn is done, none twice, each batch as soon as the cap allows.
    assert sum(model.batches) == sum(model.draws) and model._n_updates == segments + sum(model.draws)
    owed = np.cumsum(model.draws) - np.cumsum(model.batches[:-1])
    assert np.array_equal(model.batches[:-1], np.minimum(owed + model.batches[:-1], cap))


def test_an_update_given_the_average_networks_probabilities_is_the_update():
    """The trust region's reference handed in (``average_ahead``) as the average network computes it gives the
    same step, bit for bit; another reference gives another step (a tight trust region, so that it binds)."""
    model = ACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=2, seed=0), n_steps=5, seed=0, delta=1e-4)
    model.learn(40)
    segment = model.replay_buffer.sample(np.random.default_rng(0))
    n = segment.actions.size
    policies = [copy.deepcopy(model.policy) for _ in range(3)]
    with th.no_grad():
        own = th.softmax(policies[1].average_logits(model._segment_obs(segment)[:n]), dim=-1)
    model._update(segment, policies[0])
    model._update(segment, policies[1], own)
    model._update(segment, policies[2], th.full_like(own, 1 / own.shape[1]))
    flat = [th.cat([p.detach().flatten() for p in policy.parameters()]) for policy in policies]
    assert th.equal(flat[0], flat[1]) and not th.equal(flat[0], flat[2])


def test_average_ahead_replays_the_same_segments_with_the_reference_computed_before():
    """With ``average_ahead`` the replays are drawn as without it (the same segments, the same number of updates),
    each with the reference of the average network as it was when the segment's replays were handed over."""
    models = {}
    for ahead in (False, True):
        model = CountingACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=2, seed=0), n_steps=5, seed=0,
                             replay_start=10, overlap=True, average_ahead=ahead, delta=1e-4)  # a binding trust region
        drawn, sample = [], model.replay_buffer.sample

        def recording(rng=None, sample=sample, drawn=drawn):
            segment = sample(rng)
            drawn.append(segment.rewards.copy())
            return segment

        model.replay_buffer.sample = recording
        model.learn(300)
        models[ahead] = (model, drawn)
    (plain, plain_drawn), (ahead, ahead_drawn) = models[False], models[True]
    assert plain.batches == ahead.batches and plain._n_updates == ahead._n_updates
    assert len(plain_drawn) == len(ahead_drawn) and all(np.array_equal(a, b) for a, b in zip(plain_drawn, ahead_drawn))
    weights = [th.cat([p.detach().flatten() for p in m.policy.parameters()]) for m in (plain, ahead)]
    assert not th.equal(*weights)  # the older reference changes the steps
    with pytest.raises(ValueError, match="needs the overlapped loop"):
        ACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=2, seed=0), average_ahead=True)


def test_bfloat16_features_keep_the_heads_and_acting_in_float32_and_round_trip(tmp_path):
    env = make_vec_env(ImageEnv, n_envs=2, seed=0)
    model = ACER("CnnPolicy", env, n_steps=4, seed=0, replay_start=8, features_dtype="bfloat16")
    policy = model.policy
    obs = th.as_tensor(np.stack([np.full((3, 40, 40), v, np.uint8) for v in (20, 90, 200)]))
    logits, q = policy.logits_and_q(obs)
    assert logits.dtype == q.dtype == th.float32  # the heads and what the losses see stay float32
    policy.features_autocast = None
    exact_logits, exact_q = policy.logits_and_q(obs)
    exact_probs = policy.action_probs(obs)
    # bfloat16 keeps 8 bits of mantissa: the features (and so the heads' outputs) move by about 1%, no more
    assert th.allclose(logits, exact_logits, atol=0.05, rtol=0.05) and not th.equal(q, exact_q)
    policy.features_autocast = th.bfloat16
    assert th.equal(policy.action_probs(obs), exact_probs)  # acting is float32 either way
    model.learn(200)
    model.save(tmp_path / "model.zip")
    loaded = ACER.load(tmp_path / "model.zip")
    assert loaded.features_dtype == "bfloat16" and loaded.policy.features_autocast == th.bfloat16
    assert ACER("CnnPolicy", env, features_dtype="float32").policy.features_autocast is None
    with pytest.raises(ValueError, match="features_dtype"):
        ACER("CnnPolicy", env, features_dtype="float16")
