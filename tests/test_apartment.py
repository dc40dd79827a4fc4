"""The apartment: API, reward terms on constructed situations, rooms, walls, expert."""

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import sb3_disagree.envs  # noqa: F401  (registers the environments)
from sb3_disagree.envs import APARTMENT_ID, APARTMENT_STATE_ID, ApartmentEnv, default_layout
from sb3_disagree.envs.apartment import MOVE_FORWARD, TURN_LEFT, TURN_RIGHT
from sb3_disagree.envs.expert import ApartmentExpert

LAYOUT = default_layout()
EAST, NORTH, WEST, SOUTH = 0.0, math.pi / 2, math.pi, -math.pi / 2  # north is -z


@pytest.fixture(scope="module")
def rgb_env():
    env = gym.make(APARTMENT_ID, goal="bathtub")
    yield env
    env.close()


def test_check_env_state_variant():
    check_env(gym.make(APARTMENT_STATE_ID, goal="bathtub").unwrapped, skip_render_check=True)


def test_check_env_rgb_variant(rgb_env):
    check_env(rgb_env.unwrapped, skip_render_check=True)
    obs, info = rgb_env.reset(seed=0)
    assert obs.shape == (60, 80, 3) and obs.dtype == np.uint8 and obs.std() > 5


def test_same_seed_same_episode(rgb_env):
    def run(env, seed):
        obs, _ = env.reset(seed=seed)
        frames, rewards = [obs], []
        rng = np.random.default_rng(1)
        for _ in range(30):
            obs, r, term, trunc, info = env.step(int(rng.integers(3)))
            frames.append(obs)
            rewards.append(r)
        return np.stack(frames), rewards, info["position"]

    a, b, c = run(rgb_env, 7), run(rgb_env, 7), run(rgb_env, 8)
    assert np.array_equal(a[0], b[0]) and a[1] == b[1] and a[2] == b[2]
    assert not np.array_equal(a[0][0], c[0][0])


def test_state_and_rgb_variants_have_identical_dynamics(rgb_env):
    state = ApartmentEnv(goal="bathtub", obs="state")
    rgb_env.reset(seed=3)
    state.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(100):
        a = int(rng.integers(3))
        _, r1, t1, tr1, i1 = rgb_env.step(a)
        _, r2, t2, tr2, i2 = state.step(a)
        assert (r1, t1, tr1) == (r2, t2, tr2) and i1["position"] == i2["position"]


def test_reward_closing_distance_and_step_into_wall():
    env = ApartmentEnv(goal="bathtub", obs="state")
    env.reset(seed=0)
    # In the bathroom below the bathtub, facing it (south, +z): one step closes 0.25 m.
    env.set_pose(2.3, 4.0, SOUTH)
    d0 = env.distance
    _, r, term, trunc, info = env.step(MOVE_FORWARD)
    assert info["position"] == pytest.approx((2.3, 4.25))
    assert r == pytest.approx(d0 - env.distance - 0.01) and r == pytest.approx(0.25 - 0.01)
    assert not term and not trunc and not info["is_success"]
    # Facing the bathroom's east wall from 0.5 m (x = 3.5): the agent does not move; only the penalty.
    env.set_pose(3.0, 4.0, EAST)
    _, r, *_ , info = env.step(MOVE_FORWARD)
    assert info["position"] == (3.0, 4.0) and r == pytest.approx(-0.01)
    # Turning changes the heading by 30 degrees and costs the penalty.
    _, r, *_ , info = env.step(TURN_LEFT)
    assert info["heading"] == pytest.approx(math.radians(30)) and r == pytest.approx(-0.01)
    _, _, *_ , info = env.step(TURN_RIGHT)
    assert info["heading"] == pytest.approx(0.0)


def test_collision_penalty_only_on_blocked_moves():
    env = ApartmentEnv(goal="bathtub", obs="state", collision_penalty=0.1)
    env.reset(seed=0)
    env.set_pose(3.0, 4.0, EAST)  # 0.5 m from the bathroom's east wall: blocked
    _, r, *_, info = env.step(MOVE_FORWARD)
    assert info["position"] == (3.0, 4.0) and r == pytest.approx(-0.01 - 0.1)
    _, r, *_ = env.step(TURN_LEFT)  # a turn is never a collision
    assert r == pytest.approx(-0.01)
    env.set_pose(2.3, 4.0, SOUTH)  # a free move: the paper's reward, no penalty
    _, r, *_ = env.step(MOVE_FORWARD)
    assert r == pytest.approx(0.25 - 0.01)


