"""The new policy's memory (a stack of recent observations), the entropy schedule and the distillation term."""

import numpy as np
import pytest
import torch as th
from envs import CueEnv, ImageEnv
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy

from sb3_disagree import ACER
from sb3_disagree.acer.acer import as_schedule
from sb3_disagree.acer.memory import push_frames
from sb3_disagree.acer.objectives import distillation_loss
from sb3_disagree.behaviour import BehaviourPolicy, BehaviourStep


def test_push_frames_drops_the_oldest_and_clears_at_episode_starts():
    stack = np.arange(2 * 3 * 2).reshape(2, 6, 1).astype(np.int64)  # 2 envs, 3 frames of 2 channels
    new = push_frames(stack, np.full((2, 2, 1), -1), np.array([False, True]), k=3)
    assert new[0, :, 0].tolist() == [2, 3, 4, 5, -1, -1]
    assert new[1, :, 0].tolist() == [0, 0, 0, 0, -1, -1]
    assert push_frames(None, np.ones((1, 2, 1)), None, k=2)[0, :, 0].tolist() == [0, 0, 1, 1]
    obs = np.ones((1, 2))
    assert push_frames(stack, obs, None, k=1) is obs


def test_a_stacking_policy_remembers_the_cue_under_sb3s_evaluate_policy(tmp_path):
    hyper = dict(n_steps=4, learning_rate=3e-3, replay_ratio=2, replay_start=64, ent_coef=0.0, seed=0)
    results = {}
    for k in (1, 2):
        model = ACER("MlpPolicy", make_vec_env(CueEnv, n_envs=4, seed=0), policy_kwargs=dict(frame_stack=k), **hyper)
        model.learn(6_000)
        model.save(tmp_path / f"k{k}.zip")
        loaded = ACER.load(tmp_path / f"k{k}.zip")
        assert loaded.policy.frame_stack == k
        rewards, _ = evaluate_policy(loaded, make_vec_env(CueEnv, n_envs=4, seed=99), n_eval_episodes=200,
                                     return_episode_rewards=True)
        results[k] = float(np.mean(rewards))
    assert results[2] >= 0.95, results  # the cue is remembered: greedy, with the env as registered
    assert results[1] <= 0.7, results  # without memory the corridor looks the same after either cue


def test_predict_carries_the_stack_in_state_and_clears_it_at_episode_starts():
    model = ACER("MlpPolicy", make_vec_env(CueEnv, n_envs=2), policy_kwargs=dict(frame_stack=3))
    first = np.eye(3, dtype=np.float32)[[0, 1]]
    actions, state = model.predict(first, episode_start=np.ones(2, bool), deterministic=True)
    assert actions.shape == (2,) and state[0].shape == (2, 9)
    assert np.array_equal(state[0][:, 6:], first) and not state[0][:, :6].any()
    _, state = model.predict(first[::-1], state=state, episode_start=np.array([False, True]), deterministic=True)
    assert np.array_equal(state[0][0, 3:6], first[0]) and not state[0][1, :6].any()
    # A single (unbatched) observation gives a single action.
    action, _ = model.predict(first[0], deterministic=True)
    assert np.ndim(action) == 0


class Recorder(BehaviourPolicy):
    def __init__(self):
        self.shapes = set()

    def __call__(self, observations, probs, infos, episode_starts):
        self.shapes.add(tuple(np.asarray(observations).shape))
        return BehaviourStep(th.multinomial(probs, 1).squeeze(-1), probs)


def test_the_behaviour_gets_single_frames_while_the_policy_sees_stacks():
    recorder = Recorder()
    env = make_vec_env(ImageEnv, n_envs=2, seed=0)
    model = ACER("CnnPolicy", env, n_steps=3, replay_start=6, behaviour=recorder, policy_kwargs=dict(frame_stack=4))
    model.learn(12)
    assert recorder.shapes == {(2, 3, 40, 40)}  # channels first, one frame: what a prior was trained on
    assert model.replay_buffer.sample().observations.shape[-3:] == (12, 40, 40)  # stored as frames, replayed as stacks
    assert model.policy.net.features_extractor.cnn[0].in_channels == 12


