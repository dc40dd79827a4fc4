"""Tiny environments for the tests, and a callback that interrupts a run."""

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback


class ChainEnv(gym.Env):
    """
    A line of `length` cells; action 1 moves right, action 0 left (a third action stays). Reaching the right
    end gives +1 and terminates. Observation: one-hot position.
    """

    def __init__(self, length: int = 5, n_actions: int = 2) -> None:
        self.length = length
        self.observation_space = spaces.Box(0.0, 1.0, (length,), dtype=np.float32)
        self.action_space = spaces.Discrete(n_actions)
        self.pos = 0

    def _obs(self) -> np.ndarray:
        obs = np.zeros(self.length, dtype=np.float32)
        obs[self.pos] = 1.0
        return obs

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.pos = 0
        return self._obs(), {}

    def step(self, action):
        self.pos = int(np.clip(self.pos + {0: -1, 1: 1}.get(int(action), 0), 0, self.length - 1))
        terminated = self.pos == self.length - 1
        return self._obs(), float(terminated), terminated, False, {"is_success": terminated}


class ImageEnv(gym.Env):
    """A 40x40 RGB observation whose brightness says which of 3 actions pays; one-step episodes."""

    def __init__(self) -> None:
        self.observation_space = spaces.Box(0, 255, (40, 40, 3), dtype=np.uint8)
        self.action_space = spaces.Discrete(3)
        self.target = 0

    def _obs(self) -> np.ndarray:
        return np.full((40, 40, 3), 60 * (self.target + 1), dtype=np.uint8)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.target = int(self.np_random.integers(3))
        return self._obs(), {}

    def step(self, action):
        return self._obs(), float(int(action) == self.target), True, False, {}


class CueEnv(gym.Env):
    """
    A memory task: the first observation shows a cue (one of two), the second a blank corridor; the action
    taken at the corridor pays +1 where it names the cue. A policy that sees only the current observation
    wins half the time; one that remembers the cue always.
    """

    def __init__(self) -> None:
        self.observation_space = spaces.Box(0.0, 1.0, (3,), dtype=np.float32)
        self.action_space = spaces.Discrete(2)
        self.cue, self.t = 0, 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.cue, self.t = int(self.np_random.integers(2)), 0
        return np.eye(3, dtype=np.float32)[self.cue], {}

    def step(self, action):
        self.t += 1
        if self.t == 1:
            return np.eye(3, dtype=np.float32)[2], 0.0, False, False, {}
        success = int(action) == self.cue
        return np.eye(3, dtype=np.float32)[2], float(success), True, False, {"is_success": success}


class TurnEnv(gym.Env):
    """
    A line of 5 cells walked with the apartment's actions: 0 turns left, 1 right (a quarter turn), 2 moves one
    cell along the heading (east or west; facing north or south it is blocked). The east end is the goal
    (``is_success``); episodes start anywhere else facing anywhere and are cut after 40 steps. Observation:
    one-hot of (cell, heading). A policy that always turns spins in place: a greedy loop.
    """

    def __init__(self) -> None:
        self.observation_space = spaces.Box(0.0, 1.0, (20,), dtype=np.float32)
        self.action_space = spaces.Discrete(3)
        self.pos, self.heading, self.t = 0, 0, 0

    def _obs(self) -> np.ndarray:
        return np.eye(20, dtype=np.float32)[4 * self.pos + self.heading]

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.pos, self.heading, self.t = int(self.np_random.integers(4)), int(self.np_random.integers(4)), 0
        return self._obs(), {}

    def step(self, action):
        self.t += 1
        if action == 2:
            self.pos = int(np.clip(self.pos + {0: 1, 2: -1}.get(self.heading, 0), 0, 4))
        else:
            self.heading = (self.heading + (1 if action == 0 else -1)) % 4
        success = self.pos == 4
        return self._obs(), float(success), success, self.t >= 40 and not success, {"is_success": success}

    def expert_action(self) -> int:
        """Face east (turning the short way round; from west, left), then move."""
        return {0: 2, 1: 1, 2: 0, 3: 0}[self.heading]


class StopAt(BaseCallback):
    """Interrupt training (as Ctrl-C does) once ``at`` env steps are reached."""

    def __init__(self, at: int) -> None:
        super().__init__()
        self.at = at

    def _on_step(self) -> bool:
        if self.num_timesteps >= self.at:
            raise KeyboardInterrupt
        return True
