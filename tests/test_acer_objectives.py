"""The ACER targets and terms against hand-computed values and direct computations."""

import numpy as np
import pytest
import torch as th

from sb3_disagree.acer.objectives import EPS, policy_terms, retrace_targets, trust_region_project


def retrace_loop(rewards, dones, q_taken, values, rho, last_values, gamma):
    """The reference recursion, written as a loop over time."""
    q_ret = last_values.clone()
    out = th.zeros_like(rewards)
    for t in reversed(range(rewards.shape[0])):
        q_ret = rewards[t] + gamma * (1 - dones[t]) * q_ret
        out[t] = q_ret
        q_ret = th.clamp(rho[t], max=1.0) * (q_ret - q_taken[t]) + values[t]
    return out


def test_retrace_hand_computed_termination_and_truncation():
    gamma = 0.5
    # env 0 terminates at t=1; env 1 is cut by a time limit at t=0, where V(true last obs) = 3 is folded
    # into the reward as r + gamma * V = 1 + 0.5 * 3.
    rewards = th.tensor([[1.0, 1.0 + gamma * 3.0], [2.0, 2.0], [3.0, 3.0]])
    dones = th.tensor([[0.0, 1.0], [1.0, 0.0], [0.0, 0.0]])
    q_taken = th.tensor([[0.5, 1.0], [1.0, 1.0], [2.0, 1.0]])
    values = th.tensor([[1.0, 1.0], [1.5, 1.0], [2.5, 1.0]])
    rho = th.tensor([[2.0, 1.0], [0.5, 1.0], [1.0, 0.25]])
    last_values = th.tensor([4.0, 2.0])
    # By hand, env 0: Qhat_2 = 3 + .5*4 = 5; Q_ret = 1*(5-2)+2.5 = 5.5; Qhat_1 = 2 (terminal);
    #   Q_ret = .5*(2-1)+1.5 = 2; Qhat_0 = 1 + .5*2 = 2.
    # env 1: Qhat_2 = 3 + .5*2 = 4; Q_ret = .25*(4-1)+1 = 1.75; Qhat_1 = 2 + .5*1.75 = 2.875;
    #   Q_ret = 2.875; Qhat_0 = 2.5 (truncated: bootstrap only through the folded value).
    expected = th.tensor([[2.0, 2.5], [2.0, 2.875], [5.0, 4.0]])
    got = retrace_targets(rewards, dones, q_taken, values, rho, last_values, gamma)
    assert th.allclose(got, expected, atol=1e-6)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_retrace_matches_reference_loop(seed):
    g = th.Generator().manual_seed(seed)
    T, E = 20, 6
    rewards = th.randn(T, E, generator=g)
    dones = (th.rand(T, E, generator=g) < 0.15).float()
    q_taken, values = th.randn(T, E, generator=g), th.randn(T, E, generator=g)
    rho = th.rand(T, E, generator=g) * 3
    last = th.randn(E, generator=g)
    expected = retrace_loop(rewards, dones, q_taken, values, rho, last, 0.99)
    got = retrace_targets(rewards, dones, q_taken, values, rho, last, 0.99)
    assert th.allclose(got, expected, atol=1e-5)


def test_policy_terms_match_direct_computation():
    g = th.Generator().manual_seed(0)
    N, A, c = 7, 4, 1.5
    probs = th.softmax(th.randn(N, A, generator=g), -1)
    mu = th.softmax(3 * th.randn(N, A, generator=g), -1)
    actions = th.randint(A, (N,), generator=g)
    q = th.randn(N, A, generator=g)
    v = (probs * q).sum(-1)
    q_ret = th.randn(N, generator=g)
    rho = probs / (mu + EPS)
    terms = policy_terms(probs, actions, q, v, q_ret, rho, c)
    for i in range(N):
        a = int(actions[i])
        r = float(probs[i, a] / (mu[i, a] + EPS))
        expected_is = np.log(float(probs[i, a]) + EPS) * min(c, r) * float(q_ret[i] - v[i])
        expected_bc = sum(
            np.log(float(probs[i, b]) + EPS) * max(0.0, 1 - c / (float(rho[i, b]) + EPS)) * float(probs[i, b])
            * float(q[i, b] - v[i])
            for b in range(A)
        )
        expected_h = -sum(float(probs[i, b]) * np.log(float(probs[i, b]) + EPS) for b in range(A))
        assert terms.truncated_is[i].item() == pytest.approx(expected_is, rel=1e-5, abs=1e-6)
        assert terms.bias_correction[i].item() == pytest.approx(expected_bc, rel=1e-5, abs=1e-6)
        assert terms.entropy[i].item() == pytest.approx(expected_h, rel=1e-5)
    # Some bias-correction terms are active (rho > c somewhere), or the test checks nothing.
    assert (rho > c).any() and (terms.bias_correction != 0).any()


def test_policy_terms_gradient_flows_only_through_log_f():
    probs = th.tensor([[0.2, 0.5, 0.3]], requires_grad=True)
    q = th.tensor([[1.0, 2.0, 0.0]])
    v = (probs * q).sum(-1).detach()
    rho = th.tensor([[0.5, 4.0, 1.0]])
    terms = policy_terms(probs, th.tensor([1]), q, v, th.tensor([3.0]), rho, c=2.0)
    (grad,) = th.autograd.grad(terms.truncated_is.sum(), probs)
    # d/df(a) [log(f(a_t) + eps) * w] = w / (f(a_t) + eps) at a_t, 0 elsewhere; w = min(2, 4) * (3 - v)
    w = 2.0 * (3.0 - v.item())
    assert th.allclose(grad, th.tensor([[0.0, w / (0.5 + EPS), 0.0]]), atol=1e-5)


def _random_kg(seed, n=256, a=5, scale=5.0):
    g = th.Generator().manual_seed(seed)
    f = th.softmax(th.randn(n, a, generator=g), -1)
    avg = th.softmax(th.randn(n, a, generator=g), -1)
    k = -avg / (f + EPS)
    return scale * th.randn(n, a, generator=g), k


@pytest.mark.parametrize("delta", [0.1, 1.0])
def test_trust_region_keeps_k_dot_z_below_delta(delta):
    g, k = _random_kg(0)
    z, scale = trust_region_project(g, k, delta)
    kz = (k * z).sum(-1)
    assert (kz <= delta + 1e-4 * (1 + delta)).all()
    active = (k * g).sum(-1) > delta
    assert active.any() and (~active).any()
    # Where it acts, it lands on the boundary and moves along k only.
    assert th.allclose(kz[active], th.full_like(kz[active], delta), rtol=1e-4, atol=1e-4)
    diff = (g - z)[active]
    cos = (diff * k[active]).sum(-1) / (diff.norm(dim=-1) * k[active].norm(dim=-1))
    assert th.allclose(cos, th.ones_like(cos), atol=1e-4)
    # Elsewhere it is the identity.
    assert th.equal(z[~active], g[~active]) and (scale[~active] == 0).all()


def test_trust_region_identity_when_inactive():
    g, k = _random_kg(1, scale=1e-3)
    z, scale = trust_region_project(g, k, 1.0)
    assert th.equal(z, g) and (scale == 0).all()