def test_distillation_loss_against_a_hand_computation():
    probs = th.tensor([[0.5, 0.25, 0.25], [0.2, 0.3, 0.5]])
    teacher = th.tensor([[1.0, 0.0, 0.0], [0.0, 0.5, 0.5]])
    weights = th.tensor([1.0, 0.5])
    # Row 1: -log 0.5 = 0.6931; row 2: 0.5 * -(0.5 log 0.3 + 0.5 log 0.5) = 0.4743; mean 0.5837.
    assert distillation_loss(probs.log(), teacher, weights).item() == pytest.approx(0.58372, abs=1e-4)
    assert distillation_loss(probs.log(), teacher, th.zeros(2)).item() == 0.0


class Teacher(BehaviourPolicy):
    """Acts with the policy and offers a fixed teacher that always says action 2."""

    def __call__(self, observations, probs, infos, episode_starts):
        teacher = th.zeros_like(probs)
        teacher[:, 2] = 1.0
        return BehaviourStep(th.multinomial(probs, 1).squeeze(-1), probs, teacher=teacher,
                             followed=np.ones(len(probs), np.float32))


def test_distillation_pulls_the_policy_to_the_teacher_and_fades_on_schedule():
    obs = th.as_tensor(np.stack([np.full((3, 40, 40), 60 * (t + 1), np.uint8) for t in range(3)]))
    prob_of_2 = {}
    for coef in (0.0, 1.0):
        model = ACER("CnnPolicy", make_vec_env(ImageEnv, n_envs=2, seed=0), n_steps=4, replay_ratio=0, ent_coef=0.0,
                     learning_rate=1e-3, distill_coef=coef, behaviour=Teacher(), seed=0)
        model.learn(800)
        prob_of_2[coef] = model.policy.action_probs(obs)[:, 2].mean().item()
    assert prob_of_2[1.0] > 0.8 and prob_of_2[0.0] < 0.6, prob_of_2
    model.distill_steps = 400
    assert model.distill_weight() == 0.0  # annealed linearly to zero at distill_steps
    model.num_timesteps = 100
    assert model.distill_weight() == pytest.approx(0.75)


def test_entropy_weight_schedules():
    assert as_schedule("lin_0.01")(0.5) == pytest.approx(0.005)
    assert as_schedule(0.02)(0.1) == 0.02
    with pytest.raises(ValueError, match="lin_"):
        as_schedule("exp_0.1")
    with pytest.raises(ValueError, match="distill_states"):
        ACER("MlpPolicy", make_vec_env(CueEnv, n_envs=1), distill_states="some")
    with pytest.raises(ValueError, match="lin_"):
        ACER("MlpPolicy", make_vec_env(CueEnv, n_envs=1), learning_rate="cos_1e-3")


def test_a_linear_learning_rate_falls_to_zero_over_the_budget_and_survives_save_and_load(tmp_path):
    model = ACER("MlpPolicy", make_vec_env(CueEnv, n_envs=2, seed=0), n_steps=4, learning_rate="lin_0.001", seed=0)
    model.learn(80)  # ten updates; the last one, with no budget left, changes nothing
    assert model.policy.optimizer.param_groups[0]["lr"] == 0.0
    assert model.lr_schedule(0.5) == pytest.approx(0.0005)
    model.save(tmp_path / "model.zip")
    loaded = ACER.load(tmp_path / "model.zip")
    assert loaded.learning_rate == "lin_0.001" and loaded.lr_schedule(0.25) == pytest.approx(0.00025)


@pytest.mark.parametrize("policy, env_class, flags", [("MlpPolicy", CueEnv, False), ("CnnPolicy", ImageEnv, False),
                                                      ("CnnPolicy", ImageEnv, True)])
