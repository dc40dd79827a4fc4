"""Segment storage for ACER: one rollout of ``n_steps`` per env, with the full behaviour distribution mu."""

import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Union

import numpy as np
from gymnasium import spaces

from sb3_disagree.acer.memory import push_frames


@dataclass
class Segment:
    """
    A batch of segments, time-major. ``observations`` has one more step than the rest: its last row is
    the observation after the segment, where the Retrace recursion bootstraps.

    :param observations: x_0 .. x_T, shape (T + 1, E, *obs_shape)
    :param actions: a_t, shape (T, E)
    :param rewards: r_t, shape (T, E)
    :param dones: 1.0 where the episode ended at step t (terminated or truncated), shape (T, E)
    :param timeout_values: V(x_{t+1}) of the true last observation where a time limit truncated the
        episode at step t, else 0; shape (T, E)
    :param mu: Behaviour distribution at each step, shape (T, E, A)
    :param teacher: Distribution to distil toward at each step (the priors' mixture), shape (T, E, A), or None
    :param followed: 1.0 where the teacher chose the action at step t, shape (T, E), or None
    """

    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    dones: np.ndarray
    timeout_values: np.ndarray
    mu: np.ndarray
    teacher: Optional[np.ndarray] = None
    followed: Optional[np.ndarray] = None

    @property
    def n_steps(self) -> int:
        return self.actions.shape[0]


