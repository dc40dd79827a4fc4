"""The scan environment: navigable grid from geometry, geodesic distance, expert, rendering, formats."""

import json
import math

import numpy as np
import pytest
from stable_baselines3.common.env_checker import check_env

from sb3_disagree.envs.expert import GridExpert
from sb3_disagree.envs.grid import GridField
from sb3_disagree.envs.mesh_scene import load_meshes, navigable_grid
from sb3_disagree.envs.office import WALL, _Builder
from sb3_disagree.envs.scan import ScanEnv


def _two_rooms(folder, fmt="glb"):
    """Two 3 x 3 m rooms side by side (x 0..3 and 3..6), a wall at x = 3 with a 1 m door at z 1..2."""
    b = _Builder()
    b.floor("a", 0, 0, 6, 3, "carpet", (120, 120, 160))
    b.wall_x(0, 0, 6)
    b.wall_x(3, 0, 6)
    b.wall_z(0, 0, 3)
    b.wall_z(6, 0, 3)
    b.wall_z(3, 0, 3, doors=[(1.0, 2.0)])
    path = folder / f"rooms.{fmt}"
    b.scene.export(path)
    goals = {"goals": {"east": {"position": [5.0, 1.5], "radius": 0.5}, "west": {"position": [1.0, 1.5], "radius": 0.5}},
             "regions": {"west room": [0, 0, 3, 3], "east room": [3, 0, 6, 3]}}
    (folder / "rooms.goals.json").write_text(json.dumps(goals))
    return path


def _expert_succeeds(env, expert, seed):
    env.reset(seed=seed)
    for _ in range(500):
        _, _, terminated, truncated, info = env.step(expert())
        if terminated or truncated:
            return terminated and info["is_success"]
    return False


@pytest.fixture(scope="module")
def rooms(tmp_path_factory):
    return _two_rooms(tmp_path_factory.mktemp("scene"))


def test_walls_are_blocked_and_the_doorway_is_open(rooms):
    grid = navigable_grid(load_meshes(rooms), cell=0.1, agent_radius=0.2)
    assert grid.floor_y == pytest.approx(0.0, abs=1e-6)
    # The partition wall: blocked within radius + half its thickness, except in the door.
    for z in (0.5, 2.5):
        for x in (3.0, 3.0 + 0.1, 3.0 - 0.1, 3.0 + 0.2):
            assert not grid.is_free(x, z), (x, z)
        assert grid.is_free(3.0 + WALL / 2 + 0.3, z) and grid.is_free(3.0 - WALL / 2 - 0.3, z)
    assert grid.is_free(3.0, 1.5)  # the middle of the doorway
    assert not grid.is_free(3.0, 1.0 + 0.1) and not grid.is_free(3.0, 2.0 - 0.1)  # too close to the door frame
    # Outer walls and outside the floor.
    assert not grid.is_free(0.1, 1.5) and not grid.is_free(5.9, 1.5) and not grid.is_free(7.0, 1.5)
    assert grid.is_free(1.5, 1.5) and grid.is_free(4.5, 1.5)


def test_geodesic_distance_matches_a_hand_count(rooms):
    grid = navigable_grid(load_meshes(rooms), cell=0.1, agent_radius=0.2)
    gi, gj = grid.index(1.0, 1.0)
    goal = np.zeros_like(grid.free)
    goal[gi, gj] = True
    field = GridField(grid.free, goal, grid.x0, grid.z0, grid.cell)
    # Inside one room: 6 straight steps and 4 diagonal ones (octile distance).
    assert field.dist[gi + 10, gj + 4] == pytest.approx(0.6 + 0.4 * math.sqrt(2), abs=1e-9)
    # Into the other room, the way goes through the door's lowest free cell, z = 1.3 (the frame at z = 1.0
    # plus the 0.2 m radius, the next cell beyond): (1.0, 1.0) -> (3.0, 1.3) -> (5.0, 1.0) is
    # 2 x (17 straight + 3 diagonal cells), against 4.0 m in a straight line.
    assert grid.is_free(3.0, 1.3) and not grid.is_free(3.0, 1.2)
    ei, ej = grid.index(5.0, 1.0)
    assert field.dist[ei, ej] == pytest.approx(2 * (1.7 + 0.3 * math.sqrt(2)), abs=1e-9)
    # Cells behind the wall are not reachable through it.
    wi, wj = grid.index(3.0, 0.5)
    assert not np.isfinite(field.dist[wi, wj])


def test_ply_gives_the_same_grid_as_glb(rooms, tmp_path):
    ply = _two_rooms(tmp_path, fmt="ply")
    a = navigable_grid(load_meshes(rooms))
    b = navigable_grid(load_meshes(ply))
    assert a.free.shape == b.free.shape and (a.free == b.free).all()


@pytest.mark.parametrize("scene,goal", [("rooms", "east"), ("office", "table")])
def test_expert_reaches_the_goal_from_50_random_starts(rooms, scene, goal):
    env = ScanEnv(goal=goal, scene=rooms if scene == "rooms" else None, obs="state")
    expert = GridExpert(env)
    for seed in range(50):
        assert _expert_succeeds(env, expert, seed), (scene, seed)


