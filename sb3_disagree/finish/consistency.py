"""
A greedy-consistency phase for a trained ACER policy (docs/method.md, "Greedy consistency").

ACER's policy stays soft: where two actions are worth about the same to the sampled policy, its argmax is
arbitrary, and a memoryless argmax then loops (turning left and right between two poses) or stays pressed
against a wall whose picture looks like open floor. The phase acts greedily, samples only where the newest
frame was already seen in the episode (the greedy policy is in a loop), cuts every loop out of the episodes
that reach the goal, and fits the acting network by cross-entropy to the actions of the loop-free paths,
aggregated over rounds (as DAgger aggregates its labels). No prior, expert or map is used: only the policy, the
env's success flag and frame identity; a prior's phase may add the env's expert in loops (``expert_in_loops``).
"""

import copy
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Optional, Union

import numpy as np
import torch as th
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.preprocessing import maybe_transpose
from stable_baselines3.common.vec_env import VecEnv

from sb3_disagree.acer.memory import LinkedFrames, push_frames


def loop_free_labels(keys: list[Any], actions: list[int]) -> list[tuple[int, int]]:
    """
    The steps of an episode with its loops cut out, each labelled with the action that left its pose for good.

    A step whose key (its newest frame) was seen before closes a loop: the steps since that key's first visit are
    dropped, and the action now taken from that pose replaces the one taken before. Each kept pose keeps all its
    visits' inputs (a policy with memory sees a different stack on each), all labelled with its last action.

    :param keys: Per step, a hashable key of the pose (the newest frame's bytes)
    :param actions: Per step, the action taken
    :return: (step index, label) pairs, in path order
    """
    path: list[tuple[Any, list[int], int]] = []  # (key, the steps at this pose, the action that left it)
    where: dict[Any, int] = {}
    for t, (key, action) in enumerate(zip(keys, actions)):
        if key in where:
            j = where[key]
            for dropped, _, _ in path[j + 1:]:
                del where[dropped]
            path = path[:j + 1]
            path[j] = (key, path[j][1] + [t], action)
        else:
            where[key] = len(path)
            path.append((key, [t], action))
    return [(t, action) for _, steps, action in path for t in steps]


def expert_loop_labels(keys: list[Any], actions: list[int], experts: list[int], success: bool) -> list[tuple[int, int]]:
    """
    An episode's labels where an expert is at hand: the expert's action at every step whose pose the episode visits
    more than once (each visit of a loop's poses, the first included, in episodes that failed too), and, in an
    episode that reached the goal, the loop-free path's label (:func:`loop_free_labels`) at every other step.

    :param keys: Per step, a hashable key of the pose (the newest frame's bytes)
    :param actions: Per step, the action taken
    :param experts: Per step, the expert's action
    :param success: Whether the episode reached the goal
    :return: (step index, label) pairs, by step
    """
    visits = Counter(keys)
    labels = {t: int(experts[t]) for t, key in enumerate(keys) if visits[key] > 1}
    if success:
        for t, action in loop_free_labels(keys, actions):
            labels.setdefault(t, action)
    return sorted(labels.items())


@dataclass
class RoundStats:
    """What one round collected and fitted."""

    env_steps: int
    episodes: int
    successes: int
    labels: int
    loss: float
    accuracy: float
    expert_labels: int = 0  # labels of loops' poses from the env's expert (expert_in_loops)
    epoch: int = 0  # with a validation, the epoch whose weights were kept (its loss and accuracy above); 0: the last
    validation: list[float] = field(default_factory=list)  # greedy validation success after each epoch

    def as_dict(self) -> dict[str, Any]:
        return {k: [float(x) for x in v] if isinstance(v, list) else float(v) for k, v in self.__dict__.items()
                if (k not in ("epoch", "validation") or self.validation)
                and (k != "expert_labels" or self.expert_labels)}