def test_a_policy_started_from_a_prior_acts_as_the_prior_whatever_its_older_frames(policy, env_class, flags):
    """A plain prior into a policy with a stack, or with loop flags (fine-tuning with the finish's memory)."""
    from sb3_disagree.acer.torch_layers import loop_flags_kwargs
    from sb3_disagree.acer.transfer import load_prior_weights, transfer_kwargs

    env = make_vec_env(env_class, n_envs=2, seed=0)
    prior = ACER(policy, env, n_steps=4, seed=1)
    prior.learn(64)  # weights away from their initialisation
    model = ACER(policy, env, seed=2, policy_kwargs=dict(transfer_kwargs(prior.policy), frame_stack=3,
                                                         **(loop_flags_kwargs(3) if flags else {})))
    assert transfer_kwargs(model.policy)["frame_stack"] == 3  # a prior with memory passes it on to a fine-tuned policy
    copied = load_prior_weights(model.policy, prior.policy)
    assert copied and not any(name.startswith("q_net") for name in copied)
    obs = th.as_tensor(prior.policy.obs_to_tensor(np.stack([env.observation_space.sample() for _ in range(5)]))[0])
    older = th.as_tensor(np.stack([np.concatenate([env.observation_space.sample()] * 2, axis=-1 if policy == "MlpPolicy"
                                                  else 2) for _ in range(5)]))
    if policy == "CnnPolicy":
        older = older.permute(0, 3, 1, 2)
    stacked = th.cat([older.to(obs.dtype), obs], dim=1)
    if flags:  # pressed against a wall: the newest frame equals the older ones (both flags on)
        stacked[0] = th.cat([obs[0]] * 3)
        assert model.policy.net.features_extractor.flags(stacked)[0].tolist() == [1.0, 1.0]
    with th.no_grad():
        assert th.allclose(model.policy.action_probs(stacked), prior.policy.action_probs(obs), atol=1e-6)
        # The average network starts at the copied weights.
        prior_logits = prior.policy.net.logits(prior.policy.extract_features(obs, prior.policy.net.features_extractor))
        assert th.allclose(model.policy.average_logits(stacked), prior_logits, atol=1e-5)
        # The Q head is the new policy's own.
        theirs = prior.policy.net.q_net.weight
        assert not th.allclose(model.policy.net.q_net.weight[:, :theirs.shape[1]], theirs)


def test_a_prior_with_memory_gets_its_own_stack_as_its_predict_would_build_it():
    """PriorSet keeps a stack per prior with memory (cleared at episode starts), the others see single frames."""
    from sb3_disagree.options.priors import PriorSet

    env = make_vec_env(CueEnv, n_envs=2, seed=0)
    stacked = ACER("MlpPolicy", env, policy_kwargs=dict(frame_stack=3), seed=1)
    single = ACER("MlpPolicy", env, seed=2)
    priors = PriorSet([stacked, single])
    frames = [np.eye(3, dtype=np.float32)[[i % 3, (i + 1) % 3]] for i in range(5)]
    starts = [np.ones(2, bool), np.zeros(2, bool), np.array([False, True]), np.zeros(2, bool), np.zeros(2, bool)]
    state = None
    for i, (obs, start) in enumerate(zip(frames, starts)):
        got = priors.probs(obs, start)
        if i == 2:  # env 1 restarted: only its new frame; env 0 holds its last three
            assert not priors._stacks[0][1, :6].any() and np.array_equal(priors._stacks[0][0, :3], frames[0][0])
        _, state = stacked.predict(obs, state=state, episode_start=start)
        want = stacked.policy.get_distribution(th.as_tensor(state[0])).distribution.probs
        assert th.allclose(got[0], want)
        assert th.allclose(got[1], single.policy.get_distribution(th.as_tensor(obs)).distribution.probs)
    # All five steps at once (a rollout's teachers): the same distributions, the stacks left as step by step.
    at_once = PriorSet([stacked, single])
    fresh = PriorSet([stacked, single])
    per_step = th.stack([fresh.probs(obs, start) for obs, start in zip(frames, starts)], dim=1)
    assert th.allclose(at_once.probs_sequence(frames, starts), per_step, atol=1e-6)
    np.testing.assert_array_equal(at_once._stacks[0], fresh._stacks[0])


