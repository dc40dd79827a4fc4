"""ACER policies: a shared trunk with a policy head and a Q head, plus the average policy network."""

import copy
from collections.abc import Mapping
from functools import partial
from typing import Any, Optional, Union

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.distributions import CategoricalDistribution
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.preprocessing import maybe_transpose
from stable_baselines3.common.sb2_compat.rmsprop_tf_like import RMSpropTFLike
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, FlattenExtractor, NatureCNN
from stable_baselines3.common.type_aliases import PyTorchObs, Schedule
from stable_baselines3.common.utils import polyak_update
from torch import nn

from sb3_disagree.acer.memory import push_frames, stacked_space


AVERAGES = ("average_net.", "ema_net.")


def compact_averages(state: dict[str, Any]) -> dict[str, Any]:
    """
    A policy state dict without the average networks' entries that equal the current network's.

    :param state: ``ACERPolicy`` state dict, keys ``net.*``, ``average_net.*`` and maybe ``ema_net.*``
    :return: The same dict (same order) less the redundant entries
    """
    def redundant(key: str, value: Any) -> bool:
        for prefix in AVERAGES:
            if key.startswith(prefix):
                twin = state.get("net." + key[len(prefix):])
                return twin is not None and th.equal(twin, value)  # False where the shapes differ
        return False

    return type(state)((k, v) for k, v in state.items() if not redundant(k, v))


def expand_averages(state: Mapping[str, Any], *averages: Optional[nn.Module]) -> dict[str, Any]:
    """
    Undo :func:`compact_averages`: each entry that an average network has and ``state`` lacks is the current
    network's (``net.*``) entry of the same name.

    :param state: A policy state dict, maybe compacted
    :param averages: The policy's ``average_net`` and ``ema_net`` (None where not kept)
    :return: A state dict with every average entry present where ``net``'s twin is
    """
    full = dict(state)
    for prefix, module in zip(AVERAGES, averages):
        if module is None:
            continue
        for name in module.state_dict():
            twin = "net." + name
            if prefix + name not in full and twin in full:
                full[prefix + name] = full[twin].clone()  # never the same tensor as net's (``assign=True``)
    return full


def _mlp(in_dim: int, sizes: list[int], activation_fn: type[nn.Module]) -> tuple[nn.Sequential, int]:
    layers: list[nn.Module] = []
    for size in sizes:
        layers += [nn.Linear(in_dim, size), activation_fn()]
        in_dim = size
    return nn.Sequential(*layers), in_dim


