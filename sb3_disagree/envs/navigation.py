"""
What the apartment and the scans share: Habitat-style actions on a pose (x, z, heading), the reward
(decrease of a distance to the goal, a step penalty, a success bonus, an optional penalty for a blocked move),
truncation, and the interface the grid expert reads.
"""

import math
from typing import Any, Optional

import gymnasium as gym
import numpy as np

from sb3_disagree.envs.actions import MOVE_FORWARD, TURN_LEFT, TURN_RIGHT, Actions, wrap

__all__ = ["MAX_EPISODE_STEPS", "MOVE_FORWARD", "TURN_LEFT", "TURN_RIGHT", "Actions", "NavigationEnv", "wrap"]

# Steps before an episode is truncated, unless an env is made with another max_episode_steps.
MAX_EPISODE_STEPS = 500



class NavigationEnv(gym.Env):
    """
    A goal-reaching task on a pose. Subclasses set ``forward_step``, ``turn_step`` (radians),
    ``step_penalty``, ``success_reward``, ``max_episode_steps`` and ``reach``, and define
    ``distance`` (what the reward follows), ``blocked(x, z)``, ``goal_xz``,
    ``nav_field()``, ``_sample_pose()``, ``_obs()`` and ``_info(success)``.
    """

    forward_step: float
    turn_step: float
    step_penalty: float
    success_reward: float
    max_episode_steps: int
    reach: float
    # Subtracted when move_forward is blocked (0: the paper's reward). With the distance reward alone a blocked
    # move costs one step penalty, so pressing into a wall is nearly free and a greedy policy can stay there.
    collision_penalty: float = 0.0

    def _init_pose(self) -> None:
        self._expert = None
        self.x = self.z = self.heading = 0.0
        self.step_count = 0
        self.path: list[tuple[float, float]] = []
        self.previous_pose: Optional[tuple[float, float, float]] = None  # before the last step; None at a reset

    @property
    def distance(self) -> float:
        raise NotImplementedError

    @property
    def goal_xz(self) -> tuple[float, float]:
        raise NotImplementedError

    def reached(self) -> bool:
        """Within ``reach`` of the goal point in a straight line (whatever distance the reward follows)."""
        gx, gz = self.goal_xz
        return math.hypot(gx - self.x, gz - self.z) < self.reach

    def blocked(self, x: float, z: float) -> bool:
        raise NotImplementedError

    def nav_field(self):
        raise NotImplementedError

    def _sample_pose(self) -> tuple[float, float, float]:
        raise NotImplementedError

    def _obs(self) -> np.ndarray:
        raise NotImplementedError

    def _info(self, success: bool = False) -> dict[str, Any]:
        raise NotImplementedError

    def set_pose(self, x: float, z: float, heading: float) -> None:
        """Put the agent at a pose (for tests, pictures and the expert); the episode goes on from there."""
        self.x, self.z, self.heading = float(x), float(z), float(heading)

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.set_pose(*self._sample_pose())
        self.step_count = 0
        self.path = [(self.x, self.z)]
        self.previous_pose = None
        return self._obs(), self._info()

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict]:
        action = int(action)
        if not self.action_space.contains(action):
            raise ValueError(f"invalid action {action}; actions are 0 turn left, 1 turn right, 2 move forward")
        before, collided = self.distance, False
        self.previous_pose = (self.x, self.z, self.heading)
        if action == TURN_LEFT:
            self.heading = wrap(self.heading + self.turn_step)
        elif action == TURN_RIGHT:
            self.heading = wrap(self.heading - self.turn_step)
        else:
            x = self.x + self.forward_step * math.cos(self.heading)
            z = self.z - self.forward_step * math.sin(self.heading)
            collided = self.blocked(x, z)
            if not collided:
                self.x, self.z = x, z
        self.step_count += 1
        self.path.append((self.x, self.z))
        success = self.reached()
        reward = before - self.distance - self.step_penalty + (self.success_reward if success else 0.0)
        if collided:
            reward -= self.collision_penalty
        truncated = not success and self.step_count >= self.max_episode_steps
        return self._obs(), reward, success, truncated, self._info(success)

    def expert_action(self, no_return: bool = False) -> int:
        """
        The grid expert's action for the current state (what DAgger labels with).

        :param no_return: Never an action that leaves the pose as it is (a blocked move) or returns to the pose
            before the last step (turning back): the receding horizon's local minima then cannot hold it in a
            loop. A function of the last two poses, which a policy seeing two frames or more can tell apart
        """
        if self._expert is None:
            from sb3_disagree.envs.expert import GridExpert

            self._expert = GridExpert(self)
        avoid = [(self.x, self.z, self.heading), self.previous_pose] if no_return else []
        return self._expert.planned_action(self.x, self.z, self.heading, [p for p in avoid if p is not None])