def test_rewards_follow_the_geodesic_distance(rooms):
    env = ScanEnv(goal="east", scene=rooms, obs="state")
    env.reset(seed=0)
    env.set_pose(1.5, 1.5, 0.0)  # west room, facing east toward the door
    before = env.distance
    _, reward, terminated, _, info = env.step(2)
    assert env.x == pytest.approx(1.75) and not terminated
    assert reward == pytest.approx(before - env.distance - 0.01)
    assert info["room"] == "west room" and info["goal_room"] == "east room"
    env.set_pose(2.6, 0.5, 0.0)  # facing the wall: the step is refused
    env.step(2)
    assert env.x == pytest.approx(2.6)


def test_check_env_and_deterministic_rendering(rooms):
    for obs in ("state", "rgb"):
        check_env(ScanEnv(goal="east", scene=rooms, obs=obs))
    a, b = ScanEnv(goal="east", scene=rooms), ScanEnv(goal="west", scene=rooms)
    frames = []
    for env in (a, b, a):
        env.reset(seed=1)
        env.set_pose(1.5, 1.5, 0.3)
        frames.append(env._obs())
    assert frames[0].shape == (60, 80, 3) and frames[0].std() > 5
    assert (frames[0] == frames[1]).all() and (frames[0] == frames[2]).all()
    a.set_pose(1.5, 1.5, 0.3 + math.pi)
    assert not (a._obs() == frames[0]).all()


def test_unknown_goal_and_missing_scene_are_clear_errors(rooms, tmp_path):
    with pytest.raises(ValueError, match="unknown goal 'sink'.*east, west"):
        ScanEnv(goal="sink", scene=rooms)
    with pytest.raises(FileNotFoundError, match="no scene"):
        ScanEnv(goal="east", scene=tmp_path / "nothing.glb")
    with pytest.raises(ValueError, match="geodesic distance only"):
        ScanEnv(goal="east", scene=rooms, reward_distance="euclidean")
    assert ScanEnv(goal="east", scene=rooms, obs="state", reward_distance="geodesic").reward_distance == "geodesic"


def test_every_goal_of_the_shipped_office_is_reachable():
    from sb3_disagree.envs.mesh_scene import SceneGoals, goals_path
    from sb3_disagree.envs.scan import DEFAULT_SCENE

    goals = SceneGoals.load(goals_path(DEFAULT_SCENE)).goals
    assert {"table", "sofa", "fridge"} <= set(goals)
    assert {SceneGoals.load(goals_path(DEFAULT_SCENE)).region_at(goals[g].x, goals[g].z) for g in ("table", "sofa", "fridge")} \
        == {"canteen"}
    for goal in goals:
        env = ScanEnv(goal=goal, obs="state")
        expert = GridExpert(env)
        for seed in range(5):
            assert _expert_succeeds(env, expert, seed), (goal, seed)


def test_the_method_runs_on_the_office_end_to_end(tmp_path):
    from typer.testing import CliRunner

    from sb3_disagree.cli.app import app

    runner, env_id, zoo = CliRunner(), "sb3_disagree/OfficeState-v0", tmp_path / "zoo"
    for goal in ("sofa", "fridge"):
        r = runner.invoke(app, ["priors", "train", "--goal", goal, "--env", env_id, "--zoo", str(zoo), "--rounds", "1",
                                "--steps-per-round", "200", "--epochs", "1", "--episodes", "2"])
        assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["train", "--goal", "table", "--env", env_id, "--zoo", str(zoo), "--out", str(tmp_path / "runs"),
                            "--steps", "400", "--n-envs", "2", "--mode", "room-sensor"])
    assert r.exit_code == 0, r.output
    assert "priors: sofa" in r.output or "priors: fridge" in r.output
    assert (tmp_path / "runs" / "sb3_disagree__OfficeState-v0" / "table" / "room-sensor-0" / "model.zip").exists()


def test_the_expert_that_does_not_return_leaves_the_loops_the_memoryless_one_keeps():
    """From office starts where the memoryless expert (DAgger's default labels) stays in a loop until the cut, pressing
    against an obstacle (seed 10027) or turning left and right (10110), ``expert_action(no_return=True)`` reaches the
    sofa, never staying in place or going back to the pose before; ``previous_pose`` is the pose before the last step."""
    from sb3_disagree.envs.expert import _pose_key

    env = ScanEnv(goal="sofa", obs="state")
    for seed in (10027, 10110):
        for no_return in (False, True):
            env.reset(seed=seed)
            assert env.previous_pose is None
            poses, done = [_pose_key(env.x, env.z, env.heading)], False
            while not done:
                before = (env.x, env.z, env.heading)
                _, _, terminated, truncated, info = env.step(env.expert_action(no_return=no_return))
                assert env.previous_pose == before
                poses.append(_pose_key(env.x, env.z, env.heading))
                done = terminated or truncated
            assert info["is_success"] == no_return, (seed, no_return)
            returns = sum(p in (q, r) for p, q, r in zip(poses[2:], poses[1:], poses))
            assert (returns == 0) if no_return else returns > 400, (seed, returns)
