"""Disagreement options and the room sensor: gate direction, window, entropy branch, mu, batching."""

import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch as th

from sb3_disagree.options import DisagreementOptions, RoomSensorOptions, disagreement, entropy, kl

A = 3


class FakePriors:
    """Priors whose distributions the test sets for every call: a (k, E, A) tensor or a function of the step."""

    def __init__(self, probs):
        self.fn = probs if callable(probs) else (lambda step: probs)
        self.step = 0

    def __len__(self):
        return 2

    def to(self, device):
        return self

    def probs(self, observations, episode_starts=None):
        self.step += 1
        return self.fn(self.step - 1)

    def probs_sequence(self, observations, episode_starts):
        return th.stack([self.probs(o, s) for o, s in zip(observations, episode_starts)], dim=1)


def _setup(behaviour, n_envs):
    behaviour.setup(SimpleNamespace(n_envs=n_envs, device=th.device("cpu")))
    return behaviour


AGREE = th.tensor([[0.8, 0.1, 0.1], [0.7, 0.2, 0.1]])
DISAGREE = th.tensor([[0.9, 0.05, 0.05], [0.05, 0.05, 0.9]])
UNIFORM = th.full((1, A), 1 / A)


def _priors(rows, n_envs):
    return th.stack([rows[0].expand(n_envs, A), rows[1].expand(n_envs, A)])


def _run(behaviour, pi, n_envs, steps, infos=None):
    out = []
    starts = np.ones(n_envs, dtype=bool)
    for _ in range(steps):
        out.append(behaviour(None, pi.expand(n_envs, A), infos or [{}] * n_envs, starts))
        starts = np.zeros(n_envs, dtype=bool)
    return out


def test_disagreement_score_is_the_min_of_both_kls():
    p, q = th.tensor([0.7, 0.2, 0.1]), th.tensor([0.2, 0.5, 0.3])
    expected = min(sum(p[i] * math.log(p[i] / q[i]) for i in range(3)), sum(q[i] * math.log(q[i] / p[i]) for i in range(3)))
    assert disagreement(th.stack([p, q]).unsqueeze(1)).item() == pytest.approx(float(expected), rel=1e-5)
    three = th.stack([p, q, p]).unsqueeze(1)
    d_pq = disagreement(th.stack([p, q]).unsqueeze(1)).item()
    assert disagreement(three).item() == pytest.approx((d_pq + d_pq + 0.0) / 3, rel=1e-5)  # mean over pairs
    assert entropy(UNIFORM).item() == pytest.approx(math.log(3), rel=1e-6)
    assert kl(p, p).item() == pytest.approx(0.0, abs=1e-6)


def test_beta_zero_never_follows_and_huge_beta_always_follows_in_the_branch():
    n = 64
    never = _setup(DisagreementOptions(FakePriors(_priors(AGREE, n)), alpha=3, beta=0.0, seed=0), n)
    steps = _run(never, UNIFORM, n, 20)
    assert all((s.tags == "explore").all() for s in steps)
    always = _setup(DisagreementOptions(FakePriors(_priors(DISAGREE, n)), alpha=3, beta=1e9, entropy_offset=-10, seed=0), n)
    steps = _run(always, UNIFORM, n, 20)
    assert all((s.tags == "prior").all() for s in steps)  # the branch is always entered with offset -10


def test_gate_follows_while_below_beta_and_the_window_mean():
    d_agree = disagreement(_priors(AGREE, 1)).item()
    d_disagree = disagreement(_priors(DISAGREE, 1)).item()
    beta = (d_agree + d_disagree) / 2
    # Scores: 3 agreeing steps, then disagreeing ones; window alpha = 4, branch always entered.
    seq = [AGREE] * 3 + [DISAGREE] * 5
    b = _setup(DisagreementOptions(FakePriors(lambda t: _priors(seq[t], 1)), alpha=4, beta=beta, entropy_offset=-10,
                                   seed=0), 1)
    follows, means = [], []
    for t in range(len(seq)):
        s = b(None, UNIFORM, [{}], np.array([t == 0]))
        follows.append(s.tags[0] == "prior")
        means.append(b.window_mean()[0])
    window = []
    for t, rows in enumerate(seq):
        window = (window + [d_agree if rows is AGREE else d_disagree])[-4:]
        assert means[t] == pytest.approx(np.mean(window), rel=1e-5)
        assert follows[t] == (np.mean(window) < beta)
    assert follows[:4] == [True, True, True, True] and not follows[-1]


