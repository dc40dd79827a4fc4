"""
Navigation in a 3D scan (the paper's second experiment, without habitat-sim): the agent starts at a
uniformly random navigable pose anywhere in the scene, sees egocentric RGB, and must reach a named goal
within 500 actions. Habitat's actions: move_forward 0.25 m, turn_left and turn_right (30 degrees here,
as in the apartment; Habitat's PointNav default is 10).

Reward per step: the decrease of the geodesic distance to the goal (shortest path through the
navigable grid), minus ``step_penalty``; ``success_reward`` and termination once the agent is within
the goal's radius (straight-line distance to the goal point). The same ``info`` keys as the apartment.
"""

import math
from functools import lru_cache
from pathlib import Path
from typing import Any, Optional, Union

import numpy as np
from gymnasium import spaces

from sb3_disagree.envs.grid import GridField
from sb3_disagree.envs.mesh_scene import NavGrid, SceneGoals, goals_path, load_meshes, navigable_grid
from sb3_disagree.envs.navigation import MAX_EPISODE_STEPS, MOVE_FORWARD, TURN_LEFT, TURN_RIGHT, NavigationEnv

DEFAULT_SCENE = Path(__file__).resolve().parent / "scenes" / "office.glb"


@lru_cache(maxsize=8)
def _scene(path: str, cell: float, agent_radius: float) -> tuple[list, NavGrid]:
    meshes = load_meshes(Path(path))
    return meshes, navigable_grid(meshes, cell=cell, agent_radius=agent_radius)


@lru_cache(maxsize=64)
def _field(path: str, cell: float, agent_radius: float, x: float, z: float, radius: float, margin: float = 0.1
           ) -> GridField:
    grid = _scene(path, cell, agent_radius)[1]
    gx, gz = grid.coordinates()
    # Paths keep ``margin`` more clearance than the agent needs (gaps one cell wide are no way for an agent
    # that turns by 30 degrees), and aim a little inside the success radius, so that following them succeeds.
    return GridField(grid.eroded(margin), np.hypot(gx - x, gz - z) < radius - 0.05, grid.x0, grid.z0, grid.cell)


