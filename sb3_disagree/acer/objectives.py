"""
The ACER targets and policy-gradient terms as pure tensor functions (Wang et al. 2016).

Tensors are time-major: ``(n_steps, n_envs)`` for per-step scalars and ``(n_steps, n_envs, n_actions)``
for per-action quantities. Each function is tested against a direct computation.
"""

from typing import NamedTuple

import torch as th

EPS = 1e-6


def retrace_targets(
    rewards: th.Tensor,
    dones: th.Tensor,
    q_taken: th.Tensor,
    values: th.Tensor,
    rho_taken: th.Tensor,
    last_values: th.Tensor,
    gamma: float,
) -> th.Tensor:
    """
    Retrace targets with the trace truncated at 1, solved as a linear recurrence without a loop over time.

    The reference recursion, for t = T-1 .. 0, starting from ``Q_ret = V(x_T)``::

        Q_ret   = r_t + gamma * (1 - done_t) * Q_ret
        Qhat_t  = Q_ret
        Q_ret   = min(1, rho_t) * (Q_ret - Q_t(a_t)) + V_t

    is ``Qhat_t = b_t + a_t * Qhat_{t+1}`` with ``a_t = gamma (1 - done_t) cbar_{t+1}`` and
    ``b_t = r_t + gamma (1 - done_t) (V_{t+1} - cbar_{t+1} Q_{t+1}(a_{t+1}))`` (``V_T`` the bootstrap,
    ``cbar_T = 0``), whose solution ``Qhat_t = sum_{s>=t} (prod_{t<=u<s} a_u) b_s`` is a masked
    cumulative product. Exact with zeros (episode ends), which a log-space product would not be.

    :param rewards: r_t, shape (T, E); a time-limit truncation's bootstrap value is already folded in
    :param dones: 1.0 where the episode ended at step t (terminated or truncated), shape (T, E)
    :param q_taken: Q_t(a_t), shape (T, E)
    :param values: V_t = sum_a pi_t(a) Q_t(a), shape (T, E)
    :param rho_taken: pi_t(a_t) / mu_t(a_t), shape (T, E)
    :param last_values: V(x_T), the bootstrap after the segment, shape (E,)
    :param gamma: Discount factor
    :return: Qhat_t, shape (T, E)
    """
    n_steps = rewards.shape[0]
    discount = gamma * (1.0 - dones)
    c_bar = th.clamp(rho_taken, max=1.0)
    zero = th.zeros_like(last_values).unsqueeze(0)
    next_values = th.cat([values[1:], last_values.unsqueeze(0)], dim=0)
    next_c = th.cat([c_bar[1:], zero], dim=0)
    next_q = th.cat([q_taken[1:], zero], dim=0)
    b = rewards + discount * (next_values - next_c * next_q)
    a = discount * next_c
    # prods[e, t, s] = prod_{u=t}^{s-1} a_u for s >= t (1 on the diagonal), 0 below it.
    a_e = a.T  # (E, T)
    idx = th.arange(n_steps, device=rewards.device)
    upper = idx.view(1, -1) >= idx.view(-1, 1)  # [t, u]: u >= t
    factors = th.where(upper, a_e.unsqueeze(1), th.ones_like(a_e).unsqueeze(1))
    cum = th.cumprod(factors, dim=-1)  # [e, t, u] = prod_{t<=u'<=u} a_u'
    prods = th.cat([th.ones_like(cum[..., :1]), cum[..., :-1]], dim=-1) * upper
    return th.einsum("ets,es->te", prods, b.T)


class PolicyTerms(NamedTuple):
    """Per-state policy objective terms of ACER (each a gain to maximise), shape (N,)."""

    truncated_is: th.Tensor
    bias_correction: th.Tensor
    entropy: th.Tensor


def policy_terms(
    probs: th.Tensor,
    actions: th.Tensor,
    q_values: th.Tensor,
    values: th.Tensor,
    q_ret: th.Tensor,
    rho: th.Tensor,
    c: float,
) -> PolicyTerms:
    """
    Truncated importance sampling with bias correction, and the entropy, as functions of the
    probability vector ``f = pi(.|x)`` (the trust region differentiates through ``f``)::

        g_f  = log f(a_t) * sg(min(c, rho_t) * (Qhat_t - V_t))
        g_bc = sum_a log f(a) * sg([1 - c / rho(a)]_+ * f(a) * (Q(a) - V))
        H    = -sum_a f(a) log f(a)

    :param probs: f, shape (N, A), carrying the gradient
    :param actions: a_t, shape (N,)
    :param q_values: Q(x, .), shape (N, A)
    :param values: V(x), shape (N,)
    :param q_ret: Retrace targets Qhat, shape (N,)
    :param rho: pi / mu for every action, shape (N, A)
    :param c: Importance weight truncation
    :return: The three gains per state
    """
    log_f = th.log(probs + EPS)
    idx = actions.long().unsqueeze(-1)
    log_f_taken = log_f.gather(-1, idx).squeeze(-1)
    rho_taken = rho.gather(-1, idx).squeeze(-1)
    with th.no_grad():
        weight = th.clamp(rho_taken, max=c) * (q_ret - values)
        weight_bc = th.relu(1.0 - c / (rho + EPS)) * probs * (q_values - values.unsqueeze(-1))
    truncated_is = log_f_taken * weight
    bias_correction = (log_f * weight_bc).sum(-1)
    entropy = -(probs * log_f).sum(-1)
    return PolicyTerms(truncated_is, bias_correction, entropy)


def trust_region_project(g: th.Tensor, k: th.Tensor, delta: float) -> tuple[th.Tensor, th.Tensor]:
    """
    Efficient trust region: the closest ``z`` to ``g`` with ``k . z <= delta``, per state::

        z* = g - max(0, (k . g - delta) / |k|^2) * k

    The reference adds eps to ``|k|^2``, which lets ``k . z*`` overshoot delta by
    ``(k . g - delta) eps / (|k|^2 + eps)``; ``|k|^2 >= sum_a pi_avg(a)^2 > 0`` needs no eps.

    :param g: Ascent direction of the policy objective with respect to f, shape (N, A)
    :param k: Gradient of KL(pi_avg || f) with respect to f, shape (N, A)
    :param delta: Trust region bound
    :return: z* and the per-state scale of the correction (0 where the constraint is inactive)
    """
    scale = th.clamp(((k * g).sum(-1) - delta) / (k * k).sum(-1).clamp_min(1e-12), min=0.0)
    return g - scale.unsqueeze(-1) * k, scale


def distillation_loss(log_probs: th.Tensor, teacher: th.Tensor, weights: th.Tensor) -> th.Tensor:
    """
    The kickstarting term (Schmitt et al. 2018): the cross-entropy from a teacher's distribution to the
    policy, weighted per step and averaged over the batch. Its gradient is that of ``KL(teacher || pi)``.

    ``L = (1 / N) sum_t w_t * (- sum_a teacher_t(a) log pi_t(a))``

    :param log_probs: log pi_t(.), shape (N, A)
    :param teacher: teacher_t(.), shape (N, A)
    :param weights: w_t >= 0, shape (N,)
    """
    return (weights * -(teacher * log_probs).sum(-1)).mean()
