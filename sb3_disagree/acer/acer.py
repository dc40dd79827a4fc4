"""ACER: Sample Efficient Actor-Critic with Experience Replay (Wang et al. 2016), discrete actions."""

import contextlib
import pathlib
import zipfile
from typing import Any, Callable, ClassVar, Optional, TypeVar, Union

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.save_util import load_from_pkl
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule
from stable_baselines3.common.utils import obs_as_tensor
from stable_baselines3.common.vec_env import VecEnv

from sb3_disagree.acer.buffers import Segment, SegmentReplayBuffer
from sb3_disagree.acer.memory import push_frames
from sb3_disagree.acer.objectives import EPS, distillation_loss, policy_terms, retrace_targets, trust_region_project
from sb3_disagree.acer.overlap import overlapped_updates
from sb3_disagree.acer.policies import ACERPolicy, CnnPolicy, MlpPolicy, compact_averages
from sb3_disagree.behaviour import BehaviourPolicy, BehaviourStep, OnPolicyBehaviour

SelfACER = TypeVar("SelfACER", bound="ACER")


def as_schedule(value: Union[float, str, Schedule]) -> Schedule:
    """
    A weight as a function of the remaining progress (1 at the start, 0 at the end).

    :param value: A constant, a schedule, or ``"lin_<x>"``: x at the start, falling linearly to 0
    """
    if callable(value):
        return value
    if isinstance(value, str):
        if not value.startswith("lin_"):
            raise ValueError(f"a schedule string must read 'lin_<start>', got {value!r}")
        start = float(value[4:])
        return lambda progress_remaining: progress_remaining * start
    constant = float(value)
    return lambda _: constant