def test_linked_frames_rebuild_the_stacks_push_frames_built():
    """Frames linked to their predecessors give back, for any indices, the stacks built step by step along
    interleaved episodes of several envs (zeros before each episode's start)."""
    from sb3_disagree.acer.memory import LinkedFrames, push_frames

    rng = np.random.default_rng(0)
    n, k, steps = 3, 4, 30
    stack, previous, frames, links, stacks = None, np.full(n, -1), [], [], []
    starts = np.ones(n, dtype=bool)
    for t in range(steps):
        obs = rng.integers(1, 256, (n, 2, 3, 3), dtype=np.uint8)
        stack = push_frames(stack, obs, starts, k)
        here = t * n + np.arange(n)
        frames.append(obs)
        links.append(np.where(starts, -1, previous))
        stacks.append(stack)
        previous = here
        starts = rng.random(n) < 0.2
    held = LinkedFrames(np.concatenate(frames), np.concatenate(links), k)
    expected = np.concatenate(stacks)
    idx = rng.permutation(len(held))[:40]
    np.testing.assert_array_equal(held[idx], expected[idx])
    assert (expected[:n, : (k - 1) * 2] == 0).all() and len(held) == steps * n


def test_loop_flags_say_which_older_frames_the_newest_equals():
    from gymnasium import spaces

    from sb3_disagree.acer.torch_layers import LoopFlagsCNN

    space = spaces.Box(0, 255, (9, 40, 40), dtype=np.uint8)  # 3 frames of 3 channels
    extractor = LoopFlagsCNN(space, frame_stack=3, features_dim=16)
    assert extractor.features_dim == 16 + 2
    a, b = np.full((3, 40, 40), 0.2), np.full((3, 40, 40), 0.4)
    c = b.copy()
    c[1, 5, 7] += 1 / 255  # one pixel one level apart: a different pose
    cases = [  # (oldest, middle, newest) -> (newest == middle, newest == oldest)
        ((a, b, b), [1, 0]),  # pressed against a wall
        ((b, a, b), [0, 1]),  # turned back
        ((b, b, b), [1, 1]),
        ((a, b, c), [0, 0]),
        ((np.zeros_like(a), np.zeros_like(a), a), [0, 0]),  # before the episode's start: zeros, no frame
    ]
    for frames, expected in cases:
        stack = th.as_tensor(np.concatenate(frames)[None], dtype=th.float32)
        assert extractor.flags(stack).tolist() == [expected], expected
        # The CNN sees the newest frame only: the older ones reach the features through the flags alone.
        features = extractor(stack)
        alone = extractor.cnn(th.as_tensor(frames[-1][None], dtype=th.float32))
        assert th.allclose(features[:, :16], alone) and features[0, 16:].tolist() == expected
    with pytest.raises(ValueError, match="frame_stack must be >= 2"):
        LoopFlagsCNN(spaces.Box(0, 255, (3, 40, 40), dtype=np.uint8), frame_stack=1)
    with pytest.raises(ValueError, match="not a stack of 2 frames"):
        LoopFlagsCNN(space, frame_stack=2)


