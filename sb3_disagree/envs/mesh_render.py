"""
Offscreen egocentric rendering of a scene mesh on the CPU: OpenGL 3.3 through moderngl on an EGL
context (Mesa's llvmpipe where there is no GPU). Triangles are grouped by texture, one draw call each;
untextured meshes draw with their colour as a 1x1 texture.
"""

import math
from typing import Optional

import numpy as np
import trimesh

_VERTEX = """
#version 330
uniform mat4 mvp;
in vec3 in_pos;
in vec3 in_normal;
in vec2 in_uv;
out vec3 v_normal;
out vec2 v_uv;
void main() {
    gl_Position = mvp * vec4(in_pos, 1.0);
    v_normal = in_normal;
    v_uv = in_uv;
}
"""
_FRAGMENT = """
#version 330
uniform sampler2D tex;
in vec3 v_normal;
in vec2 v_uv;
out vec4 colour;
void main() {
    // Fixed light from above and the side: walls facing different ways read differently.
    vec3 light = normalize(vec3(0.35, 0.8, 0.5));
    float shade = 0.55 + 0.45 * abs(dot(normalize(v_normal), light));
    colour = vec4(texture(tex, v_uv).rgb * shade, 1.0);
}
"""


def _mesh_texture(mesh: trimesh.Trimesh) -> tuple[np.ndarray, Optional[np.ndarray]]:
    """The mesh's texture image (H, W, 3 uint8) and per-vertex UVs, or a 1x1 image of its colour and no UVs."""
    visual = mesh.visual
    if visual.kind == "texture" and visual.uv is not None:
        material = visual.material
        image = getattr(material, "baseColorTexture", None) or getattr(material, "image", None)
        if image is not None:
            return np.asarray(image.convert("RGB")), np.asarray(visual.uv, dtype=np.float32)
        colour = getattr(material, "baseColorFactor", None)
        colour = colour if colour is not None else getattr(material, "main_color", [200, 200, 200, 255])
        return np.array(colour[:3], dtype=np.uint8).reshape(1, 1, 3), None
    colour = visual.main_color if hasattr(visual, "main_color") else [200, 200, 200, 255]
    return np.array(colour[:3], dtype=np.uint8).reshape(1, 1, 3), None


def perspective(fov_y: float, aspect: float, near: float, far: float) -> np.ndarray:
    f = 1.0 / math.tan(fov_y / 2)
    return np.array([[f / aspect, 0, 0, 0], [0, f, 0, 0], [0, 0, (far + near) / (near - far), 2 * far * near / (near - far)],
                     [0, 0, -1, 0]], dtype=np.float64)


def view_matrix(x: float, y: float, z: float, heading: float) -> np.ndarray:
    """Camera at (x, y, z) looking along (cos h, 0, -sin h), y up."""
    forward = np.array([math.cos(heading), 0.0, -math.sin(heading)])
    right = np.cross(forward, [0.0, 1.0, 0.0])
    up = np.cross(right, forward)
    rot = np.stack([right, up, -forward])
    m = np.eye(4)
    m[:3, :3] = rot
    m[:3, 3] = -rot @ np.array([x, y, z])
    return m


class MeshRenderer:
    """
    Egocentric RGB frames of a scene.

    :param meshes: The scene in world coordinates, y up
    :param width: Frame width in pixels
    :param height: Frame height in pixels
    :param hfov: Horizontal field of view in degrees (Habitat's default camera: 90)
    :param camera_height: Camera height above ``floor_y`` in metres
    :param floor_y: Height of the floor
    """

    def __init__(self, meshes: list[trimesh.Trimesh], width: int = 80, height: int = 60, hfov: float = 90.0,
                 camera_height: float = 1.25, floor_y: float = 0.0, background: tuple[float, float, float] = (0.6, 0.7, 0.8)
                 ) -> None:
        from sb3_disagree.envs.headless import arrange_headless

        arrange_headless()
        import moderngl

        self.width, self.height = width, height
        self.camera_y = floor_y + camera_height
        self.background = background
        self.ctx = moderngl.create_standalone_context(backend="egl")
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.program = self.ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        self.fbo = self.ctx.framebuffer(color_attachments=[self.ctx.renderbuffer((width, height), 3)],
                                        depth_attachment=self.ctx.depth_renderbuffer((width, height)))
        fov_y = 2 * math.atan(math.tan(math.radians(hfov) / 2) * height / width)
        self.projection = perspective(fov_y, width / height, 0.05, 100.0)
        self._batches = []
        groups: dict[bytes, list] = {}
        for mesh in meshes:
            image, uv = _mesh_texture(mesh)
            key = image.tobytes()[:4096] + bytes(str(image.shape), "ascii")
            groups.setdefault(key, [image, []])[1].append((mesh, uv))
        for image, items in groups.values():
            data = []
            for mesh, uv in items:
                faces = np.asarray(mesh.faces)
                pos = np.asarray(mesh.vertices, dtype=np.float32)[faces].reshape(-1, 3)
                normal = np.repeat(np.asarray(mesh.face_normals, dtype=np.float32), 3, axis=0)
                tex = uv[faces].reshape(-1, 2) if uv is not None else np.zeros((len(pos), 2), np.float32)
                data.append(np.hstack([pos, normal, tex]).astype(np.float32))
            vbo = self.ctx.buffer(np.concatenate(data).tobytes())
            vao = self.ctx.vertex_array(self.program, [(vbo, "3f 3f 2f", "in_pos", "in_normal", "in_uv")])
            # glTF images start at the top row; OpenGL's at the bottom.
            texture = self.ctx.texture((image.shape[1], image.shape[0]), 3, np.ascontiguousarray(image[::-1]).tobytes())
            texture.build_mipmaps()
            texture.repeat_x = texture.repeat_y = True
            self._batches.append((vao, texture))

    def render(self, x: float, z: float, heading: float) -> np.ndarray:
        """The frame seen from (x, z) facing ``heading`` (radians; 0 looks along +x, pi/2 along -z): (H, W, 3) uint8."""
        mvp = (self.projection @ view_matrix(x, self.camera_y, z, heading)).astype(np.float32)
        self.program["mvp"].write(mvp.T.tobytes())
        self.fbo.use()
        self.fbo.clear(*self.background, 1.0)
        for vao, texture in self._batches:
            texture.use(0)
            vao.render()
        data = self.fbo.read(components=3, alignment=1)
        return np.frombuffer(data, dtype=np.uint8).reshape(self.height, self.width, 3)[::-1].copy()

    def close(self) -> None:
        self.ctx.release()
