"""
The apartment of the paper's first experiment: a bedroom, a kitchen and a bathroom off a corridor,
coloured boxes as objects, the agent starting at a random pose in the corridor.

``obs="rgb"`` renders the egocentric view with MiniWorld (60x80 by default); ``obs="state"`` returns
position and heading and renders nothing. Both move the agent with :mod:`sb3_disagree.envs.layout`,
so their dynamics and rewards are identical.
"""

import math
from typing import Any, Optional

import numpy as np
from gymnasium import spaces

from sb3_disagree.envs.layout import CORRIDOR, Layout, default_layout
from sb3_disagree.envs.navigation import MAX_EPISODE_STEPS, MOVE_FORWARD, TURN_LEFT, TURN_RIGHT, NavigationEnv


class ApartmentEnv(NavigationEnv):
    """
    ## Description

    The apartment of the paper's first experiment: a bedroom, a kitchen and a bathroom off a corridor, with
    coloured boxes as objects. The agent starts at a random pose in the corridor and must reach one goal
    object. Registered as ``sb3_disagree/Apartment-v0`` (egocentric RGB) and
    ``sb3_disagree/ApartmentState-v0`` (pose), both on ``import sb3_disagree``.

    ## Action Space

    ``Discrete(3)``: 0 turn left, 1 turn right (``turn_step`` degrees, 30 by default), 2 move forward
    (``forward_step`` metres, 0.25 by default; blocked moves leave the agent where it is).

    ## Observation Space

    ``obs="rgb"``: ``Box(0, 255, (obs_height, obs_width, 3), uint8)``, the egocentric MiniWorld render
    (60x80 by default). ``obs="state"``: ``Box(-1, 1, (4,), float32)``, ``(x / 8, z / 8, cos t, sin t)``.

    ## Rewards

    Each step: the decrease of the distance to the goal object, minus ``step_penalty`` (0.01); plus
    ``success_reward`` (10) on reaching it; minus ``collision_penalty`` (0 by default) when a move_forward is
    blocked. The distance is Euclidean by default (``reward_distance="euclidean"``); ``"geodesic"`` follows
    the shortest free path instead (through the doorways, around walls and objects), as the office scans do.

    ## Starting State

    A uniformly random free position in the corridor and a uniformly random heading.

    ## Episode End

    Termination once the agent is within reach of the goal (MiniWorld's ``near``: the bounding circles
    plus 1.1 forward steps; ``info["is_success"]`` is then true); truncation after ``max_episode_steps``
    (500). ``info`` also holds ``room``, ``goal_room``, ``position``, ``heading`` and ``distance``.

    ## Arguments

    :param goal: Name of the goal object (shower, bathtub, toilet, bed, wardrobe, nightstand, stove,
        toaster, microwave, table)
    :param obs: "rgb" for the egocentric render (uint8, HWC), "state" for ``(x/8, z/8, cos t, sin t)``
    :param obs_width: Width of the RGB observation
    :param obs_height: Height of the RGB observation
    :param max_episode_steps: Steps before truncation
    :param forward_step: Distance of one move_forward, in metres
    :param turn_step: Angle of one turn, in degrees
    :param step_penalty: Subtracted from the reward every step
    :param success_reward: Added on reaching the goal
    :param collision_penalty: Subtracted when move_forward is blocked (0 by default, as in the paper)
    :param reward_distance: "euclidean" (the straight line to the goal) or "geodesic" (the shortest free path,
        the grid expert's distance field): what the reward's distance follows; success is the same either way
    :param render_mode: "rgb_array" makes ``render()`` return the top-down map with the episode's path
    :param layout: The apartment; the paper's by default
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        goal: str = "bathtub",
        obs: str = "rgb",
        obs_width: int = 80,
        obs_height: int = 60,
        max_episode_steps: int = MAX_EPISODE_STEPS,
        forward_step: float = 0.25,
        turn_step: float = 30.0,
        step_penalty: float = 0.01,
        success_reward: float = 10.0,
        collision_penalty: float = 0.0,
        reward_distance: str = "euclidean",
        render_mode: Optional[str] = None,
        layout: Optional[Layout] = None,
    ) -> None:
        self.layout = layout or default_layout()
        self.goal = self.layout.object(goal)
        if obs not in ("rgb", "state"):
            raise ValueError(f"obs must be 'rgb' or 'state', got {obs!r}")
        if reward_distance not in ("euclidean", "geodesic"):
            raise ValueError(f"reward_distance must be 'euclidean' or 'geodesic', got {reward_distance!r}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.obs_mode = obs
        self.max_episode_steps = max_episode_steps
        self.forward_step = forward_step
        self.turn_step = math.radians(turn_step)
        self.step_penalty = step_penalty
        self.success_reward = success_reward
        self.collision_penalty = collision_penalty
        self.reward_distance = reward_distance
        self.render_mode = render_mode
        self.reach = self.goal.radius + self.layout.agent_radius + 1.1 * forward_step
        self.action_space = spaces.Discrete(3)
        if obs == "rgb":
            self.observation_space = spaces.Box(0, 255, (obs_height, obs_width, 3), dtype=np.uint8)
        else:
            self.observation_space = spaces.Box(-1.0, 1.0, (4,), dtype=np.float32)
        self._obs_size = (obs_width, obs_height)
        self._renderer = None
        self._nav_field = None
        self._init_pose()

    # ------------------------------------------------------------------ pose and observation

    @property
    def renderer(self):
        """The MiniWorld scene, built on first use (creating an OpenGL context costs seconds)."""
        if self._renderer is None:
            from sb3_disagree.envs.render import ApartmentRenderer

            self._renderer = ApartmentRenderer(self.layout, *self._obs_size)
        return self._renderer

    @property
    def distance(self) -> float:
        if self.reward_distance == "geodesic":
            return self.nav_field().cost(self.x, self.z)
        return math.hypot(self.goal.x - self.x, self.goal.z - self.z)

    def _obs(self) -> np.ndarray:
        if self.obs_mode == "state":
            return np.array([self.x / 8.0, self.z / 8.0, math.cos(self.heading), math.sin(self.heading)],
                            dtype=np.float32)
        return self.renderer.egocentric(self.x, self.z, self.heading)

    def _info(self, success: bool = False) -> dict[str, Any]:
        return {
            "room": self.layout.room_at(self.x, self.z),
            "goal_room": self.goal.room,
            "position": (self.x, self.z),
            "heading": self.heading,
            "distance": self.distance,
            "is_success": success,
        }

    # What the grid expert reads (sb3_disagree.envs.expert.GridExpert).
    @property
    def goal_xz(self) -> tuple[float, float]:
        return self.goal.x, self.goal.z

    def blocked(self, x: float, z: float) -> bool:
        return self.layout.blocked(x, z)

    def nav_field(self):
        # Kept on the env: with the geodesic reward it is read twice a step, and the shared cache hashes the layout.
        if self._nav_field is None:
            from sb3_disagree.envs.expert import layout_field

            self._nav_field = layout_field(self.layout, self.goal.name, self.reach)
        return self._nav_field

    def _sample_pose(self) -> tuple[float, float, float]:
        c, r = self.layout.corridor, self.layout.agent_radius
        while True:
            x = self.np_random.uniform(c.min_x + r, c.max_x - r)
            z = self.np_random.uniform(c.min_z + r, c.max_z - r)
            if not self.layout.blocked(x, z):
                return x, z, self.np_random.uniform(-math.pi, math.pi)

    def render(self) -> Optional[np.ndarray]:
        if self.render_mode != "rgb_array":
            return None
        from sb3_disagree.envs.topdown import draw_trajectory

        return draw_trajectory(self.layout, self.path, goal=self.goal.name, background=self._top_view())

    def first_person(self, pose: Optional[tuple[float, float, float]] = None) -> np.ndarray:
        """The agent's view, uint8 (H, W, 3), whatever the observations are (for videos): from ``pose`` (x, z,
        heading), by default the agent's own."""
        pose = pose or (self.x, self.z, self.heading)
        return self.renderer.egocentric(*pose)

    def _top_view(self) -> Optional[np.ndarray]:
        return self.renderer.top_view() if self.obs_mode == "rgb" else None

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


__all__ = ["CORRIDOR", "MOVE_FORWARD", "TURN_LEFT", "TURN_RIGHT", "ApartmentEnv"]