def test_geodesic_reward_follows_the_free_path_not_the_straight_line():
    straight = ApartmentEnv(goal="bathtub", obs="state")
    free_path = ApartmentEnv(goal="bathtub", obs="state", reward_distance="geodesic")
    for env in (straight, free_path):
        env.reset(seed=0)
    # In the corridor right below the bathtub (2.3, 6.6) the bathroom wall is in the way; the door is at x in [-0.75, 0.75].
    below, door = (2.3, 0.0), (0.0, 0.0)
    distances = {}
    for env in (straight, free_path):
        for name, (x, z) in (("below", below), ("door", door)):
            env.set_pose(x, z, WEST)
            distances[env.reward_distance, name] = env.distance
    assert distances["euclidean", "below"] == pytest.approx(6.6)
    assert distances["euclidean", "below"] < distances["euclidean", "door"]
    # The free path from below the bathtub runs back through the door (2.3 m west); the geodesic distance is to the
    # reach circle, so never shorter than the straight line less the reach.
    assert distances["geodesic", "below"] > distances["geodesic", "door"] + 1.0
    for name in ("below", "door"):
        assert distances["geodesic", name] >= distances["euclidean", name] - free_path.reach
    # One step west, toward the door: the straight line calls it a loss, the free path a gain of about a step.
    for env in (straight, free_path):
        env.set_pose(*below, WEST)
    _, r_straight, *_ = straight.step(MOVE_FORWARD)
    _, r_free, *_ = free_path.step(MOVE_FORWARD)
    assert r_straight == pytest.approx(6.6 - math.hypot(0.25, 6.6) - 0.01)
    assert 0.25 - 0.05 < r_free + 0.01 <= 0.25 + 1e-6
    with pytest.raises(ValueError, match="reward_distance"):
        ApartmentEnv(goal="bathtub", obs="state", reward_distance="manhattan")


def test_reaching_the_goal_pays_and_terminates():
    env = ApartmentEnv(goal="bathtub", obs="state")
    env.reset(seed=0)
    goal = LAYOUT.object("bathtub")
    env.set_pose(goal.x, goal.z - env.reach - 0.1, SOUTH)  # 0.1 m short of reach, facing it
    d0 = env.distance
    _, r, term, trunc, info = env.step(MOVE_FORWARD)
    assert term and not trunc and info["is_success"]
    assert r == pytest.approx(d0 - env.distance - 0.01 + 10.0)


def test_truncation_after_500_steps():
    env = ApartmentEnv(goal="bathtub", obs="state")
    env.reset(seed=0)
    for t in range(500):
        _, _, term, trunc, info = env.step(TURN_LEFT)
        assert not term and trunc == (t == 499)
    assert not info["is_success"]


@pytest.mark.parametrize("pos,room", [((0.0, 0.0), "corridor"), ((-5.0, -5.0), "bedroom"), ((5.0, -5.0), "kitchen"),
                                      ((0.0, 4.0), "bathroom"), ((-4.5, -1.2), "corridor"), ((7.5, 0.5), "corridor")])
def test_room_at_known_positions(pos, room):
    env = ApartmentEnv(goal="nightstand", obs="state")
    env.reset(seed=0)
    env.set_pose(*pos, EAST)
    _, _, _, _, info = env.step(TURN_LEFT)
    assert info["room"] == room and info["goal_room"] == "bedroom"


def test_start_is_in_the_corridor_and_unknown_goal_is_refused():
    env = ApartmentEnv(goal="toilet", obs="state")
    for seed in range(50):
        _, info = env.reset(seed=seed)
        assert info["room"] == "corridor" and abs(info["position"][1]) <= 0.6
    with pytest.raises(KeyError, match="unknown goal object 'sofa'"):
        ApartmentEnv(goal="sofa")


def test_walls_match_miniworld(rgb_env):
    """The collision walls of the layout are the walls MiniWorld builds and draws."""
    mw = rgb_env.unwrapped.renderer.wall_segs[:, :, [0, 2]]

    def canon(segs):
        return sorted(tuple(np.round(np.sort(s, axis=0).ravel(), 3)) for s in segs if np.linalg.norm(s[1] - s[0]) > 1e-6)

    assert canon(LAYOUT.walls) == canon(mw)


@pytest.mark.parametrize("goal", LAYOUT.object_names)
def test_expert_reaches_every_object_from_50_corridor_starts(goal):
    env = ApartmentEnv(goal=goal, obs="state")
    expert = ApartmentExpert(env)
    for seed in range(50):
        env.reset(seed=1000 + seed)
        while True:
            _, _, term, trunc, info = env.step(expert())
            if term or trunc:
                break
        assert info["is_success"], f"expert failed to reach {goal} from seed {1000 + seed}"
        assert env.step_count <= 500


def test_textures_decoded_as_pyglet_decodes_them():
    # The renderer decodes textures with Pillow (fast); the texels GL keeps (RGB, rows bottom up) must be pyglet's.
    from sb3_disagree.envs.render import texture_image  # first: it arranges pyglet's headless mode

    import pyglet
    from miniworld.utils import get_file_path

    path = get_file_path("textures", "stucco_1", "png")
    ours = np.frombuffer(texture_image(path).get_data("RGBA", 512 * 4), np.uint8).reshape(512, 512, 4)
    image = pyglet.image.load(path)
    theirs = np.frombuffer(image.get_image_data().get_data("RGBA", 512 * 4), np.uint8).reshape(512, 512, 4)
    assert image.width == image.height == 512 and ours[..., 3].min() == 255
    assert np.array_equal(ours[..., :3], theirs[..., :3]) and not np.array_equal(ours[::-1, ..., :3], ours[..., :3])