class ACERNetwork(nn.Module):
    """
    A features extractor feeding two linear heads, policy logits and Q(s, .), through MLP layers that
    are either shared (``net_arch`` a list) or separate (``dict(pi=[...], qf=[...])``, as SB3's SAC).

    :param features_extractor: Network that maps preprocessed observations to features
    :param net_arch: Hidden layer sizes: a list for a shared trunk, or a dict with keys ``pi`` and ``qf``
    :param activation_fn: Activation between the hidden layers
    :param n_actions: Number of discrete actions
    """

    def __init__(
        self,
        features_extractor: BaseFeaturesExtractor,
        net_arch: Union[list[int], dict[str, list[int]]],
        activation_fn: type[nn.Module],
        n_actions: int,
    ) -> None:
        super().__init__()
        self.features_extractor = features_extractor
        dim = features_extractor.features_dim
        if isinstance(net_arch, dict):
            self.trunk = nn.Identity()
            self.pi_net, pi_dim = _mlp(dim, list(net_arch.get("pi", [])), activation_fn)
            self.qf_net, qf_dim = _mlp(dim, list(net_arch.get("qf", [])), activation_fn)
        else:
            self.trunk, dim = _mlp(dim, list(net_arch), activation_fn)
            self.pi_net, self.qf_net = nn.Identity(), nn.Identity()
            pi_dim = qf_dim = dim
        self.action_net = nn.Linear(pi_dim, n_actions)
        self.q_net = nn.Linear(qf_dim, n_actions)

    def forward(self, features: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        latent = self.trunk(features)
        return self.action_net(self.pi_net(latent)), self.q_net(self.qf_net(latent))

    def logits(self, features: th.Tensor) -> th.Tensor:
        return self.action_net(self.pi_net(self.trunk(features)))


class ACERPolicy(BasePolicy):
    """
    Policy for ACER with discrete actions. There is no V head: ``V(s) = sum_a pi(a|s) Q(s, a)``.

    The average policy network (``average_net``) lives inside the policy, so that ``save``/``load``
    and ``get_parameters`` carry it; it is excluded from the optimizer and moves only by
    :meth:`update_average`. With ``ema=True`` the policy also keeps a slow exponential moving average of its
    weights (``ema_net``, moved by :meth:`update_ema`), and what the policy hands out to users acts with it:
    :meth:`get_distribution`, :meth:`predict` and so SB3's ``evaluate_policy``. ACER's rollouts and updates
    keep using the current weights (:meth:`action_probs`, :meth:`logits_and_q`).

    :param observation_space: Observation space
    :param action_space: Action space (``Discrete``)
    :param lr_schedule: Learning rate schedule (could be constant)
    :param net_arch: Hidden layer sizes after the features extractor: a list for a trunk shared by the
        policy and Q heads, or ``dict(pi=[...], qf=[...])`` for separate ones; default
        ``dict(pi=[64, 64], qf=[64, 64])`` for MLP features and ``[]`` for NatureCNN (its 512 features
        feed both heads directly)
    :param activation_fn: Activation function of the trunk
    :param ortho_init: Whether to use orthogonal initialization (as SB3's actor-critic policies)
    :param features_extractor_class: Features extractor to use
    :param features_extractor_kwargs: Keyword arguments to pass to the features extractor
    :param normalize_images: Whether to divide images by 255
    :param optimizer_class: The optimizer; RMSprop with TensorFlow semantics by default, as in the reference
    :param optimizer_kwargs: Additional keyword arguments, excluding the learning rate, to pass to the optimizer
    :param frame_stack: Number of recent observations the networks see, stacked along the channel axis (1: the
        current one only). The stack is the ``state`` that :meth:`predict` takes and returns, so SB3's
        ``evaluate_policy`` carries it with the env as registered; ACER keeps it during rollouts
    :param ema: Keep ``ema_net``, the moving average of the weights that the policy acts with outside training
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Discrete,
        lr_schedule: Schedule,
        net_arch: Optional[Union[list[int], dict[str, list[int]]]] = None,
        activation_fn: type[nn.Module] = nn.Tanh,
        ortho_init: bool = True,
        features_extractor_class: type[BaseFeaturesExtractor] = FlattenExtractor,
        features_extractor_kwargs: Optional[dict[str, Any]] = None,
        normalize_images: bool = True,
        optimizer_class: type[th.optim.Optimizer] = RMSpropTFLike,
        optimizer_kwargs: Optional[dict[str, Any]] = None,
        frame_stack: int = 1,
        ema: bool = False,
    ) -> None:
        if frame_stack < 1:
            raise ValueError(f"frame_stack must be >= 1, got {frame_stack}")
        if optimizer_kwargs is None:
            optimizer_kwargs = {}
            if optimizer_class is RMSpropTFLike:
                optimizer_kwargs = dict(alpha=0.99, eps=1e-5, weight_decay=0)
        super().__init__(
            observation_space,
            action_space,
            features_extractor_class,
            features_extractor_kwargs,
            normalize_images=normalize_images,
            optimizer_class=optimizer_class,
            optimizer_kwargs=optimizer_kwargs,
        )
        if not isinstance(action_space, spaces.Discrete):
            raise ValueError(f"ACER supports Discrete action spaces only, got {action_space}")
        if net_arch is None:
            # Separate MLPs for the policy and Q heads: with a shared MLP trunk the large Q-loss gradients
            # swamp the policy's (ACER did not learn Acrobot-v1 in 60k steps with one, see docs/acer.md).
            net_arch = [] if issubclass(features_extractor_class, NatureCNN) else dict(pi=[64, 64], qf=[64, 64])
        self.net_arch = net_arch
        self.activation_fn = activation_fn
        self.ortho_init = ortho_init
        self.n_actions = int(action_space.n)
        self.frame_stack = frame_stack
        self.ema = ema
        # Set by ACER (``features_dtype``): the dtype the training passes' features are computed in, None for float32.
        self.features_autocast: Optional[th.dtype] = None
        self.net_observation_space = stacked_space(observation_space, frame_stack)  # type: ignore[arg-type]
        self.action_dist = CategoricalDistribution(self.n_actions)
        self._build(lr_schedule)

    def make_features_extractor(self) -> BaseFeaturesExtractor:
        """The features extractor of the networks' input: the stack of ``frame_stack`` observations."""
        return self.features_extractor_class(self.net_observation_space, **self.features_extractor_kwargs)

    def _build(self, lr_schedule: Schedule) -> None:
        self.net = ACERNetwork(self.make_features_extractor(), self.net_arch, self.activation_fn, self.n_actions)
        if self.ortho_init:
            # Same gains as SB3's ActorCriticPolicy: small policy logits give a near-uniform first policy.
            gains = {self.net.features_extractor: np.sqrt(2), self.net.trunk: np.sqrt(2), self.net.pi_net: np.sqrt(2),
                     self.net.qf_net: np.sqrt(2), self.net.action_net: 0.01, self.net.q_net: 1.0}
            for module, gain in gains.items():
                module.apply(partial(self.init_weights, gain=gain))
        self.average_net = copy.deepcopy(self.net)
        self.average_net.requires_grad_(False)
        self.ema_net = copy.deepcopy(self.net).requires_grad_(False) if self.ema else None
        self.optimizer = self.optimizer_class(self.net.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(
            dict(
                net_arch=self.net_arch,
                activation_fn=self.activation_fn,
                ortho_init=self.ortho_init,
                lr_schedule=self._dummy_schedule,
                features_extractor_class=self.features_extractor_class,
                features_extractor_kwargs=self.features_extractor_kwargs,
                optimizer_class=self.optimizer_class,
                optimizer_kwargs=self.optimizer_kwargs,
                frame_stack=self.frame_stack,
                ema=self.ema,
            )
        )
        return data

    def extract_features(self, obs: PyTorchObs, features_extractor: BaseFeaturesExtractor) -> th.Tensor:
        """SB3's preprocessing then the extractor, except for an extractor that scales what it uses itself
        (``takes_raw_images``, as ``LoopFlagsCNN``: scaling a whole stack would cost more than its CNN's input)."""
        if getattr(features_extractor, "takes_raw_images", False) and self.normalize_images and isinstance(
                obs, th.Tensor) and obs.dtype == th.uint8:
            return features_extractor(obs)
        return super().extract_features(obs, features_extractor)

    def training_features(self, obs: PyTorchObs, net: "ACERNetwork") -> th.Tensor:
        """
        The features of ``net`` for the training passes: under ``torch.autocast`` to ``features_autocast`` where it
        is set (the features extractor's convolutions in bfloat16), returned as float32 so that the heads, the
        Q-values and the losses stay float32.

        :param obs: Observations, as tensors
        :param net: ``net`` or ``average_net``
        """
        if self.features_autocast is None:
            return self.extract_features(obs, net.features_extractor)
        with th.autocast(self.device.type, dtype=self.features_autocast):
            features = self.extract_features(obs, net.features_extractor)
        return features.float()

    def logits_and_q(self, obs: PyTorchObs) -> tuple[th.Tensor, th.Tensor]:
        """
        :param obs: Observations, as tensors
        :return: Policy logits and Q-values, both of shape (batch, n_actions)
        """
        return self.net(self.training_features(obs, self.net))

    @property
    def acting_net(self) -> ACERNetwork:
        """The network the policy acts with outside training: the moving average where one is kept, else ``net``."""
        return self.net if self.ema_net is None else self.ema_net

    def average_logits(self, obs: PyTorchObs) -> th.Tensor:
        """
        :param obs: Observations, as tensors
        :return: Logits of the average policy network (no gradient)
        """
        with th.no_grad():
            return self.average_net.logits(self.training_features(obs, self.average_net))

    def action_probs(self, obs: PyTorchObs) -> th.Tensor:
        """
        :param obs: Observations, as tensors
        :return: Action probabilities pi(.|s) of the current policy, shape (batch, n_actions)
        """
        logits = self.net.logits(self.extract_features(obs, self.net.features_extractor))
        return th.softmax(logits, dim=-1)

    def get_distribution(self, obs: PyTorchObs) -> CategoricalDistribution:
        """
        The policy's action distribution, as SB3's actor-critic policies expose it: of the moving average of the
        weights where one is kept (``ema``), else of the current weights.

        :param obs: Observations, as tensors
        :return: A categorical distribution over actions
        """
        net = self.acting_net
        logits = net.logits(self.extract_features(obs, net.features_extractor))
        return self.action_dist.proba_distribution(action_logits=logits)

    def forward(self, obs: th.Tensor, deterministic: bool = False) -> th.Tensor:
        return self.get_distribution(obs).get_actions(deterministic=deterministic)

    def _predict(self, observation: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        return self.get_distribution(observation).get_actions(deterministic=deterministic)

    def predict(
        self,
        observation: Union[np.ndarray, dict[str, np.ndarray]],
        state: Optional[tuple[np.ndarray, ...]] = None,
        episode_start: Optional[np.ndarray] = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, Optional[tuple[np.ndarray, ...]]]:
        """
        The policy's actions for a batch of observations; with ``frame_stack > 1`` the stack of recent
        observations rides in ``state`` (a 1-tuple holding the stacks), as recurrent SB3 policies carry theirs.

        :param observation: The observations, as the env gives them
        :param state: The stacks returned by the previous call (None at the start: zeros)
        :param episode_start: True where the observation is the first of an episode (the stack is cleared)
        :param deterministic: Greedy actions if True, sampled otherwise
        :return: The actions and the new state (None without frame stacking)
        """
        if self.frame_stack == 1:
            return super().predict(observation, state, episode_start, deterministic)
        self.set_training_mode(False)
        obs = np.asarray(maybe_transpose(observation, self.observation_space))  # type: ignore[arg-type]
        vectorized = obs.shape != self.observation_space.shape
        obs = obs.reshape((-1, *self.observation_space.shape))  # type: ignore[misc]
        stack = push_frames(None if state is None else state[0], obs, episode_start, self.frame_stack)
        with th.no_grad():
            actions = self._predict(th.as_tensor(stack, device=self.device), deterministic=deterministic)
        actions = actions.cpu().numpy().reshape((-1, *self.action_space.shape))  # type: ignore[misc]
        return (actions if vectorized else actions.squeeze(axis=0)), (stack,)

    def update_average(self, alpha: float) -> None:
        """
        Move the average network toward the current one: ``theta_avg <- alpha * theta_avg + (1 - alpha) * theta``.

        :param alpha: Decay of the average network (0.99 in the reference)
        """
        polyak_update(self.net.parameters(), self.average_net.parameters(), 1.0 - alpha)

    def update_ema(self, decay: float) -> None:
        """
        Move the acting average toward the current weights: ``theta_ema <- decay * theta_ema + (1 - decay) * theta``.

        :param decay: Decay per update, in [0, 1)
        """
        if self.ema_net is not None:
            polyak_update(self.net.parameters(), self.ema_net.parameters(), 1.0 - decay)

    def load_state_dict(self, state_dict: Mapping[str, Any], strict: bool = True, assign: bool = False) -> Any:
        """
        ``nn.Module.load_state_dict``, each average-network entry that ``state_dict`` lacks taken as the current
        network's: ``ACER.save`` leaves out the entries that equal it (:func:`compact_averages`).
        """
        return super().load_state_dict(expand_averages(state_dict, self.average_net, self.ema_net), strict, assign)

    def sync_averages(self) -> None:
        """Set the average networks to the current weights (after weights were copied into ``net``)."""
        self.average_net.load_state_dict(self.net.state_dict())
        if self.ema_net is not None:
            self.ema_net.load_state_dict(self.net.state_dict())


MlpPolicy = ACERPolicy


class CnnPolicy(ACERPolicy):
    """ACERPolicy with the NatureCNN features extractor, for image observations."""

    def __init__(self, *args: Any, features_extractor_class: type[BaseFeaturesExtractor] = NatureCNN, **kwargs: Any) -> None:
        kwargs.setdefault("activation_fn", nn.ReLU)
        super().__init__(*args, features_extractor_class=features_extractor_class, **kwargs)
