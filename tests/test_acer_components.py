"""ACER's buffer, average network, behaviour checks and time-limit bootstrap."""

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from envs import ChainEnv
from gymnasium import spaces
from stable_baselines3.common.env_util import make_vec_env

from sb3_disagree import ACER, BehaviourPolicy, BehaviourStep
from sb3_disagree.acer.buffers import Segment, SegmentReplayBuffer


def _segment(T, E, A, value):
    return Segment(
        observations=np.full((T + 1, E, 3), value, dtype=np.float32),
        actions=np.full((T, E), value, dtype=np.int64),
        rewards=np.full((T, E), value, dtype=np.float32),
        dones=np.zeros((T, E), dtype=np.float32),
        timeout_values=np.full((T, E), value, dtype=np.float32),
        mu=np.full((T, E, A), value, dtype=np.float32),
    )


def test_buffer_returns_whole_segments_with_their_mu():
    T, E, A = 4, 3, 2
    buf = SegmentReplayBuffer(buffer_size=T * E * 5, n_steps=T, n_envs=E,
                              observation_space=spaces.Box(-1, 1, (3,)), n_actions=A)
    assert buf.n_segments == 5
    for value in range(7):  # wraps around: segments 2..6 remain
        buf.add(_segment(T, E, A, value))
    assert buf.full and buf.size() == 5 * T * E
    rng = np.random.default_rng(0)
    seen = set()
    for _ in range(50):
        s = buf.sample(rng)
        assert s.observations.shape == (T + 1, E, 3) and s.mu.shape == (T, E, A) and s.actions.shape == (T, E)
        for e in range(E):
            v = s.actions[0, e]  # every field of env e's column comes from the same stored segment
            assert 2 <= v <= 6
            assert (s.actions[:, e] == v).all() and (s.observations[:, e] == v).all()
            assert (s.mu[:, e] == v).all() and (s.rewards[:, e] == v).all() and (s.timeout_values[:, e] == v).all()
            seen.add(int(v))
    assert seen == {2, 3, 4, 5, 6}


def test_buffer_keeps_env_columns_apart():
    T, E, A = 2, 2, 3
    buf = SegmentReplayBuffer(T * E, T, E, spaces.Box(-1, 1, (3,)), A)
    seg = _segment(T, E, A, 0)
    seg.actions[:, 1] = 2
    seg.mu[:, 1] = [0.2, 0.3, 0.5]
    buf.add(seg)
    s = buf.sample()
    assert (s.actions[:, 0] == 0).all() and (s.actions[:, 1] == 2).all()
    assert np.allclose(s.mu[:, 1], [0.2, 0.3, 0.5])


def test_average_network_moves_by_one_minus_alpha():
    model = ACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=2, seed=0), n_steps=5, alpha=0.9, seed=0)
    policy = model.policy
    with th.no_grad():
        for p in policy.average_net.parameters():
            p.add_(th.randn_like(p))
    before_avg = [p.detach().clone() for p in policy.average_net.parameters()]
    before_net = [p.detach().clone() for p in policy.net.parameters()]
    policy.update_average(0.9)
    for avg, old_avg, net in zip(policy.average_net.parameters(), before_avg, before_net):
        assert th.allclose(avg, 0.9 * old_avg + 0.1 * net, atol=1e-6)
    # ... and an ACER update moves it exactly so, toward the parameters after the optimizer step.
    before_avg = [p.detach().clone() for p in policy.average_net.parameters()]
    model.learn(10)
    for avg, old_avg, net in zip(policy.average_net.parameters(), before_avg, policy.net.parameters()):
        assert th.allclose(avg, 0.9 * old_avg + 0.1 * net, atol=1e-6)
    assert not all(th.equal(a, b) for a, b in zip(policy.average_net.parameters(), before_avg))
    # The average network is never trained by the optimizer.
    opt_params = {id(p) for group in policy.optimizer.param_groups for p in group["params"]}
    assert not opt_params & {id(p) for p in policy.average_net.parameters()}