class ScanEnv(NavigationEnv):
    """
    ## Description

    Navigation in a 3D scan (the paper's second experiment, without habitat-sim): reach a named goal in a
    scene mesh from a random navigable pose. Registered as ``sb3_disagree/Office-v0`` (egocentric RGB) and
    ``sb3_disagree/OfficeState-v0`` (pose) on the generated office floor; ``scene=`` takes any scan with a
    goals file.

    ## Action Space

    ``Discrete(3)``, Habitat's: 0 turn left, 1 turn right (``turn_step`` degrees, 30 by default), 2 move
    forward (``forward_step`` metres, 0.25 by default; blocked moves leave the agent where it is).

    ## Observation Space

    ``obs="rgb"``: ``Box(0, 255, (obs_height, obs_width, 3), uint8)``, rendered by EGL (60x80 by default).
    ``obs="state"``: ``Box(-1, 1, (4,), float32)``, ``x, z`` scaled by the scene's size, ``cos t, sin t``.

    ## Rewards

    Each step: the decrease of the geodesic distance to the goal (the shortest path through the navigable
    grid), minus ``step_penalty`` (0.01); plus ``success_reward`` (10) on reaching it; minus ``collision_penalty``
    (0 by default) when a move_forward is blocked.

    ## Starting State

    A uniformly random navigable position anywhere in the scene and a uniformly random heading.

    ## Episode End

    Termination once the agent is within the goal's radius (straight-line distance to the goal point;
    ``info["is_success"]`` is then true); truncation after ``max_episode_steps`` (500). ``info`` holds the
    same keys as the apartment's.

    ## Arguments

    :param goal: A goal named in the scene's goals file
    :param scene: A .glb/.gltf/.obj/.ply scene with ``<name>.goals.json`` beside it (default: the
        generated office floor)
    :param obs: "rgb" (uint8, HWC) or "state" (``x, z`` scaled by the scene size, ``cos t, sin t``)
    :param obs_width: Width of the RGB observation
    :param obs_height: Height of the RGB observation
    :param hfov: Horizontal field of view in degrees
    :param camera_height: Camera height above the floor in metres
    :param max_episode_steps: Steps before truncation
    :param forward_step: Distance of one move_forward, in metres
    :param turn_step: Angle of one turn, in degrees
    :param agent_radius: Clearance kept from obstacles, in metres
    :param cell: Resolution of the navigable grid, in metres
    :param step_penalty: Subtracted from the reward every step
    :param success_reward: Added on reaching the goal
    :param collision_penalty: Subtracted when move_forward is blocked (0 by default, as in the paper)
    :param reward_distance: "geodesic", the only distance a scan's reward follows (the argument exists so that
        the apartment's ``reward_distance`` can be passed to either env)
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        goal: str = "table",
        scene: Union[str, Path, None] = None,
        obs: str = "rgb",
        obs_width: int = 80,
        obs_height: int = 60,
        hfov: float = 90.0,
        camera_height: float = 1.25,
        max_episode_steps: int = MAX_EPISODE_STEPS,
        forward_step: float = 0.25,
        turn_step: float = 30.0,
        agent_radius: float = 0.2,
        cell: float = 0.1,
        step_penalty: float = 0.01,
        success_reward: float = 10.0,
        collision_penalty: float = 0.0,
        reward_distance: str = "geodesic",
        render_mode: Optional[str] = None,
    ) -> None:
        if reward_distance != "geodesic":
            raise ValueError(f"a scan's reward follows the geodesic distance only, got reward_distance={reward_distance!r}")
        self.scene_path = str(Path(scene) if scene is not None else DEFAULT_SCENE)
        if not Path(self.scene_path).exists():
            raise FileNotFoundError(f"no scene at {self.scene_path}")
        self.scene_goals = SceneGoals.load(goals_path(Path(self.scene_path)))
        if goal not in self.scene_goals.goals:
            raise ValueError(f"unknown goal {goal!r} for {self.scene_path}; goals: {', '.join(self.scene_goals.goals)}")
        if obs not in ("rgb", "state"):
            raise ValueError(f"obs must be 'rgb' or 'state', got {obs!r}")
        self.goal = self.scene_goals.goals[goal]
        self.obs_mode, self.render_mode = obs, render_mode
        self.obs_width, self.obs_height, self.hfov, self.camera_height = obs_width, obs_height, hfov, camera_height
        self.max_episode_steps, self.forward_step = max_episode_steps, forward_step
        self.turn_step = math.radians(turn_step)
        self.agent_radius, self.cell = agent_radius, cell
        self.step_penalty, self.success_reward = step_penalty, success_reward
        self.collision_penalty = collision_penalty
        self.reward_distance = reward_distance
        self.reach = self.goal.radius
        self.meshes, self.grid = _scene(self.scene_path, cell, agent_radius)
        self.field = _field(self.scene_path, cell, agent_radius, self.goal.x, self.goal.z, self.goal.radius)
        # Starts: any navigable cell that reaches the goal and is not already at it.
        gx, gz = self.grid.coordinates()
        starts = self.field.reachable & (np.hypot(gx - self.goal.x, gz - self.goal.z) >= self.goal.radius)
        self._starts = np.argwhere(starts)
        self.extent = max(self.grid.free.shape) * cell
        self.action_space = spaces.Discrete(3)
        if obs == "rgb":
            self.observation_space = spaces.Box(0, 255, (obs_height, obs_width, 3), dtype=np.uint8)
        else:
            self.observation_space = spaces.Box(-1.0, 1.0, (4,), dtype=np.float32)
        self._renderer = None
        self._init_pose()

    @property
    def renderer(self):
        if self._renderer is None:
            from sb3_disagree.envs.mesh_render import MeshRenderer

            self._renderer = MeshRenderer(self.meshes, self.obs_width, self.obs_height, self.hfov, self.camera_height,
                                          self.grid.floor_y)
        return self._renderer

    # What the grid expert reads (sb3_disagree.envs.expert.GridExpert).
    @property
    def goal_xz(self) -> tuple[float, float]:
        return self.goal.x, self.goal.z

    def blocked(self, x: float, z: float) -> bool:
        return not self.grid.is_free(x, z)

    def nav_field(self) -> GridField:
        return self.field

    @property
    def distance(self) -> float:
        """Geodesic distance to the goal point's region."""
        return self.field.cost(self.x, self.z)

    def _obs(self) -> np.ndarray:
        if self.obs_mode == "state":
            return np.array([self.x / self.extent, self.z / self.extent, math.cos(self.heading), math.sin(self.heading)],
                            dtype=np.float32)
        return self.renderer.render(self.x, self.z, self.heading)

    def _info(self, success: bool = False) -> dict[str, Any]:
        return {
            "room": self.scene_goals.region_at(self.x, self.z),
            "goal_room": self.scene_goals.region_at(self.goal.x, self.goal.z),
            "position": (self.x, self.z),
            "heading": self.heading,
            "distance": self.distance,
            "is_success": success,
        }

    def _sample_pose(self) -> tuple[float, float, float]:
        i, j = self._starts[self.np_random.integers(len(self._starts))]
        x, z = self.field.point(int(i), int(j))
        return x, z, self.np_random.uniform(-math.pi, math.pi)

    def first_person(self, pose: Optional[tuple[float, float, float]] = None) -> np.ndarray:
        """The agent's view, uint8 (H, W, 3), whatever the observations are (for videos): from ``pose`` (x, z,
        heading), by default the agent's own."""
        pose = pose or (self.x, self.z, self.heading)
        return self.renderer.render(*pose)

    def render(self) -> Optional[np.ndarray]:
        if self.render_mode != "rgb_array":
            return None
        return self.first_person()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


__all__ = ["DEFAULT_SCENE", "MOVE_FORWARD", "TURN_LEFT", "TURN_RIGHT", "ScanEnv"]