class SegmentReplayBuffer:
    """
    Circular buffer of whole segments. A sample takes one random stored segment per environment, so a
    replay batch has the shape of an on-policy batch (as in the reference implementation).

    :param buffer_size: Capacity in env transitions, over all envs (SB3's convention); rounded down to
        whole segments, at least one
    :param n_steps: Length of a segment
    :param n_envs: Number of parallel environments
    :param observation_space: Observation space (of the policy's input: with frame stacking, the stacks)
    :param n_actions: Number of discrete actions
    :param frame_stack: Frames per observation. With more than one, a segment's observations are stored as
        its first stack and the newest frame of each later one (``T + K`` frames instead of ``(T + 1) K``),
        and the stacks are rebuilt on sampling as the rollout built them, cleared where an episode ended
    """

    def __init__(
        self,
        buffer_size: int,
        n_steps: int,
        n_envs: int,
        observation_space: spaces.Space,
        n_actions: int,
        frame_stack: int = 1,
    ) -> None:
        self.n_steps = n_steps
        self.n_envs = n_envs
        self.n_actions = n_actions
        self.frame_stack = frame_stack
        self.n_segments = max(1, buffer_size // (n_steps * n_envs))
        obs_shape = observation_space.shape if observation_space.shape is not None else ()
        s, t, e = self.n_segments, n_steps, n_envs
        if frame_stack > 1:
            if not obs_shape or obs_shape[0] % frame_stack:
                raise ValueError(f"observations of shape {obs_shape} are not stacks of {frame_stack} frames")
            frame = (obs_shape[0] // frame_stack, *obs_shape[1:])
            self.first_stacks = np.zeros((s, e, *obs_shape), dtype=observation_space.dtype)
            self.observations = np.zeros((s, t, e, *frame), dtype=observation_space.dtype)  # newest frames
        else:
            self.observations = np.zeros((s, t + 1, e, *obs_shape), dtype=observation_space.dtype)
        self.actions = np.zeros((s, t, e), dtype=np.int64)
        self.rewards = np.zeros((s, t, e), dtype=np.float32)
        self.dones = np.zeros((s, t, e), dtype=np.float32)
        self.timeout_values = np.zeros((s, t, e), dtype=np.float32)
        self.mu = np.zeros((s, t, e, n_actions), dtype=np.float32)
        # Zero rows mean "no teacher" (a distillation term weighs them by 0).
        self.teacher = np.zeros((s, t, e, n_actions), dtype=np.float32)
        self.followed = np.zeros((s, t, e), dtype=np.float32)
        self.pos = 0
        self.full = False

    ARRAYS = ("first_stacks", "observations", "actions", "rewards", "dones", "timeout_values", "mu", "teacher", "followed")

    def save(self, path: Union[str, Path]) -> None:
        """Write the buffer as arrays (numpy's ``.npz``, nothing pickled), to the exact ``path`` given."""
        arrays = {name: getattr(self, name) for name in self.ARRAYS if hasattr(self, name)}
        meta = np.array([self.n_steps, self.n_envs, self.n_actions, self.frame_stack, self.n_segments, self.pos,
                         int(self.full)], dtype=np.int64)
        with open(path, "wb") as f:
            np.savez(f, meta=meta, **arrays)

    @classmethod
    def load(cls, path: Union[str, Path]) -> "SegmentReplayBuffer":
        """
        A buffer written by :meth:`save` (read with ``allow_pickle=False``: nothing in the file can run).

        :raises ValueError: A file that is not such a buffer
        """
        try:
            with np.load(path, allow_pickle=False) as data:
                n_steps, n_envs, n_actions, frame_stack, n_segments, pos, full = (int(x) for x in data["meta"])
                buffer = cls.__new__(cls)
                buffer.n_steps, buffer.n_envs, buffer.n_actions = n_steps, n_envs, n_actions
                buffer.frame_stack, buffer.n_segments, buffer.pos, buffer.full = frame_stack, n_segments, pos, bool(full)
                for name in cls.ARRAYS:
                    if name in data:
                        setattr(buffer, name, data[name])
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
            raise ValueError(f"{path} is not a replay buffer this package wrote ({exc})") from None
        shapes = (n_segments, n_steps, n_envs)
        if any(getattr(buffer, name, None) is None for name in cls.ARRAYS[1:]) or buffer.actions.shape != shapes \
                or buffer.mu.shape != (*shapes, n_actions) or not 0 <= pos < n_segments:
            raise ValueError(f"{path} is not a replay buffer this package wrote (its arrays do not fit together)")
        return buffer

    @property
    def n_stored(self) -> int:
        """Number of segments stored."""
        return self.n_segments if self.full else self.pos

    def size(self) -> int:
        """Number of env transitions stored, over all envs."""
        return self.n_stored * self.n_steps * self.n_envs

    def add(self, segment: Segment) -> None:
        """
        Store a segment batch (copied), overwriting the oldest when full.

        :param segment: Segments of shape (T, E, ...) matching this buffer
        """
        i = self.pos
        if self.frame_stack > 1:
            self.first_stacks[i] = segment.observations[0]
            self.observations[i] = segment.observations[1:, :, -self.observations.shape[3]:]
        else:
            self.observations[i] = segment.observations
        self.actions[i] = segment.actions
        self.rewards[i] = segment.rewards
        self.dones[i] = segment.dones
        self.timeout_values[i] = segment.timeout_values
        self.mu[i] = segment.mu
        self.teacher[i] = 0.0 if segment.teacher is None else segment.teacher
        self.followed[i] = 0.0 if segment.followed is None else segment.followed
        self.pos = (self.pos + 1) % self.n_segments
        self.full = self.full or self.pos == 0

    def sample(self, rng: Optional[np.random.Generator] = None) -> Segment:
        """
        :param rng: Random generator; numpy's global one if None
        :return: One random stored segment for each environment, stacked as a (T, E, ...) batch
        """
        if self.n_stored == 0:
            raise ValueError("The replay buffer is empty")
        if rng is None:
            seg = np.random.randint(0, self.n_stored, size=self.n_envs)
        else:
            seg = rng.integers(0, self.n_stored, size=self.n_envs)
        env = np.arange(self.n_envs)
        dones = self.dones[seg, :, env].T
        # Advanced indexing over (segment, env) pairs puts that axis first: move it back behind time.
        if self.frame_stack > 1:
            frames = np.moveaxis(self.observations[seg, :, env], 0, 1)
            stacks = [self.first_stacks[seg, env]]
            for t in range(self.n_steps):
                stacks.append(push_frames(stacks[-1], frames[t], dones[t] > 0, self.frame_stack))
            observations = np.stack(stacks)
        else:
            observations = np.moveaxis(self.observations[seg, :, env], 0, 1)
        return Segment(
            observations=observations,
            actions=self.actions[seg, :, env].T,
            rewards=self.rewards[seg, :, env].T,
            dones=dones,
            timeout_values=self.timeout_values[seg, :, env].T,
            mu=np.moveaxis(self.mu[seg, :, env], 0, 1),
            teacher=np.moveaxis(self.teacher[seg, :, env], 0, 1),
            followed=self.followed[seg, :, env].T,
        )