def test_loop_flags_with_the_cnn_on_the_whole_stack():
    """cnn_sees="stack": the CNN reads every frame in order (two stacks with the same newest frame and flags differ
    in their features), the flags are the same as with the newest frame alone, and a bad value is refused."""
    from gymnasium import spaces

    from sb3_disagree.acer.torch_layers import LoopFlagsCNN

    space = spaces.Box(0, 255, (9, 40, 40), dtype=np.uint8)
    th.manual_seed(0)
    extractor = LoopFlagsCNN(space, frame_stack=3, features_dim=16, cnn_sees="stack")
    assert extractor.cnn.cnn[0].in_channels == 9 and extractor.features_dim == 16 + 2
    rng = np.random.default_rng(0)
    a, b, c = (rng.integers(0, 256, (3, 40, 40), dtype=np.uint8) for _ in range(3))
    stacks = th.as_tensor(np.stack([np.concatenate(f) for f in [(a, b, c), (b, a, c), (a, c, c)]]))
    features = extractor(stacks)
    assert features[:, 16:].tolist() == [[0, 0], [0, 0], [1, 0]]
    assert not th.allclose(features[0, :16], features[1, :16])  # the order of the older frames reaches the CNN
    assert th.allclose(features[:, :16], extractor.cnn(stacks.float() / 255))
    with pytest.raises(ValueError, match="cnn_sees must be one of"):
        LoopFlagsCNN(space, frame_stack=3, cnn_sees="oldest")


def test_a_loop_flags_policy_round_trips_through_save_load_and_evaluate_policy(tmp_path):
    from sb3_disagree.acer.torch_layers import LoopFlagsCNN

    env = make_vec_env(ImageEnv, n_envs=2, seed=0)
    kwargs = dict(frame_stack=2, features_extractor_class=LoopFlagsCNN, features_extractor_kwargs=dict(frame_stack=2))
    model = ACER("CnnPolicy", env, n_steps=3, replay_start=6, seed=0, policy_kwargs=kwargs)
    model.learn(30)
    model.save(tmp_path / "m.zip")
    loaded = ACER.load(tmp_path / "m.zip")
    assert isinstance(loaded.policy.net.features_extractor, LoopFlagsCNN) and loaded.policy.frame_stack == 2
    obs = np.stack([ImageEnv()._obs(), np.full((40, 40, 3), 180, np.uint8)])
    state = None
    for start in (True, False, False):  # the same frames again: the flags turn on through the carried stack
        expected, state_a = model.predict(obs, state=state, episode_start=np.full(2, start), deterministic=True)
        got, state = loaded.predict(obs, state=state, episode_start=np.full(2, start), deterministic=True)
        assert np.array_equal(expected, got) and np.array_equal(state_a[0], state[0])
    flags = loaded.policy.net.features_extractor.flags(th.as_tensor(state[0], dtype=th.float32) / 255)
    assert flags.tolist() == [[1.0], [1.0]]
    evaluate_policy(loaded, env, n_eval_episodes=4)


def test_loop_flags_on_raw_frames_match_sb3s_preprocessing_bit_for_bit():
    from stable_baselines3.common.preprocessing import preprocess_obs

    from sb3_disagree.acer.torch_layers import LoopFlagsCNN

    model = ACER("CnnPolicy", make_vec_env(ImageEnv, n_envs=1), policy_kwargs=dict(
        frame_stack=3, features_extractor_class=LoopFlagsCNN, features_extractor_kwargs=dict(frame_stack=3)))
    policy, rng = model.policy, np.random.default_rng(0)
    frames = rng.integers(0, 256, (4, 3, 40, 40), dtype=np.uint8)
    one_off = frames[0].copy()
    one_off[2, 3, 4] ^= 1
    stacks = th.as_tensor(np.stack([np.concatenate(f) for f in [
        (frames[0], frames[1], frames[1]), (frames[1], frames[0], frames[1]), (frames[2], frames[3], frames[0]),
        (frames[0], one_off, frames[0]), (np.zeros_like(frames[0]), np.zeros_like(frames[0]), frames[0])]]))
    extractor = policy.net.features_extractor
    raw = policy.extract_features(stacks, extractor)  # the stack as stored, scaled inside
    scaled = extractor(preprocess_obs(stacks, policy.observation_space))  # SB3's way: the whole stack scaled first
    assert th.equal(raw, scaled)
    assert raw[:, -2:].tolist() == [[1, 0], [0, 1], [0, 0], [0, 1], [0, 0]]
    # Frames whose byte count 8 does not divide are compared byte by byte: the same flags.
    small = stacks[:, :, :5, :5].contiguous()
    assert extractor.flags(small).tolist() == [[1, 0], [0, 1], [0, 0], [0, 1], [0, 0]]


