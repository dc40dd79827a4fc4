"""The policy alone, watched: its own episodes as a video (the agent's view beside the map) or as a picture."""

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

import numpy as np

from sb3_disagree.defaults import FINAL_EVAL_SEED_OFFSET
from sb3_disagree.envs.vec import make_vec

VIDEO_FORMATS = (".gif", ".mp4")
PATH_COLOR = (214, 39, 40)
VIEW_HEIGHT = 240  # the agent's view (4x its 60x80 pixels) and the map, side by side


@dataclass
class PlayedEpisode:
    """One episode of the policy alone: where it went, whether it reached the goal, and its frames if recorded."""

    positions: list[tuple[float, float]]
    success: bool
    frames: list[np.ndarray] = field(default_factory=list)

    @property
    def length(self) -> int:
        return len(self.positions) - 1


def play(model: Any, config: dict[str, Any], episodes: int = 1, deterministic: bool = True, seed: Optional[int] = None,
         frames: bool = False) -> list[PlayedEpisode]:
    """
    Episodes of the policy alone (no priors) in its run's task, one env, acting as SB3's ``evaluate_policy`` does
    (``predict`` with the policy's state carried between steps).

    :param model: The trained model
    :param config: The run's configuration (``config.yaml``): env, goal, env keywords, seed
    :param episodes: How many episodes
    :param deterministic: Greedy actions (the default, as ``evaluate_policy``) or sampled ones
    :param seed: Env seed (default: the run's seed + ``FINAL_EVAL_SEED_OFFSET``, never trained on)
    :param frames: Also keep each step's frame: the agent's view beside the map with its path so far, uint8
    :return: The episodes, each with one frame per observation (its first, then one per step)
    """
    seed = config.get("seed", 0) + FINAL_EVAL_SEED_OFFSET if seed is None else seed
    env = make_vec(config["env_id"], config["goal"], config.get("env_kwargs") or {}, n_envs=1, seed=seed)
    try:
        nav = env.envs[0].unwrapped
        picture = _Frames(nav, config["goal"], deterministic) if frames else None
        played: list[PlayedEpisode] = []
        obs, state, start = env.reset(), None, np.ones((1,), dtype=bool)
        episode = PlayedEpisode([tuple(nav.path[-1])], False)
        while len(played) < episodes:
            if picture is not None:
                episode.frames.append(picture(episode, len(played), nav.first_person()))
            action, state = model.predict(obs, state=state, episode_start=start, deterministic=deterministic)
            obs, _, dones, infos = env.step(action)
            start = dones
            info = infos[0]  # the step's own: at an episode's end the env has been reset since
            episode.positions.append(tuple(info["position"]))
            if dones[0]:
                episode.success = bool(info.get("is_success", False))
                if picture is not None:  # where it ended (the env has been reset: its own pose is the next start)
                    view = nav.first_person((*info["position"], info["heading"]))
                    episode.frames.append(picture(episode, len(played), view, ended=True))
                played.append(episode)
                episode = PlayedEpisode([tuple(nav.path[-1])], False)
        return played
    finally:
        env.close()


class _Frames:
    """Draws a frame: the agent's view (scaled) beside the map with the path so far and a caption."""

    def __init__(self, env, goal: str, deterministic: bool) -> None:
        from sb3_disagree.envs.topdown import map_image

        self.goal, self.how = goal, "greedy" if deterministic else "sampled"
        image, (self.x0, self.x1, self.z0, self.z1) = map_image(env)
        h, w = image.shape[:2]
        self.map_size = (round(w * VIEW_HEIGHT / h), VIEW_HEIGHT)
        from PIL import Image

        self.map = Image.fromarray(image).resize(self.map_size, Image.BILINEAR)

    def _pixel(self, x: float, z: float) -> tuple[float, float]:
        w, h = self.map_size
        return (x - self.x0) / (self.x1 - self.x0) * w, (z - self.z0) / (self.z1 - self.z0) * h

    def __call__(self, episode: PlayedEpisode, index: int, view: np.ndarray, ended: bool = False) -> np.ndarray:
        from PIL import Image, ImageDraw

        vh, vw = view.shape[:2]
        view = Image.fromarray(view).resize((round(vw * VIEW_HEIGHT / vh), VIEW_HEIGHT), Image.NEAREST)
        caption = 16
        frame = Image.new("RGB", (view.width + self.map_size[0], VIEW_HEIGHT + caption), "white")
        frame.paste(view, (0, caption))
        chart = self.map.copy()
        draw = ImageDraw.Draw(chart)
        points = [self._pixel(x, z) for x, z in episode.positions]
        if len(points) > 1:
            draw.line(points, fill=PATH_COLOR, width=2)
        (u, v), r = points[-1], 3
        draw.ellipse((u - r, v - r, u + r, v + r), fill=(0, 0, 0))
        frame.paste(chart, (view.width, caption))
        text = f"{self.goal}, {self.how}, episode {index + 1}, step {episode.length}"
        if ended:
            text += ": reached the goal" if episode.success else ": did not reach the goal"
        ImageDraw.Draw(frame).text((4, 2), text, fill=(0, 0, 0))
        return np.asarray(frame)


def write_video(episodes: list[PlayedEpisode], path: Path, fps: int = 10) -> int:
    """
    Write the episodes' frames as an animated GIF (each episode's last frame held a second) or an MP4, by
    ``path``'s suffix.

    :return: The number of frames written
    """
    path = Path(path)
    frames = [f for e in episodes for f in e.frames]
    if path.suffix == ".gif":
        from PIL import Image

        images = [Image.fromarray(f) for f in frames]
        # One palette for all frames: the map and the walls keep their colours, and the file stays small.
        palette = images[0].quantize(colors=128)
        images = [im.quantize(palette=palette, dither=Image.Dither.NONE) for im in images]
        durations = [1000 if i == len(e.frames) - 1 else round(1000 / fps) for e in episodes for i in range(len(e.frames))]
        images[0].save(path, save_all=True, append_images=images[1:], duration=durations, loop=0, optimize=True)
    else:
        try:
            import imageio.v2 as imageio
            import imageio_ffmpeg  # noqa: F401
        except ImportError:
            raise ValueError("--video .mp4 needs imageio-ffmpeg: pip install 'sb3-disagree[video]' (or write a .gif)") from None

        with imageio.get_writer(path, fps=fps, macro_block_size=1) as writer:
            for f in frames:
                writer.append_data(f)
    return len(frames)


def draw_played(episode: PlayedEpisode, env_id: str, goal: str, title: str, out: Path) -> None:
    """
    One played episode on the map of its env (as the paper's trajectory figures): its path, start, goal, a legend
    and a title that says how it acted and whether it reached the goal.
    """
    from sb3_disagree.envs.topdown import draw_trajectory
    from sb3_disagree.envs.vec import make_task

    layout = getattr(make_task(env_id, goal).unwrapped, "layout", None)
    if layout is None:
        raise ValueError(f"{env_id} has no map to draw episodes on: use --video")
    draw_trajectory(layout, episode.positions, goal=goal, out=out, title=title, legend=True)