class _Labels:
    """
    The labels of loop-free paths, their inputs held as single frames linked back along their episodes
    (:class:`~sb3_disagree.acer.memory.LinkedFrames`): a stack of ``k`` frames costs one frame, so the phase's memory
    does not grow with the policy's (ten rounds of six-frame stacks would be about 16 GB, as frames 3 GB).

    :param k: Number of frames in the policy's input
    """

    def __init__(self, k: int = 1) -> None:
        self.k = k
        self.frames: list[np.ndarray] = []
        self.previous: list[int] = []  # per frame, the one before it in its episode, or -1
        self.at: list[int] = []  # per label, its step's newest frame
        self.actions: list[int] = []

    def add_episode(self, stacks: list[np.ndarray], labels: list[tuple[int, int]]) -> None:
        """
        Keep an episode's labels.

        :param stacks: The network's input at each step of the episode (from where it was first seen)
        :param labels: (step, action) pairs, as :func:`loop_free_labels` returns them
        """
        c = len(stacks[0]) // self.k
        # The first input's k frames, oldest first (an episode under way when first seen carries its earlier
        # frames; zeros before an episode's start are kept as zero frames), then each step's newest frame.
        chain = [stacks[0][j * c:(j + 1) * c] for j in range(self.k)] + [x[len(x) - c:] for x in stacks[1:]]
        positions = []
        for frame in chain:
            self.previous.append(len(self.frames) - 1 if positions else -1)
            self.frames.append(frame.copy())
            positions.append(len(self.frames) - 1)
        steps = positions[self.k - 1:]
        for t, action in labels:
            self.at.append(steps[t])
            self.actions.append(int(action))

    def linked(self) -> tuple[LinkedFrames, np.ndarray]:
        """The frames as :class:`LinkedFrames` and each label's frame in them."""
        frames = LinkedFrames(np.stack(self.frames), np.asarray(self.previous, dtype=np.int64), self.k)
        return frames, np.asarray(self.at, dtype=np.int64)

    @property
    def inputs(self) -> np.ndarray:
        """Every label's input, rebuilt (shape (labels, k * c, ...)); an empty array without labels."""
        if not self.at:
            return np.zeros((0,))
        frames, at = self.linked()
        return frames[at]


class _Trails:
    """Each env's episode under way (inputs, pose keys, actions, the expert's actions); at its end, its loop-free
    path is kept as labels if it reached the goal, and with ``expert`` its loops' poses with the expert's actions
    (:func:`expert_loop_labels`)."""

    def __init__(self, n_envs: int, k: int = 1, expert: bool = False) -> None:
        self.trails: list[list[tuple[np.ndarray, bytes, int, int]]] = [[] for _ in range(n_envs)]
        self.labels, self.episodes, self.successes, self.expert, self.expert_labels = _Labels(k), 0, 0, expert, 0

    def add(self, i: int, net_input: np.ndarray, key: bytes, action: int, expert: int = -1) -> None:
        self.trails[i].append((net_input.copy(), key, int(action), int(expert)))

    def end(self, i: int, success: bool) -> None:
        trail, self.trails[i] = self.trails[i], []
        self.episodes += 1
        self.successes += int(success)
        keys, actions = [step[1] for step in trail], [step[2] for step in trail]
        if self.expert:
            labels = expert_loop_labels(keys, actions, [step[3] for step in trail], success)
            self.expert_labels += sum(n for n in Counter(keys).values() if n > 1)  # every visit of a loop's pose
        else:
            labels = loop_free_labels(keys, actions) if success else []
        if labels:
            self.labels.add_episode([step[0] for step in trail], labels)


class _Rounds:
    """The labels' inputs, one linked array of frames per round, indexed as one array of stacks: each round is
    stored once, instead of all rounds again at each fit."""

    def __init__(self) -> None:
        self.parts: list[tuple[LinkedFrames, np.ndarray]] = []  # per round, its frames and each label's frame
        self.ends = np.zeros(0, dtype=np.int64)
        self.starts = np.zeros(0, dtype=np.int64)

    def add(self, labels: _Labels) -> None:
        if labels.at:
            self.parts.append(labels.linked())
            self.ends = np.cumsum([len(at) for _, at in self.parts])
            self.starts = self.ends - [len(at) for _, at in self.parts]

    def __len__(self) -> int:
        return int(self.ends[-1]) if len(self.ends) else 0

    def __getitem__(self, index: np.ndarray) -> np.ndarray:
        index = np.asarray(index)
        part = np.searchsorted(self.ends, index, side="right")
        linked = self.parts[0][0]
        out = np.empty((len(index), linked.k * linked.frames.shape[1], *linked.frames.shape[2:]),
                       dtype=linked.frames.dtype)
        for p in np.unique(part):
            here = part == p
            frames, at = self.parts[p]
            out[here] = frames[at[index[here] - self.starts[p]]]
        return out


