"""
MiniWorld as the apartment's renderer: the scene is built once, then drawn from any agent pose.

Importing this module imports MiniWorld, after arranging pyglet's headless mode where there is no display.
"""

import contextlib
import io

import numpy as np

from sb3_disagree.envs.headless import arrange_headless

arrange_headless()
import pyglet  # noqa: E402
from miniworld.entity import COLORS, Box  # noqa: E402
from miniworld.miniworld import MiniWorldEnv  # noqa: E402
from miniworld.opengl import Texture  # noqa: E402
from PIL import Image  # noqa: E402
from pyglet import gl  # noqa: E402

from sb3_disagree.envs.layout import EXTRA_COLORS, Layout  # noqa: E402

for _name, _rgb in EXTRA_COLORS.items():
    COLORS.setdefault(_name, np.array(_rgb))


def texture_image(tex_path: str) -> "pyglet.image.ImageData":
    """
    A texture file as pyglet RGBA image data, rows bottom up as GL reads them, decoded by Pillow: pyglet's own
    RGB to RGBA conversion runs in Python and cost ~4 s of each process's first scene (1.3 s for a 1024x1024
    texture). Its RGB is the same; its alpha differs (pyglet's fills alpha with red), which MiniWorld's GL_RGB
    textures drop.
    """
    rgba = Image.open(tex_path).convert("RGBA").transpose(Image.Transpose.FLIP_TOP_BOTTOM)
    return pyglet.image.ImageData(rgba.width, rgba.height, "RGBA", rgba.tobytes(), pitch=rgba.width * 4)


def _load_texture(cls: type, tex_path: str) -> "pyglet.image.Texture":
    """MiniWorld's ``Texture.load``, the same GL calls on :func:`texture_image`'s data."""
    img = texture_image(tex_path)
    tex = img.get_texture()
    gl.glEnable(tex.target)
    gl.glBindTexture(tex.target, tex.id)
    gl.glTexImage2D(gl.GL_TEXTURE_2D, 0, gl.GL_RGB, img.width, img.height, 0, gl.GL_RGBA, gl.GL_UNSIGNED_BYTE,
                    img.get_data("RGBA", img.width * 4))
    gl.glHint(gl.GL_GENERATE_MIPMAP_HINT, gl.GL_NICEST)
    gl.glGenerateMipmap(gl.GL_TEXTURE_2D)
    gl.glTexParameteri(gl.GL_TEXTURE_2D, gl.GL_TEXTURE_MAG_FILTER, gl.GL_LINEAR)
    gl.glTexParameteri(gl.GL_TEXTURE_2D, gl.GL_TEXTURE_MIN_FILTER, gl.GL_LINEAR_MIPMAP_LINEAR)
    gl.glBindTexture(gl.GL_TEXTURE_2D, 0)
    return tex


Texture.load = classmethod(_load_texture)


class StaticBox(Box):
    """A box that never moves: MiniWorld compiles it into the scene's display list instead of drawing
    it call by call every frame."""

    @property
    def is_static(self) -> bool:
        return True


class ApartmentRenderer(MiniWorldEnv):
    """
    The apartment's rooms, doorways and boxes as a MiniWorld scene. Dynamics live in the layout; this
    class only draws, so it never regenerates the world after construction.

    :param layout: The apartment to draw
    :param obs_width: Width of the egocentric frame
    :param obs_height: Height of the egocentric frame
    """

    def __init__(self, layout: Layout, obs_width: int = 80, obs_height: int = 60) -> None:
        self.layout = layout
        # MiniWorld prints "Falling back to num_samples=4" when llvmpipe caps anti-aliasing: harmless.
        with contextlib.redirect_stdout(io.StringIO()):
            super().__init__(max_episode_steps=10**9, obs_width=obs_width, obs_height=obs_height)

    def _gen_world(self) -> None:
        rooms = {}
        for room in self.layout.all_rooms:
            rooms[room.name] = self.add_rect_room(
                min_x=room.min_x, max_x=room.max_x, min_z=room.min_z, max_z=room.max_z,
                wall_tex=room.wall_tex, floor_tex=room.floor_tex,
            )
        corridor = rooms[self.layout.corridor.name]
        for door in self.layout.doorways:
            self.connect_rooms(corridor, rooms[door.room], min_x=door.min_x, max_x=door.max_x)
        for obj in self.layout.objects:
            self.place_entity(StaticBox(color=obj.color, size=list(obj.size)), pos=np.array([obj.x, 0.0, obj.z]), dir=0.0)
        c = self.layout.corridor
        self.place_agent(pos=np.array([(c.min_x + c.max_x) / 2, 0.0, (c.min_z + c.max_z) / 2]), dir=0.0)

    def egocentric(self, x: float, z: float, heading: float) -> np.ndarray:
        """
        :return: The agent's view from (x, z) facing ``heading``, uint8 (H, W, 3)
        """
        self.agent.pos = np.array([x, 0.0, z])
        self.agent.dir = heading
        return self.render_obs()

    def top_view(self) -> np.ndarray:
        """
        :return: The map seen from above without the agent (800x600), image-up = -z
        """
        return self.render_top_view(frame_buffer=self.vis_fb, render_agent=False)