class FixedAction(BehaviourPolicy):
    """Always takes `action`; reports `mu` as given."""

    def __init__(self, action, mu, tags=None):
        self.action, self.mu, self.tags = action, np.asarray(mu, dtype=np.float32), tags

    def __call__(self, observations, probs, infos, episode_starts):
        n = probs.shape[0]
        tags = None if self.tags is None else np.array([self.tags] * n)
        return BehaviourStep(np.full(n, self.action), np.tile(self.mu, (n, 1)), tags)


def test_behaviour_with_zero_mass_on_taken_action_is_rejected():
    model = ACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=2, seed=0), n_steps=4,
                 behaviour=FixedAction(0, [0.0, 1.0]))
    with pytest.raises(ValueError, match=r"mu\(a_t\) = 0"):
        model.learn(8)


def test_behaviour_mu_must_be_a_distribution():
    model = ACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=2, seed=0), n_steps=4,
                 behaviour=FixedAction(1, [0.5, 0.9]))
    with pytest.raises(ValueError, match="probability distribution"):
        model.learn(8)


def test_behaviour_actions_mu_and_tags_reach_the_buffer():
    model = ACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=3, seed=0), n_steps=4, replay_ratio=0,
                 behaviour=FixedAction(1, [0.25, 0.75], tags="prior"))
    model.learn(12)
    buf = model.replay_buffer
    assert buf.n_stored == 1
    assert (buf.actions[0] == 1).all()
    assert np.allclose(buf.mu[0], [0.25, 0.75])
    assert model.last_rollout_tags.shape == (4, 3) and (model.last_rollout_tags == "prior").all()


def test_default_behaviour_stores_mu_equal_to_pi():
    model = ACER("MlpPolicy", make_vec_env(ChainEnv, n_envs=2, seed=0), n_steps=3, replay_ratio=0, learning_rate=0.0)
    model.learn(6)
    obs = model.replay_buffer.observations[0, :3].reshape(6, -1)
    with th.no_grad():
        pi = model.policy.action_probs(th.as_tensor(obs)).numpy()
    assert np.allclose(model.replay_buffer.mu[0].reshape(6, -1), pi, atol=1e-6)


def test_time_limit_truncation_is_bootstrapped_and_termination_is_not():
    # ChainEnv(length=3) terminates after two steps right; a time limit of 1 truncates first otherwise.
    def make(limit):
        return gym.wrappers.TimeLimit(ChainEnv(length=3), max_episode_steps=limit)

    model = ACER("MlpPolicy", make_vec_env(lambda: make(1), n_envs=1), n_steps=4, replay_ratio=0, learning_rate=0.0,
                 behaviour=FixedAction(1, [0.5, 0.5]))
    model.learn(4)
    buf = model.replay_buffer
    assert (buf.dones[0] == 1).all()  # every step was cut by the time limit
    obs_after_one_right = th.tensor([[0.0, 1.0, 0.0]])
    with th.no_grad():
        logits, q = model.policy.logits_and_q(obs_after_one_right)
        v = (th.softmax(logits, -1) * q).sum().item()
    # V(x) of the true last observation (one step right), not of the reset observation that replaced it.
    assert v != 0 and np.allclose(buf.timeout_values[0], v, atol=1e-6)

    model = ACER("MlpPolicy", make_vec_env(lambda: make(50), n_envs=1), n_steps=4, replay_ratio=0,
                 behaviour=FixedAction(1, [0.5, 0.5]))
    model.learn(4)
    buf = model.replay_buffer
    assert buf.dones[0, :, 0].tolist() == [0, 1, 0, 1]  # terminations at the right end
    assert (buf.timeout_values[0] == 0).all()


