"""Top-down pictures of the apartment with trajectories, coloured by per-step tags (paper Figs. 4-5)."""

from collections.abc import Sequence
from pathlib import Path
from typing import Optional, Union

import numpy as np

from sb3_disagree.envs.layout import EXTRA_COLORS, Layout

TAG_COLORS = {"prior": "#1a9e2f", "explore": "#1f4fd6"}
DEFAULT_PATH_COLOR = "#d62728"
_MINIWORLD_COLORS = {"red": (1, 0, 0), "green": (0, 1, 0), "blue": (0, 0, 1), "purple": (0.44, 0.15, 0.76),
                     "yellow": (1, 1, 0), "grey": (0.39, 0.39, 0.39)}


def map_extent(layout: Layout, width: int = 800, height: int = 600) -> tuple[float, float, float, float]:
    """(min_x, max_x, min_z, max_z) that MiniWorld's top view shows: the rooms plus 1 m, padded to the aspect."""
    min_x = min(r.min_x for r in layout.all_rooms) - 1
    max_x = max(r.max_x for r in layout.all_rooms) + 1
    min_z = min(r.min_z for r in layout.all_rooms) - 1
    max_z = max(r.max_z for r in layout.all_rooms) + 1
    aspect, fb_aspect = (max_x - min_x) / (max_z - min_z), width / height
    if aspect > fb_aspect:
        pad = ((max_x - min_x) / fb_aspect - (max_z - min_z)) / 2
        min_z, max_z = min_z - pad, max_z + pad
    elif aspect < fb_aspect:
        pad = ((max_z - min_z) * fb_aspect - (max_x - min_x)) / 2
        min_x, max_x = min_x - pad, max_x + pad
    return min_x, max_x, min_z, max_z


def _figure(layout: Layout, background: Optional[np.ndarray], goal: Optional[str]):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    min_x, max_x, min_z, max_z = map_extent(layout)
    fig, ax = plt.subplots(figsize=(8, 6), dpi=100)
    fig.subplots_adjust(0, 0, 1, 1)
    ax.set_xlim(min_x, max_x)
    ax.set_ylim(max_z, min_z)  # image-up is -z, as in MiniWorld's top view
    ax.set_axis_off()
    if background is not None:
        ax.imshow(background, extent=(min_x, max_x, max_z, min_z))
    else:
        ax.set_facecolor("#9fd8f5")
        for room in layout.all_rooms:
            ax.add_patch(Rectangle((room.min_x, room.min_z), room.max_x - room.min_x, room.max_z - room.min_z,
                                   facecolor="#e8e4da", edgecolor="none"))
        for d in layout.doorways:
            room = layout.room(d.room)
            z0, z1 = sorted((room.max_z if room.max_z <= layout.corridor.min_z else room.min_z,
                             layout.corridor.min_z if room.max_z <= layout.corridor.min_z else layout.corridor.max_z))
            ax.add_patch(Rectangle((d.min_x, z0), d.max_x - d.min_x, z1 - z0, facecolor="#e8e4da", edgecolor="none"))
        for (x0, z0), (x1, z1) in layout.walls:
            ax.plot([x0, x1], [z0, z1], color="#333333", lw=2)
        for room in layout.all_rooms:
            cx, cz = room.center
            ax.text(cx, cz, room.name, ha="center", va="center", color="#777777", fontsize=11)
        for o in layout.objects:
            color = _MINIWORLD_COLORS.get(o.color) or EXTRA_COLORS[o.color]
            ax.add_patch(Rectangle((o.x - o.size[0] / 2, o.z - o.size[2] / 2), o.size[0], o.size[2],
                                   facecolor=color, edgecolor="black", lw=0.8))
    for o in layout.objects:
        ax.text(o.x, o.z + o.size[2] / 2 + 0.35, o.name, ha="center", va="center", fontsize=8,
                color="black", bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.7))
    if goal is not None:
        g = layout.object(goal)
        ax.plot(g.x, g.z, marker="*", color="#ff2d2d", markersize=22, markeredgecolor="black")
    return fig, ax