def test_window_is_cleared_at_episode_start_and_counts_only_branch_steps():
    b = _setup(DisagreementOptions(FakePriors(_priors(DISAGREE, 2)), alpha=5, beta=0.1, entropy_offset=-10, seed=0), 2)
    _run(b, UNIFORM, 2, 3)
    assert (b.count == 3).all()
    b(None, UNIFORM.expand(2, A), [{}, {}], np.array([True, False]))
    assert b.count.tolist() == [1, 4]
    # Outside the branch (offset above the entropy) nothing is added.
    b.entropy_offset = 10
    b(None, UNIFORM.expand(2, A), [{}, {}], np.array([False, False]))
    assert b.count.tolist() == [1, 4]


def test_entropy_branch_frequency_matches_its_formula():
    n = 4000
    pi = th.tensor([[0.85, 0.1, 0.05]])
    h = entropy(pi).item()
    b = _setup(DisagreementOptions(FakePriors(_priors(AGREE, n)), beta=1e9, seed=1), n)
    steps = _run(b, pi, n, 5)
    freq = np.mean([(s.tags == "prior").mean() for s in steps])
    assert freq == pytest.approx(h - 0.1, abs=0.015)


def test_mu_is_the_exact_mixture_and_sums_to_one():
    n = 5
    pi = th.tensor([[0.6, 0.3, 0.1]])
    h = entropy(pi).item()
    prior_probs = th.softmax(th.randn(2, n, A, generator=th.Generator().manual_seed(0)), -1)
    for beta, gate in ((1e9, 1.0), (0.0, 0.0)):
        b = _setup(DisagreementOptions(FakePriors(prior_probs), beta=beta, seed=0), n)
        step = _run(b, pi, n, 1)[0]
        q = min(max(h - 0.1, 0.0), 1.0) * gate
        expected = q * prior_probs.mean(0) + (1 - q) * pi.expand(n, A)
        assert th.allclose(step.mu, expected, atol=1e-6)
        assert th.allclose(step.mu.sum(-1), th.ones(n), atol=1e-6)
        assert (step.mu.gather(1, step.actions.view(-1, 1)) > 0).all()


def test_batched_and_per_env_agree():
    n, steps = 6, 12
    g = th.Generator().manual_seed(3)
    seq = [th.softmax(2 * th.randn(2, n, A, generator=g), -1) for _ in range(steps)]
    starts = [np.array([t == 0 or (t == 5 and e % 2 == 0) for e in range(n)]) for t in range(steps)]
    pi = th.tensor([[0.5, 0.3, 0.2]])
    batched = _setup(DisagreementOptions(FakePriors(lambda t: seq[t]), alpha=4, beta=0.4, entropy_offset=-10), n)
    out_b = [batched(None, pi.expand(n, A), [{}] * n, starts[t]) for t in range(steps)]
    for e in range(n):
        single = _setup(DisagreementOptions(FakePriors(lambda t: seq[t][:, e:e + 1]), alpha=4, beta=0.4,
                                            entropy_offset=-10), 1)
        for t in range(steps):
            s = single(None, pi, [{}], starts[t][e:e + 1])
            assert th.allclose(s.mu[0], out_b[t].mu[e], atol=1e-6) and s.tags[0] == out_b[t].tags[e]


def test_room_sensor_follows_only_outside_the_goal_room():
    n = 4
    b = _setup(RoomSensorOptions(FakePriors(_priors(DISAGREE, n)), entropy_offset=-10, seed=0), n)
    infos = [{"room": "corridor", "goal_room": "bathroom"}, {"room": "bathroom", "goal_room": "bathroom"},
             {"room": "kitchen", "goal_room": "bathroom"}, {}]
    step = b(None, UNIFORM.expand(n, A), infos, np.zeros(n, dtype=bool))
    assert step.tags.tolist() == ["prior", "explore", "prior", "prior"]
    assert th.allclose(step.mu[1], UNIFORM[0]) and not th.allclose(step.mu[0], UNIFORM[0])


def test_parameters_out_of_range_are_refused():
    with pytest.raises(ValueError, match="beta"):
        DisagreementOptions(FakePriors(_priors(AGREE, 1)), beta=-0.1)
    with pytest.raises(ValueError, match="alpha"):
        DisagreementOptions(FakePriors(_priors(AGREE, 1)), alpha=0)