@pytest.mark.parametrize("scale", [0.1, 1.0])
def test_reward_scale_enters_the_targets_and_the_q_loss_is_half_the_squared_error(monkeypatch, scale):
    import sb3_disagree.acer.acer as acer_module

    seen = {}
    real = acer_module.retrace_targets

    def spy(rewards, *args):
        seen["rewards"], seen["q_ret"] = rewards.clone(), real(rewards, *args)
        return seen["q_ret"]

    monkeypatch.setattr(acer_module, "retrace_targets", spy)
    model = ACER("MlpPolicy", make_vec_env(lambda: ChainEnv(length=3), n_envs=2), n_steps=3, reward_scale=scale,
                 seed=0)
    rng = np.random.default_rng(0)
    obs = np.eye(3, dtype=np.float32)[rng.integers(0, 3, size=(4, 2))]
    segment = Segment(observations=obs, actions=rng.integers(0, 2, size=(3, 2)),
                      rewards=np.full((3, 2), 5.0, dtype=np.float32), dones=np.zeros((3, 2), dtype=np.float32),
                      timeout_values=np.zeros((3, 2), dtype=np.float32), mu=np.full((3, 2, 2), 0.5, dtype=np.float32))
    with th.no_grad():
        _, q = model.policy.logits_and_q(th.as_tensor(obs[:3].reshape(6, 3)))
        q_taken = q.gather(1, th.as_tensor(segment.actions.reshape(6, 1))).squeeze(1)
    stats = model._update(segment)
    assert th.allclose(seen["rewards"], th.full((3, 2), 5.0 * scale))
    err = seen["q_ret"].reshape(6) - q_taken
    expected = 0.5 * err**2
    assert stats["value_loss"] == pytest.approx(expected.mean().item(), rel=1e-5)


def test_buffer_stores_frame_stacks_as_frames_and_rebuilds_them():
    """With frame stacking, a segment is stored as its first stack and each later stack's newest frame; sampling
    gives back exactly the stacks the rollout built, cleared where an episode ended, in a sixth of the memory."""
    from sb3_disagree.acer.memory import push_frames

    T, E, A, K, C = 20, 3, 3, 8, 2
    rng = np.random.default_rng(0)
    space = spaces.Box(0, 255, (K * C, 4, 5), np.uint8)
    whole = SegmentReplayBuffer(T * E * 2, T, E, space, A)
    frames = SegmentReplayBuffer(T * E * 2, T, E, space, A, frame_stack=K)
    stack, kept = push_frames(None, rng.integers(0, 256, (E, C, 4, 5), dtype=np.uint8), None, K), []
    for _ in range(2):
        seg = _segment(T, E, A, 0)
        seg.observations = np.zeros((T + 1, E, K * C, 4, 5), np.uint8)
        seg.dones = (rng.random((T, E)) < 0.15).astype(np.float32)
        for t in range(T + 1):  # as collect_rollouts builds them: the stack after step t-1's done flags
            seg.observations[t] = stack
            if t < T:
                stack = push_frames(stack, rng.integers(0, 256, (E, C, 4, 5), dtype=np.uint8), seg.dones[t] > 0, K)
        seg.actions[:] = len(kept)  # tells the stored segments apart
        kept.append(seg)
        whole.add(seg)
        frames.add(seg)
    assert frames.observations.nbytes + frames.first_stacks.nbytes < whole.observations.nbytes / 5
    assert kept[0].dones.any() and (kept[0].observations[1:][kept[0].dones > 0][:, :-C] == 0).all()
    for _ in range(10):
        s = frames.sample(np.random.default_rng(_))
        for e in range(E):
            np.testing.assert_array_equal(s.observations[:, e], kept[s.actions[0, e]].observations[:, e])
    with pytest.raises(ValueError, match="not stacks of 8 frames"):
        SegmentReplayBuffer(T * E, T, E, spaces.Box(0, 255, (3, 4, 5), np.uint8), A, frame_stack=K)