@pytest.mark.parametrize("stack", [1, 3])
def test_a_rollouts_teachers_computed_at_once_equal_those_computed_at_each_step(stack):
    """PriorTeacher's teachers, computed once per rollout (the default) or at each step: the same segment, the same
    teachers (a prior with memory among them), and the new policy's own stack of ``stack`` frames."""
    from sb3_disagree.options import PriorSet, PriorTeacher

    def segment_teacher(per_rollout: bool) -> tuple[np.ndarray, np.ndarray]:
        env = make_vec_env(CueEnv, n_envs=2, seed=0)
        priors = PriorSet([ACER("MlpPolicy", env, policy_kwargs=dict(frame_stack=2), seed=1),
                           ACER("MlpPolicy", env, seed=2)])
        model = ACER("MlpPolicy", env, n_steps=5, replay_start=10_000, distill_coef=1.0, seed=3,
                     policy_kwargs=dict(frame_stack=stack), behaviour=PriorTeacher(priors, per_rollout=per_rollout))
        model.learn(30)  # three rollouts of 5 steps x 2 envs; episodes of CueEnv end within them
        return model.replay_buffer.teacher[:3].copy(), model.replay_buffer.actions[:3].copy()

    at_once, actions = segment_teacher(True)
    per_step, same_actions = segment_teacher(False)
    np.testing.assert_array_equal(actions, same_actions)
    assert at_once.any() and np.allclose(at_once.sum(-1), 1.0)
    np.testing.assert_allclose(at_once, per_step, atol=1e-6)


@pytest.mark.parametrize("states", ["followed", "all"])
def test_disagreement_distills_toward_the_priors_mixture_on_the_steps_configured(states, monkeypatch):
    """Mode disagreement-distill: Algorithm 1's behaviour, and ACER's distillation term toward the priors' mixture on
    the steps where the priors chose the action ("followed") or on every step ("all"), against a hand computation."""
    import sb3_disagree.acer.acer as acer_module
    from sb3_disagree.options import DisagreementOptions, PriorSet

    env = make_vec_env(CueEnv, n_envs=2, seed=0)
    priors = PriorSet([ACER("MlpPolicy", env, seed=1), ACER("MlpPolicy", env, seed=2)])
    steps, calls = [], []

    class Recording(DisagreementOptions):
        def __call__(self, *args):
            steps.append(super().__call__(*args))
            return steps[-1]

    behaviour = Recording(priors, alpha=2, beta=10.0, entropy_offset=0.35, seed=0)  # the priors always agree
    original = acer_module.distillation_loss

    def capture(log_probs, teacher, weights):
        calls.append((log_probs.detach().clone(), teacher.clone(), weights.clone()))
        return original(log_probs, teacher, weights)

    monkeypatch.setattr(acer_module, "distillation_loss", capture)
    model = ACER("MlpPolicy", env, n_steps=8, replay_ratio=0, distill_coef=1.0, distill_states=states, seed=3,
                 behaviour=behaviour)
    model.learn(16)  # one segment of 8 steps x 2 envs, one on-policy update
    log_probs, teacher, weights = calls[0]
    followed = np.concatenate([s.followed for s in steps[:8]])
    mixture = th.cat([th.as_tensor(s.teacher) for s in steps[:8]])
    assert 0 < followed.sum() < len(followed)  # the entropy branch followed the priors at some steps, not all
    np.testing.assert_allclose(teacher.numpy(), mixture.numpy(), atol=1e-6)
    np.testing.assert_array_equal(weights.numpy(), followed if states == "followed" else np.ones_like(followed))
    # L = (1/N) sum_t w_t * -(sum_a teacher_t(a) log pi_t(a)), by hand over the kept steps
    by_hand = sum(-(mixture[t] * log_probs[t]).sum().item() for t in range(16) if states == "all" or followed[t]) / 16
    assert original(log_probs, teacher, weights).item() == pytest.approx(by_hand, abs=1e-5)