SAMPLING = ("loops", "always")  # where the collection samples instead of acting greedily


def collect_escapes(model: Any, env: VecEnv, steps: int, rng: np.random.Generator,
                    sampling: str = "loops", loop_uniform: float = 0.0,
                    expert_in_loops: bool = False) -> tuple[_Labels, dict[str, int]]:
    """
    Act greedily with the model's acting network, sampling from it only where the newest frame was already seen
    in the episode, for ``steps`` env steps; return the loop-free labels of the episodes that reached the goal
    (``info["is_success"]``). Episodes still running at the end are dropped.

    :param model: A trained ACER model
    :param env: Envs of its task
    :param steps: Env steps over all envs
    :param rng: Draws of the sampled actions
    :param sampling: "loops" (greedy, sampling in loops) or "always" (every action sampled, as training acts)
    :param loop_uniform: In a loop, the share of the uniform distribution in what is sampled,
        ``(1 - u) pi + u / n``: a sharp policy that loops (pi near 1 on turning back) escapes only by this
    :param expert_in_loops: Label every visit of a pose the episode visits more than once with the env's expert
        (its envs' ``expert_action()``), in failed episodes too (:func:`expert_loop_labels`): where the policy
        loops, a path that escaped by chance is not the only teacher
    :return: The labels and counts (env_steps, episodes, successes, expert_labels)
    """
    if sampling not in SAMPLING:
        raise ValueError(f"sampling must be one of {SAMPLING}, got {sampling!r}")
    policy, n, k = model.policy, env.num_envs, model.policy.frame_stack
    obs = np.asarray(maybe_transpose(env.reset(), policy.observation_space))  # images: channels first, as stored
    stack = push_frames(None, obs, None, k)
    trails = _Trails(n, k, expert_in_loops)
    seen: list[set[bytes]] = [set() for _ in range(n)]
    experts = np.full(n, -1)
    for _ in range(max(steps // n, 1)):
        with th.no_grad():  # the acting network's distribution, as predict draws from it
            probs = policy.get_distribution(th.as_tensor(stack, device=policy.device)).distribution.probs.cpu().numpy()
        actions = probs.argmax(-1)
        if expert_in_loops:
            experts = np.asarray(env.env_method("expert_action"), dtype=np.int64)
        for i in range(n):
            key = obs[i].tobytes()
            looping = key in seen[i]  # a pose seen before: the greedy policy loops, so sample
            if sampling == "always" or looping:
                p = probs[i] / probs[i].sum()
                if looping and loop_uniform:
                    p = (1 - loop_uniform) * p + loop_uniform / len(p)
                actions[i] = rng.choice(len(p), p=p)
            seen[i].add(key)
            trails.add(i, stack[i], key, int(actions[i]), int(experts[i]))
        new_obs, _, dones, infos = env.step(actions)
        for i in np.flatnonzero(dones):
            trails.end(i, bool(infos[i].get("is_success")))
            seen[i] = set()
        obs = np.asarray(maybe_transpose(new_obs, policy.observation_space))
        stack = push_frames(stack, obs, dones, k)
    return trails.labels, {"env_steps": max(steps // n, 1) * n, "episodes": trails.episodes,
                           "successes": trails.successes, "expert_labels": trails.expert_labels}


def acting_network(policy: Any) -> th.nn.Module:
    """What the fit trains: an ACER policy's acting network (its moving average where one is kept), or any other SB3
    policy whole (PPO's: the fit acts through its action distribution, as ``predict`` does)."""
    return policy.acting_net if hasattr(policy, "acting_net") else policy


def _logits(policy: Any, net: th.nn.Module, x: th.Tensor) -> th.Tensor:
    if net is policy:
        return policy.get_distribution(x).distribution.logits
    return net.logits(policy.extract_features(x, net.features_extractor))


def fit_labels(policy: Any, inputs: Union[np.ndarray, _Rounds], actions: np.ndarray, epochs: int,
               learning_rate: float, batch_size: int, rng: np.random.Generator,
               on_epoch: Optional[Callable[[int, float, float], None]] = None) -> tuple[float, float]:
    """
    Fit the policy's acting network (the moving average where one is kept) to ``actions`` by cross-entropy.

    :param inputs: The network's inputs, an array or the rounds' arrays (indexed by an array of positions)
    :param on_epoch: Called after each epoch with its number (from 1), mean loss and accuracy
    :return: The last epoch's mean loss and accuracy (argmax equal to the label)
    """
    net = acting_network(policy)
    net.requires_grad_(True)
    optimizer = th.optim.Adam(net.parameters(), lr=learning_rate)
    loss_sum = correct = 0.0
    try:
        for epoch in range(1, epochs + 1):
            loss_sum = correct = 0.0
            for batch in np.array_split(rng.permutation(len(inputs)), max(len(inputs) // batch_size, 1)):
                x = th.as_tensor(inputs[batch], device=policy.device)
                y = th.as_tensor(actions[batch], device=policy.device)
                logits = _logits(policy, net, x)
                loss = th.nn.functional.cross_entropy(logits, y)
                optimizer.zero_grad()
                loss.backward()
                optimizer.step()
                loss_sum += loss.item() * len(batch)
                correct += (logits.argmax(-1) == y).sum().item()
            if on_epoch is not None:
                on_epoch(epoch, loss_sum / max(len(inputs), 1), correct / max(len(inputs), 1))
    finally:
        if net is not getattr(policy, "net", net):  # the moving average is not trained by gradient elsewhere
            net.requires_grad_(False)
    return loss_sum / max(len(inputs), 1), correct / max(len(inputs), 1)


def fit_best_epoch(policy: Any, inputs: Union[np.ndarray, _Rounds], actions: np.ndarray, epochs: int,
                   learning_rate: float, batch_size: int, rng: np.random.Generator,
                   validate: Callable[[], tuple[float, float]]) -> tuple[int, float, float, list[float]]:
    """
    :func:`fit_labels`, validated after every epoch, keeping the weights of the epoch with the highest greedy
    validation success (ties: the shorter mean episode, then the earlier epoch). A greedy policy's success is a
    fragile function of its weights: one more epoch on the same labels can move it by 0.17 (docs/method.md).

    :param validate: The acting network's greedy success and mean episode length on validation episodes
    :return: The kept epoch, its loss and accuracy, and every epoch's validation success
    """
    net, best, scores = acting_network(policy), None, []

    def on_epoch(epoch: int, loss: float, accuracy: float) -> None:
        nonlocal best
        success, length = validate()
        scores.append(success)
        if best is None or (success, -length) > best[0]:
            best = ((success, -length), epoch, loss, accuracy, copy.deepcopy(net.state_dict()))

    fit_labels(policy, inputs, actions, epochs, learning_rate, batch_size, rng, on_epoch)
    _, epoch, loss, accuracy, weights = best
    net.load_state_dict(weights)
    return epoch, loss, accuracy, scores


def greedy_consistency(model: Any, env: Optional[VecEnv], rounds: int = 3, steps: int = 20_000, epochs: int = 3,
                       learning_rate: float = 3e-4, batch_size: int = 128, seed: int = 0,
                       on_round: Optional[Any] = None, sampling: str = "loops", loop_uniform: float = 0.0,
                       harvest: Optional["HarvestLabels"] = None,
                       validate: Optional[Callable[[], tuple[float, float]]] = None,
                       expert_in_loops: bool = False) -> list[RoundStats]:
    """
    The greedy-consistency phase: ``rounds`` times, collect ``steps`` env steps acting greedily (sampling only
    in loops), add the loop-free labels of the successful episodes to those of earlier rounds, and fit the acting
    network to all of them. The model is changed in place; ``rounds * steps`` env steps are spent. With
    ``harvest``, the labels of the training's own last episodes join the first round's; with ``rounds`` 0 they
    are fitted alone (one fit, no env step spent).

    :param model: A trained ACER model
    :param env: Envs of its task (seeded apart from its training and evaluation envs); None with ``rounds`` 0
    :param rounds: Collect-and-fit rounds
    :param steps: Env steps per round, over all envs
    :param epochs: Passes over the aggregated labels per round
    :param learning_rate: Adam's step size
    :param batch_size: Labels per gradient step
    :param seed: Seed of the sampled actions and the minibatches
    :param on_round: Called with each round's :class:`RoundStats`
    :param sampling: Where the collection samples: "loops" (the phase) or "always" (as training acts)
    :param loop_uniform: In a loop, the share of the uniform distribution in the sampled one (see
        :func:`collect_escapes`)
    :param harvest: The labels a :class:`HarvestLabels` kept during training
    :param validate: The acting network's greedy success and mean episode length on validation episodes; with it,
        each fit keeps the weights of its epoch that validates best (:func:`fit_best_epoch`)
    :param expert_in_loops: Label the poses of loops with the env's expert (see :func:`collect_escapes`): for a
        prior, whose env has one
    :return: Each round's statistics (with ``rounds`` 0, the harvest's fit: its episodes, 0 env steps)
    """
    if rounds < (0 if harvest is not None else 1) or epochs < 1 or (rounds and steps < env.num_envs):
        raise ValueError(f"rounds and epochs must be >= 1 (rounds >= 0 with a harvest) and steps >= the number of "
                         f"envs, got {rounds}, {steps}, {epochs}")
    rng = np.random.default_rng(seed)
    trails = harvest.trails if harvest is not None else _Trails(0)
    inputs, actions = _Rounds(), list(trails.labels.actions)
    inputs.add(trails.labels)

    def fit(env_steps: int, episodes: int, successes: int, labels: int, expert_labels: int = 0) -> RoundStats:
        stats = RoundStats(env_steps, episodes, successes, labels, float("nan"), float("nan"), expert_labels)
        if len(inputs):
            fit_args = (model.policy, inputs, np.asarray(actions, dtype=np.int64), epochs, learning_rate, batch_size,
                        rng)
            if validate is None:
                stats.loss, stats.accuracy = fit_labels(*fit_args)
            else:
                stats.epoch, stats.loss, stats.accuracy, stats.validation = fit_best_epoch(*fit_args, validate)
        if on_round is not None:
            on_round(stats)
        return stats

    if rounds == 0:
        return [fit(0, trails.episodes, trails.successes, len(actions))]
    history = []
    for _ in range(rounds):
        labels, counts = collect_escapes(model, env, steps, rng, sampling, loop_uniform, expert_in_loops)
        inputs.add(labels)
        actions += labels.actions
        history.append(fit(counts["env_steps"], counts["episodes"], counts["successes"], len(labels.actions),
                           counts["expert_labels"]))
    return history


class HarvestLabels(BaseCallback):
    """
    Keep the loop-free paths of the training's own successful episodes (ACER's, or any SB3 on-policy algorithm's)
    from env step ``start`` on: labels for
    :func:`greedy_consistency` from steps the training has spent anyway (an episode under way at ``start`` counts
    from there: the rest of a path to the goal is a path to the goal).

    :param start: The env step after which steps are kept (the budget minus the harvest)
    """

    def __init__(self, start: int) -> None:
        super().__init__()
        self.start = start
        self.trails = _Trails(0)  # what was kept: labels, episodes, successes

    def _init_callback(self) -> None:
        self.trails = _Trails(self.training_env.num_envs, getattr(self.model.policy, "frame_stack", 1))

    def _on_step(self) -> bool:
        if self.num_timesteps <= self.start:  # num_timesteps counts this step already
            return True
        # The observation (its newest frame) before this step, and the net's input: ACER's collect_rollouts keeps the
        # stack it acted on; SB3's on-policy loop (PPO) acts on the observation itself.
        obs = self.model._last_obs
        net_inputs = self.locals["observations"][self.locals["step"]] if "observations" in self.locals else obs
        for i, action in enumerate(self.locals["actions"]):
            self.trails.add(i, net_inputs[i], obs[i].tobytes(), int(action))
        for i in np.flatnonzero(self.locals["dones"]):
            self.trails.end(i, bool(self.locals["infos"][i].get("is_success")))
        return True

