"""
A policy's short memory: the last ``k`` observations stacked along the first (channel) axis.

The stack is the state a stacking policy carries between calls of ``predict`` (as SB3's recurrent
policies carry their hidden state), so that SB3's ``evaluate_policy`` and any loop that passes ``state``
and ``episode_start`` back use it with the env as registered, no wrapper. Frames from before an
episode's start are zeros, as in SB3's ``VecFrameStack``.
"""

from typing import Optional

import numpy as np
from gymnasium import spaces


def stacked_space(space: spaces.Box, k: int) -> spaces.Box:
    """
    The space of ``k`` observations of ``space`` stacked along axis 0 (channels first for images).

    :param space: The single observation's space
    :param k: Number of observations in the stack
    """
    if k == 1:
        return space
    if not isinstance(space, spaces.Box):
        raise ValueError(f"frame stacking needs a Box observation space, got {space}")
    low = np.concatenate([space.low] * k, axis=0)
    high = np.concatenate([space.high] * k, axis=0)
    return spaces.Box(low=low, high=high, dtype=space.dtype)  # type: ignore[arg-type]


def push_frames(stack: Optional[np.ndarray], obs: np.ndarray, episode_starts: Optional[np.ndarray], k: int) -> np.ndarray:
    """
    The stack after ``obs`` arrives: the oldest frame drops out, ``obs`` is the newest (last) one; where an
    episode starts, the earlier frames are zeros.

    :param stack: The previous stacks, shape (n, k * c, ...), or None (all zeros)
    :param obs: The new observations, shape (n, c, ...)
    :param episode_starts: True where ``obs`` is the first observation of an episode; None for none
    :param k: Number of frames in the stack
    :return: The new stacks, shape (n, k * c, ...); ``obs`` itself when ``k`` is 1
    """
    if k == 1:
        return obs
    c = obs.shape[1]
    new = np.zeros((obs.shape[0], k * c, *obs.shape[2:]), dtype=obs.dtype)
    if stack is not None:
        new[:, : (k - 1) * c] = stack[:, c:]
    if episode_starts is not None:
        new[np.asarray(episode_starts, dtype=bool), : (k - 1) * c] = 0
    new[:, (k - 1) * c :] = obs
    return new


class LinkedFrames:
    """
    Many stacks held as single frames: each frame links to the frame before it in its env's episode (-1 at
    an episode's start), and ``frames[idx]`` rebuilds the stacks of those frames as :func:`push_frames` built
    them along the way, in ``1 / k`` of the memory the stacks would take.

    :param frames: The frames, shape (n, c, ...)
    :param previous: For each frame the index of the one before it in the same episode, or -1; shape (n,)
    :param k: Number of frames in a stack
    """

    def __init__(self, frames: np.ndarray, previous: np.ndarray, k: int) -> None:
        self.frames, self.previous, self.k = frames, previous, k

    def __len__(self) -> int:
        return len(self.frames)

    def __getitem__(self, idx: np.ndarray) -> np.ndarray:
        idx = np.asarray(idx)
        c = self.frames.shape[1]
        out = np.zeros((len(idx), self.k * c, *self.frames.shape[2:]), dtype=self.frames.dtype)
        current = idx.copy()
        for j in range(self.k - 1, -1, -1):  # newest frame last, walking back through the episode
            held = current >= 0
            out[held, j * c:(j + 1) * c] = self.frames[current[held]]
            current = np.where(held, self.previous[np.maximum(current, 0)], -1)
        return out