class _ImageEnv:
    """The smallest image env SB3's CNN policies accept (models are only built, never trained)."""

    def __new__(cls):
        import gymnasium as gym
        from gymnasium import spaces

        class Env(gym.Env):
            observation_space = spaces.Box(0, 255, (36, 36, 3), np.uint8)
            action_space = spaces.Discrete(3)

            def reset(self, seed=None, options=None):
                return self.observation_space.sample(), {}

            def step(self, action):
                return self.observation_space.sample(), 0.0, False, False, {}

        return Env()


def test_prior_probabilities_equal_each_policys_own_distribution():
    """Priors of different algorithms that share one converted batch each give what their own
    get_distribution gives (an image batch preprocessed twice would not)."""
    from stable_baselines3 import PPO

    from sb3_disagree.acer import ACER
    from sb3_disagree.options.priors import PriorSet

    priors = [ACER("CnnPolicy", _ImageEnv(), seed=0), PPO("CnnPolicy", _ImageEnv(), seed=1),
              ACER("CnnPolicy", _ImageEnv(), seed=2)]
    obs = np.random.default_rng(0).integers(0, 256, (4, 3, 36, 36), dtype=np.uint8)
    got = PriorSet(priors).probs(obs)
    for i, prior in enumerate(priors):
        with th.no_grad():
            expected = prior.policy.get_distribution(prior.policy.obs_to_tensor(obs)[0]).distribution.probs
        assert th.equal(got[i], expected), i


def _empirical(steps, n_actions=A):
    """Per step: the frequency of each action over the batch of envs."""
    return [np.bincount(np.asarray(s.actions), minlength=n_actions) / len(s.actions) for s in steps]


def test_jump_start_guides_the_first_h_steps_with_an_exact_mu():
    from collections import deque

    from sb3_disagree.options import JumpStart

    n = 3000
    prior_probs = _priors(DISAGREE, n)
    pi = th.tensor([[0.1, 0.2, 0.7]]).expand(n, A)
    model = SimpleNamespace(n_envs=n, device=th.device("cpu"), ep_success_buffer=deque(maxlen=100))
    b = JumpStart(FakePriors(prior_probs), horizon=3, stages=3, window=5)
    b.setup(model)
    starts = np.ones(n, dtype=bool)
    steps = []
    for _ in range(5):
        steps.append(b(None, pi, [{}] * n, starts))
        starts = np.zeros(n, dtype=bool)
    mix = prior_probs.mean(0)[0]
    for t, (step, freq) in enumerate(zip(steps, _empirical(steps))):
        expected = mix if t < 3 else pi[0]
        assert th.allclose(step.mu, expected.expand(n, A)) and (step.tags == ("prior" if t < 3 else "explore")).all()
        assert np.allclose(freq, expected.numpy(), atol=0.03), (t, freq)  # the actions are draws from mu
        assert th.allclose(step.teacher, mix.expand(n, A)) and step.followed.mean() == (t < 3)
    # The curriculum: after `window` ended episodes whose success is within tolerance of the best, h steps down.
    model.ep_success_buffer.extend([1.0] * 5)
    b.ended = 0
    b(None, pi, [{}] * n, np.ones(n, dtype=bool))  # n episodes end here
    assert b.stage == 1 and b.h == 2
    model.ep_success_buffer.extend([0.0] * 5)  # success fell far below the best: no advance
    b(None, pi, [{}] * n, np.ones(n, dtype=bool))
    assert b.stage == 1


def test_prior_teacher_acts_with_the_policy_and_offers_the_priors_mixture():
    from sb3_disagree.options import PriorTeacher

    n = 3000
    prior_probs = _priors(AGREE, n)
    pi = th.tensor([[0.2, 0.5, 0.3]]).expand(n, A)
    b = _setup(PriorTeacher(FakePriors(prior_probs), per_rollout=False), n)
    step = b(None, pi, [{}] * n, np.ones(n, dtype=bool))
    assert th.allclose(step.mu, pi) and np.allclose(_empirical([step])[0], pi[0].numpy(), atol=0.03)
    assert th.allclose(step.teacher, prior_probs.mean(0)) and not step.followed.any()
    # By default the teachers come once per rollout, one row per step, and the steps carry none.
    b = _setup(PriorTeacher(FakePriors(prior_probs)), n)
    b.rollout_start()
    steps = [b(None, pi, [{}] * n, np.ones(n, dtype=bool)) for _ in range(3)]
    assert all(s.teacher is None for s in steps) and th.allclose(steps[0].mu, pi)
    teacher = b.rollout_teacher()
    assert teacher.shape == (3, n, A) and np.allclose(teacher, prior_probs.mean(0).numpy())
    assert b.rollout_teacher() is None  # handed over once