class ACER(BaseAlgorithm):
    """
    Actor-Critic with Experience Replay (ACER) for discrete actions, with a behaviour-policy hook.

    Each iteration collects ``n_steps`` per env with the behaviour policy, stores the segment with the
    behaviour distribution mu, does one on-policy update on it, then ``Poisson(replay_ratio)`` updates
    on segments drawn from the replay buffer once it holds ``replay_start`` transitions.

    Paper: https://arxiv.org/abs/1611.01224. The implementation details, each with its equation, are
    listed in ``docs/acer.md``.

    :param policy: The policy model to use (MlpPolicy, CnnPolicy, ...)
    :param env: The environment to learn from (if registered in Gym, can be str)
    :param learning_rate: The learning rate: a constant, a function of the remaining progress (from 1 to 0), or
        ``"lin_<x>"`` for x falling linearly to 0 over the budget (the reference ACER's schedule)
    :param n_steps: Length of a segment: env steps per env between updates
    :param gamma: Discount factor
    :param buffer_size: Replay capacity in env transitions over all envs, stored as whole segments
    :param replay_ratio: Mean of the Poisson number of replay updates after each on-policy update
        (0 gives on-policy ACER)
    :param replay_start: Number of stored transitions (over all envs) before replay updates begin
    :param q_coef: Weight of the Q-value loss
    :param reward_scale: Rewards are multiplied by this in the targets (Q is learned in scaled units)
    :param ent_coef: Weight of the entropy bonus: a constant, a function of the remaining progress (from 1 to
        0), or ``"lin_<x>"`` for a weight falling linearly from x to 0 over the budget (rl-zoo3's notation)
    :param max_grad_norm: Clip of the global gradient norm
    :param c: Truncation of the importance weights in the policy gradient (bias correction beyond it)
    :param trust_region: Whether to use the efficient trust region against the average policy network
    :param alpha: Decay of the average policy network, updated after every optimizer step
    :param ema_decay: Decay of a slow moving average of the policy's weights, updated after every optimizer step
        and acted with by ``predict`` (what ``evaluate_policy`` and a user of the saved model see); rollouts and
        updates use the current weights. 0 (the default) keeps none: ``predict`` uses the current weights
    :param delta: Bound of the trust region
    :param distill_coef: Weight of the distillation term toward the behaviour's teacher (the priors' mixture;
        kickstarting), 0 for none
    :param distill_steps: The distillation weight falls linearly to 0 at this many env steps (0: constant)
    :param distill_states: "followed" distils on the steps where the teacher chose the action, "all" on every
        step that has a teacher
    :param features_dtype: "bfloat16" computes the features extractor's passes in ACER's updates (and the values
        of truncated episodes' last states) under ``torch.autocast`` in bfloat16; the heads, targets and losses stay
        float32, as do acting (rollouts, ``predict``) and the weights. None or "float32" (the default): all float32
    :param behaviour: The behaviour policy that chooses the actions during rollouts; sampling from the
        current policy if None. It is not saved with the model.
    :param overlap: Run the replay updates of segment k in a second thread while segment k + 1 is
        collected (the on-policy update of segment k comes first, with all threads): the rollouts then
        miss the latest segment's replay updates, which the stored mu and the importance weights correct
        for; the number of updates is unchanged, at most ``ceil(replay_ratio) + 1`` of them per segment
        (the rest of a large Poisson draw is carried to the next). ``self.policy`` (what callbacks,
        ``predict`` and ``save`` see) is the acting copy, synchronised with the learner, optimizer state
        included, after every on-policy update and when ``learn`` ends or is interrupted.
    :param average_ahead: With ``overlap``, the rollout thread draws each segment's replay batches and computes the
        trust region's reference on them (the average network's probabilities) before handing them to the worker,
        which then does one forward pass less per replay update; the reference is then up to
        ``ceil(replay_ratio)`` updates older (docs/acer.md, item 24). Needs ``overlap``
    :param stats_window_size: Window size for the rollout logging, number of episodes to average
    :param tensorboard_log: The log location for tensorboard (if None, no logging)
    :param policy_kwargs: Additional arguments to be passed to the policy on creation
    :param verbose: Verbosity level: 0 for no output, 1 for info messages, 2 for debug messages
    :param seed: Seed for the pseudo random generators
    :param device: Device (cpu, cuda, ...) on which the code should be run
    :param _init_setup_model: Whether or not to build the network at the creation of the instance
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {
        "MlpPolicy": MlpPolicy,
        "CnnPolicy": CnnPolicy,
    }
    policy: ACERPolicy
    replay_buffer: SegmentReplayBuffer

    def __init__(
        self,
        policy: Union[str, type[ACERPolicy]],
        env: Union[GymEnv, str],
        learning_rate: Union[float, str, Schedule] = 7e-4,
        n_steps: int = 20,
        gamma: float = 0.99,
        buffer_size: int = 50_000,
        replay_ratio: float = 4.0,
        replay_start: int = 1_000,
        q_coef: float = 0.5,
        reward_scale: float = 1.0,
        ent_coef: Union[float, str, Schedule] = 0.01,
        max_grad_norm: float = 10.0,
        c: float = 10.0,
        trust_region: bool = True,
        alpha: float = 0.99,
        ema_decay: float = 0.0,
        delta: float = 1.0,
        distill_coef: float = 0.0,
        distill_steps: int = 0,
        distill_states: str = "followed",
        features_dtype: Optional[str] = None,
        behaviour: Optional[BehaviourPolicy] = None,
        overlap: bool = False,
        average_ahead: bool = False,
        stats_window_size: int = 100,
        tensorboard_log: Optional[str] = None,
        policy_kwargs: Optional[dict[str, Any]] = None,
        verbose: int = 0,
        seed: Optional[int] = None,
        device: Union[th.device, str] = "auto",
        _init_setup_model: bool = True,
    ) -> None:
        super().__init__(
            policy,
            env,
            learning_rate=learning_rate,
            policy_kwargs=policy_kwargs,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            device=device,
            support_multi_env=True,
            seed=seed,
            supported_action_spaces=(spaces.Discrete,),
        )
        self.n_steps = n_steps
        self.gamma = gamma
        self.buffer_size = buffer_size
        self.replay_ratio = replay_ratio
        self.replay_start = replay_start
        self.q_coef = q_coef
        self.reward_scale = reward_scale
        self.ent_coef = ent_coef
        self.max_grad_norm = max_grad_norm
        self.c = c
        self.trust_region = trust_region
        self.alpha = alpha
        self.check_settings(reward_scale=reward_scale, ema_decay=ema_decay, distill_coef=distill_coef,
                            distill_steps=distill_steps, distill_states=distill_states, features_dtype=features_dtype,
                            overlap=overlap, average_ahead=average_ahead)
        self.ema_decay = ema_decay
        self.delta = delta
        as_schedule(ent_coef), as_schedule(learning_rate)  # refuse what is not a weight
        self.features_dtype = features_dtype
        self.distill_coef = distill_coef
        self.distill_steps = distill_steps
        self.distill_states = distill_states
        self.behaviour = behaviour
        self.overlap = overlap
        self.average_ahead = average_ahead
        if _init_setup_model:
            self._setup_model()

    @staticmethod
    def check_settings(reward_scale: Any = 1.0, ema_decay: Any = 0.0, distill_coef: Any = 0.0, distill_steps: Any = 0,
                       distill_states: Any = "followed", features_dtype: Any = None, overlap: Any = False,
                       average_ahead: Any = False, **_: Any) -> None:
        """
        Refuse settings ACER cannot train with, in one line that names the setting: the one check of them (a run's
        configuration is checked with it before anything is written).
        """
        def number(value: Any) -> bool:
            return isinstance(value, (int, float)) and not isinstance(value, bool)

        if not number(reward_scale) or not reward_scale > 0:
            raise ValueError(f"reward_scale must be a number > 0, got {reward_scale!r}")
        if not number(ema_decay) or not 0 <= ema_decay < 1:
            raise ValueError(f"ema_decay must be a number in [0, 1), got {ema_decay!r}")
        if distill_states not in ("followed", "all"):
            raise ValueError(f"distill_states must be followed or all, got {distill_states!r}")
        if not number(distill_coef) or not number(distill_steps) or distill_coef < 0 or distill_steps < 0:
            raise ValueError(f"distill_coef and distill_steps must be numbers >= 0, got {distill_coef!r} and "
                             f"{distill_steps!r}")
        if features_dtype not in (None, "float32", "bfloat16"):
            raise ValueError(f"features_dtype must be float32 or bfloat16, got {features_dtype!r}")
        if average_ahead and not overlap:
            raise ValueError("average_ahead computes the replays' reference while the worker replays: it needs the "
                             "overlapped loop (overlap)")

    def _setup_model(self) -> None:
        if isinstance(self.observation_space, spaces.Dict):
            raise ValueError("ACER does not support Dict observation spaces")
        self._setup_lr_schedule()
        self.set_random_seed(self.seed)
        policy_kwargs = {**self.policy_kwargs, **({"ema": True} if self.ema_decay > 0 else {})}
        self.policy = self.policy_class(  # type: ignore[assignment]
            self.observation_space, self.action_space, self.lr_schedule, **policy_kwargs
        )
        self.policy = self.policy.to(self.device)
        self.policy.features_autocast = th.bfloat16 if self.features_dtype == "bfloat16" else None
        self.replay_buffer = SegmentReplayBuffer(
            self.buffer_size, self.n_steps, self.n_envs, self.policy.net_observation_space, int(self.action_space.n),
            frame_stack=self.policy.frame_stack,
        )
        self._last_infos: list[dict[str, Any]] = [{} for _ in range(self.n_envs)]
        self._last_stack: Optional[np.ndarray] = None  # the policy's input: the last frame_stack observations
        self._ent_coef_schedule = as_schedule(self.ent_coef)
        self.last_rollout_tags: Optional[np.ndarray] = None

    def _setup_lr_schedule(self) -> None:
        # SB3's constants and schedules, and rl-zoo3's "lin_<x>" as the ent_coef takes it.
        self.lr_schedule = as_schedule(self.learning_rate)

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "behaviour", "_last_infos", "_last_stack", "_ent_coef_schedule",
                "last_rollout_tags"]

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        return ["policy", "policy.optimizer"], []

    def get_parameters(self) -> dict[str, dict]:
        """
        SB3's parameters (what ``save`` writes), the policy's without the average networks' entries that equal the
        current network's: a prior made by imitation holds ``average_net == net``, and a second copy would double
        its file. The policy's ``load_state_dict`` takes them back from ``net``, so a save/load round trip is exact.
        """
        params = super().get_parameters()
        params["policy"] = compact_averages(params["policy"])
        return params

    @property
    def behaviour_policy(self) -> BehaviourPolicy:
        """The behaviour in use: the one given, or sampling from the current policy."""
        if self.behaviour is None:
            self.behaviour = OnPolicyBehaviour()
        return self.behaviour

    # ------------------------------------------------------------------ rollouts

    def _checked_behaviour_step(self, obs: Any, probs: th.Tensor) -> tuple[np.ndarray, np.ndarray, BehaviourStep]:
        """Ask the behaviour for this step's actions and check that mu is a distribution covering them."""
        step = self.behaviour_policy(obs, probs, self._last_infos, self._last_episode_starts)
        actions = th.as_tensor(step.actions, device=self.device).long().reshape(-1)
        mu = th.as_tensor(step.mu, dtype=th.float32, device=self.device)
        name = type(self.behaviour_policy).__name__
        if mu.shape != probs.shape or actions.shape[0] != probs.shape[0]:
            raise ValueError(
                f"Behaviour {name} returned actions of shape {tuple(actions.shape)} and mu of shape {tuple(mu.shape)}; "
                f"expected ({probs.shape[0]},) and {tuple(probs.shape)}"
            )
        mu_taken = mu.gather(1, actions.unsqueeze(1)).squeeze(1)
        not_distribution = (mu.amin(-1) < 0) | ((mu.sum(-1) - 1.0).abs() > 1e-4)
        if bool((not_distribution | (mu_taken <= 0)).any()):  # one check on the hot path, details when it fails
            if bool(not_distribution.any()):
                raise ValueError(f"Behaviour {name} returned a mu that is not a probability distribution per env")
            bad = th.nonzero(mu_taken <= 0).flatten().tolist()
            raise ValueError(
                f"Behaviour {name} took actions with mu(a_t) = 0 in envs {bad}: importance weights pi/mu would be "
                "unbounded. Report the distribution the actions were drawn from, with positive mass on the taken "
                "action (mix a deterministic choice with some mass on every action)."
            )
        return actions.cpu().numpy(), mu.cpu().numpy(), step

    def _timeout_values(self, dones: np.ndarray, infos: list[dict[str, Any]], stack: np.ndarray) -> np.ndarray:
        """V of the true last observation where a time limit cut the episode (it is bootstrapped, not terminal);
        ``stack`` is the policy's input before the step, onto which that observation is pushed."""
        values = np.zeros(len(dones), dtype=np.float32)
        idx = [
            i
            for i in np.flatnonzero(dones)
            if infos[i].get("TimeLimit.truncated", False) and infos[i].get("terminal_observation") is not None
        ]
        if idx:
            terminal = np.stack([infos[i]["terminal_observation"] for i in idx])
            terminal = push_frames(stack[idx], terminal, None, self.policy.frame_stack)
            with th.no_grad():
                logits, q = self.policy.logits_and_q(obs_as_tensor(terminal, self.device))
                values[idx] = (th.softmax(logits, -1) * q).sum(-1).cpu().numpy()
        return values

    @staticmethod
    def _infos_of_current_obs(env: VecEnv, infos: list[dict[str, Any]], dones: np.ndarray) -> list[dict[str, Any]]:
        """The infos that describe the observations the behaviour sees next: where an episode ended, the
        env was reset, and its reset info (not the last episode's final info) describes the new observation."""
        if not dones.any():
            return infos
        reset_infos = getattr(env, "reset_infos", None) or [{} for _ in infos]
        return [reset_infos[i] if done else info for i, (info, done) in enumerate(zip(infos, dones))]

    def collect_rollouts(self, env: VecEnv, callback: BaseCallback) -> Optional[Segment]:
        """
        Collect one segment of ``n_steps`` per env with the behaviour policy.

        :param env: The training environment
        :param callback: Callback called at each step (and at the beginning and end of the rollout)
        :return: The segment, or None if the callback stopped training
        """
        assert self._last_obs is not None, "No previous observation was provided"
        self.policy.set_training_mode(False)
        n_envs, n_actions = env.num_envs, int(self.action_space.n)
        k = self.policy.frame_stack
        obs_shape = self.policy.net_observation_space.shape
        if self._last_stack is None or self._last_stack.shape[0] != n_envs:
            self._last_stack = push_frames(None, self._last_obs, None, k)  # type: ignore[arg-type]
        observations = np.zeros((self.n_steps + 1, n_envs, *obs_shape), dtype=self.observation_space.dtype)
        actions_buf = np.zeros((self.n_steps, n_envs), dtype=np.int64)
        rewards_buf = np.zeros((self.n_steps, n_envs), dtype=np.float32)
        dones_buf = np.zeros((self.n_steps, n_envs), dtype=np.float32)
        timeout_buf = np.zeros((self.n_steps, n_envs), dtype=np.float32)
        mu_buf = np.zeros((self.n_steps, n_envs, n_actions), dtype=np.float32)
        tags_buf: list[Optional[np.ndarray]] = []
        teacher_buf = np.zeros((self.n_steps, n_envs, n_actions), dtype=np.float32)
        followed_buf = np.zeros((self.n_steps, n_envs), dtype=np.float32)

        callback.on_rollout_start()
        self.behaviour_policy.rollout_start()
        for step in range(self.n_steps):
            observations[step] = self._last_stack
            with th.no_grad():
                obs_tensor = obs_as_tensor(self._last_stack, self.device)
                probs = self.policy.action_probs(obs_tensor)
            # The behaviour (the priors) sees the single observation its policies were trained on.
            actions, mu, behaviour_step = self._checked_behaviour_step(self._last_obs, probs)
            tags = behaviour_step.tags

            new_obs, rewards, dones, infos = env.step(actions)
            self.num_timesteps += n_envs

            callback.update_locals(locals())
            if not callback.on_step():
                return None
            self._update_info_buffer(infos, dones)

            actions_buf[step] = actions
            rewards_buf[step] = rewards
            dones_buf[step] = dones
            mu_buf[step] = mu
            tags_buf.append(tags)
            if behaviour_step.teacher is not None:
                teacher_buf[step] = _as_numpy(behaviour_step.teacher)
                if behaviour_step.followed is not None:
                    followed_buf[step] = _as_numpy(behaviour_step.followed)
            if dones.any():
                timeout_buf[step] = self._timeout_values(dones, infos, self._last_stack)
            self._last_obs = new_obs  # type: ignore[assignment]
            self._last_stack = push_frames(self._last_stack, new_obs, dones, k)  # type: ignore[arg-type]
            self._last_episode_starts = dones
            self._last_infos = self._infos_of_current_obs(env, infos, dones)

        late = self.behaviour_policy.rollout_teacher()  # teachers computed once for the whole rollout
        if late is not None:
            teacher_buf[: len(late)] = late
        observations[self.n_steps] = self._last_stack
        self.last_rollout_tags = None if any(t is None for t in tags_buf) else np.stack(tags_buf)
        callback.update_locals(locals())
        callback.on_rollout_end()
        return Segment(observations, actions_buf, rewards_buf, dones_buf, timeout_buf, mu_buf, teacher_buf, followed_buf)

    # ------------------------------------------------------------------ updates

    def _segment_obs(self, segment: Segment) -> th.Tensor:
        """A segment's observations, its T + 1 steps of E envs flattened, the last step's E last."""
        obs = th.as_tensor(segment.observations, device=self.device)
        return obs.reshape(-1, *obs.shape[2:])

    @staticmethod
    def _average_probs(policy: ACERPolicy, obs: th.Tensor) -> th.Tensor:
        """The trust region's reference on ``obs``: the average network's action probabilities (item 12)."""
        return th.softmax(policy.average_logits(obs), dim=-1)

    def _update(self, segment: Segment, policy: Optional[ACERPolicy] = None,
                reference: Optional[th.Tensor] = None, coefs: Optional[tuple[float, float]] = None) -> dict[str, float]:
        """
        One gradient step of ``policy`` (``self.policy`` if None) on a (T, E) segment batch; returns statistics.

        :param reference: The trust region's reference on the segment's T * E states, the average network's
            probabilities (computed here from ``policy``'s average network if None)
        :param coefs: The entropy and distillation weights to use (:meth:`scheduled_coefs`; read now if None)
        """
        policy = self.policy if policy is None else policy
        ent_coef, distill_coef = self.scheduled_coefs() if coefs is None else coefs
        n_steps, n_envs = segment.actions.shape
        n = n_steps * n_envs
        obs = self._segment_obs(segment)
        actions = th.as_tensor(segment.actions, device=self.device).reshape(n)
        mu = th.as_tensor(segment.mu, device=self.device).reshape(n, -1)
        rewards = th.as_tensor(segment.rewards, device=self.device)
        dones = th.as_tensor(segment.dones, device=self.device)
        timeout_values = th.as_tensor(segment.timeout_values, device=self.device)

        logits, q_all = policy.logits_and_q(obs)
        probs_all = th.softmax(logits, dim=-1)
        values_all = (probs_all * q_all).sum(-1).detach()
        probs, q_values, values = probs_all[:n], q_all[:n], values_all[:n]
        q_taken = q_values.gather(1, actions.unsqueeze(1)).squeeze(1)

        with th.no_grad():
            rho = probs / (mu + EPS)
            rho_taken = rho.gather(1, actions.unsqueeze(1)).squeeze(1)
            q_ret = retrace_targets(
                self.reward_scale * rewards + self.gamma * timeout_values,
                dones,
                q_taken.detach().view(n_steps, n_envs),
                values.view(n_steps, n_envs),
                rho_taken.view(n_steps, n_envs),
                values_all[n:],
                self.gamma,
            ).reshape(n)
        q_loss = 0.5 * (q_ret - q_taken).pow(2).mean()

        # The policy objective as a function of the probability vector f, where the trust region acts.
        f = probs.detach().requires_grad_(True)
        terms = policy_terms(f, actions, q_values.detach(), values, q_ret, rho, self.c)
        objective = (terms.truncated_is + terms.bias_correction + ent_coef * terms.entropy).mean()
        (g,) = th.autograd.grad(objective * n, f)
        tr_scale = th.zeros(n, device=self.device)
        if self.trust_region:
            average_probs = self._average_probs(policy, obs[:n]) if reference is None else reference
            k = -average_probs / (f.detach() + EPS)
            g, tr_scale = trust_region_project(g, k, self.delta)
        loss = -(probs * g.detach()).sum() / n + self.q_coef * q_loss
        distill = th.zeros(())
        if distill_coef > 0 and segment.teacher is not None:
            teacher = th.as_tensor(segment.teacher, device=self.device).reshape(n, -1)
            has_teacher = (teacher.sum(-1) > 0).float()
            weights = has_teacher
            if self.distill_states == "followed" and segment.followed is not None:
                weights = has_teacher * th.as_tensor(segment.followed, device=self.device).reshape(n)
            distill = distillation_loss(th.log_softmax(logits[:n], dim=-1), teacher, weights)
            loss = loss + distill_coef * distill

        policy.optimizer.zero_grad()
        loss.backward()
        grad_norm = th.nn.utils.clip_grad_norm_(policy.net.parameters(), self.max_grad_norm)
        policy.optimizer.step()
        policy.update_average(self.alpha)
        policy.update_ema(self.ema_decay)
        self._n_updates += 1
        return {
            "policy_loss": -terms.truncated_is.mean().item(),
            "bias_correction_loss": -terms.bias_correction.mean().item(),
            "entropy_loss": -terms.entropy.mean().item(),
            "value_loss": q_loss.item(),
            "rho_mean": rho_taken.mean().item(),
            "rho_truncated_fraction": (rho_taken > self.c).float().mean().item(),
            "trust_region_active_fraction": (tr_scale > 0).float().mean().item(),
            "grad_norm": float(grad_norm),
            "ent_coef": ent_coef,
            **({"distill_loss": distill.item(), "distill_coef": distill_coef} if self.distill_coef > 0 else {}),
        }

    def scheduled_coefs(self) -> tuple[float, float]:
        """The entropy and distillation weights at the current progress. A replay update in the overlapped loop's
        worker is given those of its segment's hand-over: the rollouts move the progress on meanwhile."""
        return float(self._ent_coef_schedule(self._current_progress_remaining)), self.distill_weight()

    def distill_weight(self) -> float:
        """The distillation weight now: ``distill_coef * max(0, 1 - num_timesteps / distill_steps)``."""
        if self.distill_steps <= 0:
            return self.distill_coef
        return self.distill_coef * max(0.0, 1.0 - self.num_timesteps / self.distill_steps)

    def train(self, segment: Segment) -> None:
        """
        Store the segment, update on it, then on ``Poisson(replay_ratio)`` segments from the replay buffer.

        :param segment: The segment just collected
        """
        stats = self.on_policy_update(segment, self.policy)
        n_replay = self.replay(self.policy, self.replay_count(None))
        self.record_train({**stats, "replay_updates": n_replay})

    # The update API a trainer calls (train above, the overlapped trainer in overlap.py): each part of learning from
    # a segment, on the policy given (the overlapped trainer's learner copy, or the model's own).

    def on_policy_update(self, segment: Segment, policy: ACERPolicy) -> dict[str, float]:
        """
        Store the segment and update ``policy`` on it, at the learning rate of the current progress.

        :return: The update's statistics (``train/`` keys without the prefix)
        """
        self._update_learning_rate(policy.optimizer)
        policy.set_training_mode(True)
        self.replay_buffer.add(segment)
        return self._update(segment, policy)

    def replay_count(self, rng: Optional[np.random.Generator]) -> int:
        """How many replay updates this segment earns: ``Poisson(replay_ratio)`` once the buffer is warm, drawn
        from ``rng`` (numpy's global generator if None)."""
        if self.replay_ratio <= 0 or self.replay_buffer.size() < self.replay_start:
            return 0
        return int(np.random.poisson(self.replay_ratio) if rng is None else rng.poisson(self.replay_ratio))

    def replay(self, policy: ACERPolicy, n_replay: int, rng: Optional[np.random.Generator] = None,
               batches: Optional[list[tuple[Segment, th.Tensor]]] = None,
               coefs: Optional[tuple[float, float]] = None) -> int:
        """``n_replay`` updates of ``policy`` on segments drawn from the replay buffer with ``rng``, or on
        ``batches`` (segments with their trust region's reference, :meth:`replay_references`) where given, with
        the weights ``coefs`` (:meth:`scheduled_coefs`; read at each update if None)."""
        for i in range(n_replay):
            segment, reference = (self.replay_buffer.sample(rng), None) if batches is None else batches[i]
            self._update(segment, policy, reference, coefs)
        return n_replay

    def replay_references(self, policy: ACERPolicy, n_replay: int, rng: np.random.Generator) -> list[tuple[Segment, th.Tensor]]:
        """``n_replay`` segments drawn from the replay buffer with ``rng`` (as :meth:`replay` would draw them),
        each with the trust region's reference computed now by ``policy``'s average network (``average_ahead``)."""
        batches = []
        with th.no_grad():
            for _ in range(n_replay):
                segment = self.replay_buffer.sample(rng)
                obs = self._segment_obs(segment)[:segment.actions.size]
                batches.append((segment, self._average_probs(policy, obs)))
        return batches

    def record_train(self, stats: dict[str, float]) -> None:
        """Log an update's statistics under ``train/``."""
        for key, value in stats.items():
            self.logger.record(f"train/{key}", value)
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")

    def learn(
        self: SelfACER,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 100,
        tb_log_name: str = "ACER",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfACER:
        """
        Return a trained model.

        :param total_timesteps: The total number of env steps to train on
        :param callback: Callback(s) called at every step with the state of the algorithm
        :param log_interval: Number of iterations (segments) between log dumps
        :param tb_log_name: The name of the run for TensorBoard logging
        :param reset_num_timesteps: Whether or not to reset the current timestep number (used in logging)
        :param progress_bar: Display a progress bar using tqdm and rich
        :return: The trained model
        """
        iteration = 0
        fresh = self._last_obs is None  # a new or loaded model: _setup_learn resets the env
        total_timesteps, callback = self._setup_learn(total_timesteps, callback, reset_num_timesteps, tb_log_name, progress_bar)
        if reset_num_timesteps or fresh:
            self._last_stack = None  # rebuilt from the reset observations
        # The behaviour's first infos describe the reset observations (after ACER.load too, where the env was reset).
        if reset_num_timesteps or fresh or len(self._last_infos) != self.n_envs:
            reset_infos = getattr(self.env, "reset_infos", None)
            self._last_infos = [dict(i) for i in reset_infos] if reset_infos else [{} for _ in range(self.n_envs)]
        self.behaviour_policy.setup(self)
        callback.on_training_start(locals(), globals())
        assert self.env is not None

        with self._segment_trainer() as train_on:
            # The budget is read at each segment: a callback may end the run sooner (end_at), after its update.
            while self.num_timesteps < self._total_timesteps:
                segment = self.collect_rollouts(self.env, callback)
                if segment is None:
                    break
                iteration += 1
                self._update_current_progress_remaining(self.num_timesteps, self._total_timesteps)
                self.behaviour_policy.record(self.logger)
                self._record_tags()
                train_on(segment)
                if log_interval is not None and iteration % log_interval == 0:
                    self.dump_logs(iteration)

        callback.on_training_end()
        return self

    def end_at(self, timesteps: int) -> None:
        """
        End the current ``learn`` once ``num_timesteps`` reaches ``timesteps`` (at the end of that segment, after its
        update), where that is sooner than its budget; for a callback that decides the budget while learning.

        :param timesteps: The env step count (``num_timesteps``) to stop at
        """
        self._total_timesteps = min(self._total_timesteps, int(timesteps))

    def _segment_trainer(self) -> contextlib.AbstractContextManager[Callable[[Segment], None]]:
        """What learns from each collected segment: :meth:`train`, or with ``overlap`` the overlapped trainer
        (:func:`sb3_disagree.acer.overlap.overlapped_updates`)."""
        return overlapped_updates(self) if self.overlap else contextlib.nullcontext(self.train)

    def _record_tags(self) -> None:
        if self.last_rollout_tags is None:
            return
        labels, counts = np.unique(self.last_rollout_tags.astype(str), return_counts=True)
        for label, count in zip(labels, counts):
            self.logger.record(f"behaviour/{label}", count / self.last_rollout_tags.size)

    def dump_logs(self, iteration: int = 0) -> None:
        """
        Write the log: ``rollout/`` (episode return, length, success rate), ``time/`` and the last ``train/``.

        :param iteration: Current logging iteration
        """
        OnPolicyAlgorithm.dump_logs(self, iteration)  # type: ignore[arg-type]

    # ------------------------------------------------------------------ replay buffer I/O

    def save_replay_buffer(self, path: Union[str, pathlib.Path]) -> None:
        """
        Save the replay buffer as arrays (numpy's ``.npz`` format, to the exact path given): unlike SB3's pickle,
        loading it back runs nothing.

        :param path: Path to the file where the replay buffer should be saved
        """
        self.replay_buffer.save(path)

    def load_replay_buffer(self, path: Union[str, pathlib.Path], trust: bool = False) -> None:
        """
        Load a replay buffer saved by :meth:`save_replay_buffer`; a pickled one (as SB3 saves them) only with
        ``trust``, since unpickling a file can run its code.

        :param path: Path to the saved replay buffer
        :param trust: Also accept a pickled buffer
        """
        if zipfile.is_zipfile(path):
            buffer = SegmentReplayBuffer.load(path)
        elif trust:
            buffer = load_from_pkl(path, self.verbose)
        else:
            raise ValueError(f"{path} is a pickled replay buffer: loading it could run code; pass --trust if you "
                             "made it")
        if not isinstance(buffer, SegmentReplayBuffer):
            raise ValueError(f"{path} does not hold an ACER segment replay buffer")
        expected = (self.n_steps, self.n_envs, int(self.action_space.n))
        if (buffer.n_steps, buffer.n_envs, buffer.n_actions) != expected:
            raise ValueError(
                f"The replay buffer holds segments of (n_steps, n_envs, n_actions) = "
                f"{(buffer.n_steps, buffer.n_envs, buffer.n_actions)}, the model expects {expected}"
            )
        if not hasattr(buffer, "frame_stack"):  # saved before stacks were stored as frames: whole observations
            buffer.frame_stack = 1
        if not hasattr(buffer, "teacher"):  # saved before the buffer kept a teacher: none
            buffer.teacher = np.zeros_like(buffer.mu)
            buffer.followed = np.zeros_like(buffer.rewards)
        self.replay_buffer = buffer


def _as_numpy(x: Union[np.ndarray, th.Tensor]) -> np.ndarray:
    return x.detach().cpu().numpy() if isinstance(x, th.Tensor) else np.asarray(x)