def draw_trajectory(
    layout: Layout,
    path: Sequence[tuple[float, float]],
    tags: Optional[Sequence[str]] = None,
    goal: Optional[str] = None,
    background: Optional[np.ndarray] = None,
    out: Optional[Union[str, Path]] = None,
    title: Optional[str] = None,
    legend: bool = False,
) -> np.ndarray:
    """
    Draw a path on the map: segment t (from position t to t+1) in the colour of tag t (green where
    the priors were followed, blue where the agent explored), red without tags.

    :param layout: The apartment
    :param path: Agent positions (x, z), one more than the steps
    :param tags: One tag per step, or None
    :param goal: Goal object to mark with a star
    :param background: MiniWorld's top view to draw on; a schematic map if None
    :param out: PNG file to write, if given
    :param title: Written at the top of the picture
    :param legend: Say what the colours and marks are
    :return: The picture, uint8 (600, 800, 3)
    """
    fig, ax = _figure(layout, background, goal)
    pts = np.asarray(path, dtype=float)
    if len(pts) > 1:
        from matplotlib.collections import LineCollection

        segs = np.stack([pts[:-1], pts[1:]], axis=1)
        colors = [TAG_COLORS.get(t, "#888888") for t in tags] if tags is not None else DEFAULT_PATH_COLOR
        ax.add_collection(LineCollection(segs, colors=colors, linewidths=2.5))
    if len(pts):
        ax.plot(pts[0, 0], pts[0, 1], "o", color="black", markersize=7)
    if title is not None:
        ax.text(0.5, 0.98, title, transform=ax.transAxes, ha="center", va="top", fontsize=12,
                bbox=dict(boxstyle="round,pad=0.3", fc="white", ec="none", alpha=0.85))
    if legend:
        from matplotlib.lines import Line2D

        lines = ([Line2D([], [], color=c, lw=2.5, label=f"{t} step") for t, c in TAG_COLORS.items()] if tags is not None
                 else [Line2D([], [], color=DEFAULT_PATH_COLOR, lw=2.5, label="path")])
        marks = [Line2D([], [], marker="o", color="black", ls="", label="start")]
        if goal is not None:
            marks.append(Line2D([], [], marker="*", color="#ff2d2d", markeredgecolor="black", markersize=14, ls="",
                                label=f"goal: {goal}"))
        ax.legend(handles=lines + marks, loc="lower right", framealpha=0.9)
    fig.canvas.draw()
    image = np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    if out is not None:
        fig.savefig(out)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return image


def map_image(env) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """
    The map of a navigation env with its goal marked, and where it lies: pixel (u, v) of the picture (W, H) shows
    x = min_x + u / W * (max_x - min_x) and z = min_z + v / H * (max_z - min_z).

    :param env: An apartment (drawn schematically) or a scan (its navigable grid), unwrapped or not
    :return: The picture, uint8 (H, W, 3), and (min_x, max_x, min_z, max_z)
    """
    env = env.unwrapped
    if hasattr(env, "layout"):
        import matplotlib.pyplot as plt

        fig, _ = _figure(env.layout, None, env.goal.name)
        fig.canvas.draw()
        image = np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
        plt.close(fig)
        return image, map_extent(env.layout)
    grid = env.grid
    image = np.full(grid.free.shape + (3,), 255, dtype=np.uint8)
    image[grid.floor] = 204
    image[grid.free] = 255
    image[grid.obstacle] = 64
    gi, gj = (min(max(k, 0), n - 1) for k, n in zip(grid.index(*env.goal_xz), grid.free.shape))
    image[max(gi - 2, 0):gi + 3, max(gj - 2, 0):gj + 3] = (255, 45, 45)
    extent = (grid.x0 - grid.cell / 2, grid.x0 + grid.cell * (grid.free.shape[0] - 0.5),
              grid.z0 - grid.cell / 2, grid.z0 + grid.cell * (grid.free.shape[1] - 0.5))
    return image.transpose(1, 0, 2).copy(), extent