def test_prior_teacher_stops_asking_the_priors_once_distillation_has_annealed_to_zero():
    from sb3_disagree.options import PriorTeacher

    n = 4
    priors = FakePriors(_priors(AGREE, n))
    pi = th.tensor([[0.2, 0.5, 0.3]]).expand(n, A)
    model = SimpleNamespace(n_envs=n, device=th.device("cpu"), weight=0.5)
    model.distill_weight = lambda: model.weight
    b = PriorTeacher(priors, per_rollout=False)
    b.setup(model)
    assert b(None, pi, [{}] * n, np.ones(n, dtype=bool)).teacher is not None and priors.step == 1
    model.weight = 0.0
    step = b(None, pi, [{}] * n, np.zeros(n, dtype=bool))
    assert step.teacher is None and priors.step == 1  # the priors were not run
    assert th.allclose(step.mu, pi)
    # Once per rollout: the taught step gets its row, the step after the annealing a row of zeros.
    b = PriorTeacher(priors)
    b.setup(model)
    model.weight = 0.5
    b.rollout_start()
    b(None, pi, [{}] * n, np.ones(n, dtype=bool))
    model.weight = 0.0
    b(None, pi, [{}] * n, np.zeros(n, dtype=bool))
    teacher = b.rollout_teacher()
    assert priors.step == 2 and np.allclose(teacher[0], priors.fn(0).mean(0).numpy()) and not teacher[1].any()
    b.rollout_start()
    b(None, pi, [{}] * n, np.zeros(n, dtype=bool))
    assert b.rollout_teacher() is None and priors.step == 2  # a rollout with no teaching runs no prior


def test_greedy_phase_acts_by_the_argmax_with_an_exact_mu_after_its_start():
    from sb3_disagree.finish.greedy_phase import GreedyPhase
    from sb3_disagree.options import PriorTeacher

    n = 3000
    prior_probs = _priors(AGREE, n)
    pi = th.tensor([[0.2, 0.5, 0.3]]).expand(n, A)
    model = SimpleNamespace(n_envs=n, device=th.device("cpu"), num_timesteps=0)
    b = GreedyPhase(PriorTeacher(FakePriors(prior_probs), per_rollout=False), start=100, epsilon=0.2)
    b.setup(model)
    before = b(None, pi, [{}] * n, np.ones(n, dtype=bool))
    assert th.allclose(before.mu, pi)  # the inner behaviour's step, untouched
    model.num_timesteps = 100
    during = b(None, pi, [{}] * n, np.zeros(n, dtype=bool))
    expected = th.tensor([0.8 * 0 + 0.2 * 0.2, 0.8 + 0.2 * 0.5, 0.2 * 0.3])  # (1 - eps) onehot(argmax) + eps pi
    assert th.allclose(during.mu, expected.expand(n, A)) and th.allclose(during.mu.sum(-1), th.ones(n))
    assert np.allclose(_empirical([during])[0], expected.numpy(), atol=0.03)  # the actions are draws from mu
    assert th.allclose(during.teacher, prior_probs.mean(0)) and (during.tags == "greedy").all()
    with pytest.raises(ValueError):
        GreedyPhase(PriorTeacher(FakePriors(prior_probs)), start=0, epsilon=0.0)


def test_greedy_phase_reports_no_prior_usage_for_the_steps_it_took_over():
    from stable_baselines3.common.logger import Logger

    from sb3_disagree.behaviour import OnPolicyBehaviour
    from sb3_disagree.finish.greedy_phase import GreedyPhase

    class Half(OnPolicyBehaviour):  # an inner behaviour that would have followed priors half the time
        def record(self, logger):
            logger.record("prior/usage", 0.5)

    model = SimpleNamespace(num_timesteps=0)
    b = GreedyPhase(Half(), start=2, epsilon=0.2)
    b.setup(model)
    pi = th.tensor([[0.2, 0.5, 0.3]])
    for t in range(4):  # two steps before the phase, two in it
        model.num_timesteps = t
        b(None, pi, [{}], np.zeros(1, dtype=bool))
    logger = Logger(None, [])
    b.record(logger)
    assert logger.name_to_value["behaviour/greedy_phase"] == 0.5 and logger.name_to_value["prior/usage"] == 0.25
