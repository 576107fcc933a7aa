"""A pinhole camera rendered with OpenGL (moderngl) on a headless EGL context: RGB and metric depth.

Plain class, no bus and no I/O. :class:`Renderer` holds an EGL context, an offscreen framebuffer
and a scene of triangle meshes (each in its own frame, with one colour); :meth:`Renderer.render`
draws them from a camera pose and returns

- ``rgb``: (H, W, 3) uint8, Lambert shading
  ``colour * min(1, ambient + max(0, n . s) + lamp max(0, n . l) / d^2)`` for a Sun direction ``s``
  (None: no Sun, in the Earth's shadow) and a lamp at the camera's origin (``l`` the unit vector
  from the surface towards it, ``d`` its distance in m: inverse-square falloff), black where
  nothing is hit (the sky);
  ``colour`` is a mesh's per-vertex colour, or its texture's (trilinear, mipmapped) where it has one;
- ``depth``: (H, W) float32, metres along the optical axis (the camera frame's z), 0 where
  nothing is hit.

Conventions (OpenCV's): the camera frame has z forward, x right, y down; pixel (u, v) has its
centre at integer coordinates, u along the row, v down the column; K = [[fx, 0, cx], [0, fy, cy],
[0, 0, 1]] projects a point p in the camera frame to (fx x/z + cx, fy y/z + cy). OpenGL's window
coordinates put a pixel's centre at i + 0.5, so the projection below places the principal point
at cx + 0.5, cy + 0.5 (else every pixel is half a pixel off OpenCV's), and it maps image row v to
framebuffer row v, so the rows read back in OpenCV's order without a flip.

Depth is the camera-frame z interpolated over each triangle (perspective-correct) and written by
the fragment shader into a float32 attachment, not recovered from the z-buffer (whose
non-linear, fixed-point values lose millimetres at a few metres). The z-buffer (24-bit)
only decides what is in front.

No shadows between objects (a body shading another is lit as if it did not), no reflections, no
Earth in the scene: the sky is black. Units: m, rad, pixels.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import moderngl

#: The Debian packages that provide EGL and Mesa's software OpenGL (llvmpipe).
EGL_PACKAGES = "libegl1 libegl-mesa0 libgl1-mesa-dri"

_VERTEX = """
#version 330
uniform mat4 T_camera_mesh;   // mesh frame -> camera frame (OpenCV axes)
uniform mat4 projection;      // camera frame -> clip
in vec3 position;
in vec3 normal;
in vec3 colour;
in vec2 uv;
out vec3 p_camera;
out vec3 n_camera;
out vec3 v_colour;
out vec2 v_uv;
void main() {
    vec4 p = T_camera_mesh * vec4(position, 1.0);
    p_camera = p.xyz;
    n_camera = mat3(T_camera_mesh) * normal;
    v_colour = colour;
    v_uv = uv;
    gl_Position = projection * p;
}
"""

_FRAGMENT = """
#version 330
uniform vec3 sun_camera;      // unit vector towards the Sun, camera axes (0: none)
uniform float ambient;
uniform float lamp;           // a lamp at the camera's origin: light on a face square to it at 1 m
uniform bool textured;
uniform sampler2D image;
in vec3 p_camera;
in vec3 n_camera;
in vec3 v_colour;             // 0..1
in vec2 v_uv;
layout(location = 0) out vec4 rgb;
layout(location = 1) out float depth;
void main() {
    vec3 n = normalize(n_camera);
    // two-sided: the side the camera sees faces it
    if (dot(n, p_camera) > 0.0) n = -n;
    float d2 = dot(p_camera, p_camera);
    float light = ambient + max(dot(n, sun_camera), 0.0) + lamp * max(dot(n, -p_camera), 0.0) / (d2 * sqrt(d2));
    vec3 colour = textured ? texture(image, v_uv).rgb : v_colour;
    rgb = vec4(colour * min(light, 1.0), 1.0);
    depth = p_camera.z;
}
"""


class RenderError(Exception):
    """No OpenGL context can be made (EGL missing), or a mesh is unusable."""


def projection_matrix(K: np.ndarray, width: int, height: int, near: float, far: float) -> np.ndarray:
    """The OpenGL projection (4x4, row-major) of a camera frame with OpenCV axes onto a framebuffer of
    ``width`` x ``height`` whose row v is image row v: clip = P [x, y, z, 1], w_clip = z.

    x_ndc = 2 (fx x/z + cx + 0.5) / W - 1, y_ndc = 2 (fy y/z + cy + 0.5) / H - 1, and z_ndc from -1
    at ``near`` to 1 at ``far`` (m)."""
    fx, fy, cx, cy, skew = K[0, 0], K[1, 1], K[0, 2], K[1, 2], K[0, 1]
    return np.array(
        [
            [2.0 * fx / width, 2.0 * skew / width, 2.0 * (cx + 0.5) / width - 1.0, 0.0],
            [0.0, 2.0 * fy / height, 2.0 * (cy + 0.5) / height - 1.0, 0.0],
            [0.0, 0.0, (far + near) / (far - near), -2.0 * far * near / (far - near)],
            [0.0, 0.0, 1.0, 0.0],
        ]
    )


def egl_problem() -> str | None:
    """Why no headless OpenGL context can be made here, or None when one can."""
    try:
        context = _context()
    except RenderError as e:
        return str(e)
    context.release()
    return None


def _context():
    try:
        import moderngl
    except ImportError as e:
        raise RenderError(f"moderngl is not installed ({e}): pip install moderngl") from None
    try:
        # moderngl's stub types each **settings value as a dict; backend is a string
        return moderngl.create_standalone_context(backend="egl", require=330)  # type: ignore[arg-type]
    except Exception as e:  # glcontext raises plain Exceptions: a missing libEGL, no driver
        raise RenderError(
            f"no EGL OpenGL 3.3 context ({type(e).__name__}: {e}); on Debian/Ubuntu: apt-get install {EGL_PACKAGES}"
        ) from None


class Renderer:
    """An offscreen pinhole camera of intrinsics ``K`` (3x3, pixels), ``width`` x ``height`` pixels,
    clipping at ``near`` and ``far`` (m); ``ambient`` is the light a surface gets without the Sun
    (0..1 of its colour); ``lamp`` the light of a lamp at the camera's origin on a face square to
    it 1 m away (0..1 of its colour, m^2: it falls off as 1/d^2)."""

    def __init__(
        self, K: np.ndarray, width: int, height: int, near: float, far: float, ambient: float = 0.0, lamp: float = 0.0
    ):
        self.K = np.array(K, dtype=np.float64).reshape(3, 3)
        self.width, self.height, self.ambient, self.lamp = int(width), int(height), float(ambient), float(lamp)
        self.ctx = _context()
        with self.ctx:  # every GL call in this context: another camera's may be current in this process
            self._build(near, far)

    def _build(self, near: float, far: float) -> None:
        ctx = self.ctx
        self.program = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        self.program["projection"].write(
            projection_matrix(self.K, self.width, self.height, near, far).T.astype("f4").tobytes()
        )
        size = (self.width, self.height)
        self.colour_buffer = ctx.renderbuffer(size, components=4, dtype="f1")
        self.depth_buffer = ctx.renderbuffer(size, components=1, dtype="f4")
        self.z_buffer = ctx.depth_renderbuffer(size)
        self.fbo = ctx.framebuffer(
            color_attachments=[self.colour_buffer, self.depth_buffer], depth_attachment=self.z_buffer
        )
        self.program["image"].value = 0
        self.meshes: list[tuple[moderngl.VertexArray, moderngl.Buffer, moderngl.Texture | None]] = []

    def add_mesh(
        self,
        vertices: np.ndarray,
        triangles: np.ndarray,
        normals: np.ndarray,
        colour,
        uv: np.ndarray | None = None,
        texture: np.ndarray | None = None,
    ) -> int:
        """Add a mesh: vertices (n, 3) in its own frame (m), triangles (m, 3) indices, vertex
        normals (n, 3); ``colour`` (r, g, b) in 0..1, one for the mesh or one per vertex (n, 3);
        or a ``texture`` (h, w, 3 or 4) uint8, its row 0 the image's top, with texture
        coordinates ``uv`` (n, 2), (0, 0) at the image's bottom left (OBJ's and trimesh's
        convention). Returns its index (the order of ``render``'s poses)."""
        vertices = np.asarray(vertices, dtype=np.float32).reshape(-1, 3)
        n = len(vertices)
        normals = np.asarray(normals, dtype=np.float32).reshape(-1, 3)
        triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        if len(normals) != n or not len(triangles) or triangles.max() >= n or triangles.min() < 0:
            raise RenderError(
                f"mesh of {n} vertices, {len(normals)} normals and {len(triangles)} "
                "triangles: expected one normal per vertex and triangle indices within the vertices"
            )
        colours = np.broadcast_to(np.asarray(colour, dtype=np.float32).reshape(-1, 3), (n, 3))
        if (uv is None) != (texture is None):
            raise RenderError("a textured mesh needs both uv and texture")
        uv = np.zeros((n, 2), dtype=np.float32) if uv is None else np.asarray(uv, dtype=np.float32).reshape(n, 2)
        # unindexed: three vertices per triangle (no index buffer; meshes are small)
        corners = triangles.ravel()
        data = np.hstack([vertices[corners], normals[corners], colours[corners], uv[corners]]).astype("f4")
        with self.ctx:
            buffer = self.ctx.buffer(data.tobytes())
            vao = self.ctx.vertex_array(self.program, [(buffer, "3f 3f 3f 2f", "position", "normal", "colour", "uv")])
            self.meshes.append((vao, buffer, None if texture is None else self._texture(texture)))
        return len(self.meshes) - 1

    def _texture(self, image: np.ndarray):
        import moderngl

        image = np.asarray(image, dtype=np.uint8)
        if image.ndim != 3 or image.shape[2] not in (3, 4):
            raise RenderError(f"a texture is (h, w, 3 or 4) uint8, got shape {image.shape}")
        rows = np.ascontiguousarray(image[::-1, :, :3])  # OpenGL's row 0 is the bottom
        texture = self.ctx.texture((rows.shape[1], rows.shape[0]), 3, rows.tobytes(), alignment=1)
        texture.build_mipmaps()
        texture.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        texture.repeat_x = texture.repeat_y = True
        return texture

    def render(self, T_camera_meshes, sun_camera: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Draw every mesh at its pose ``T_camera_meshes[i]`` (4x4, mesh frame -> camera frame, m;
        None: not drawn) lit by the Sun from ``sun_camera`` (unit vector towards the Sun, camera
        axes; None: no Sun). Returns ``rgb`` (H, W, 3) uint8 and ``depth`` (H, W) float32 (m along
        the optical axis, 0 where nothing is hit)."""
        with self.ctx:
            return self._render(T_camera_meshes, sun_camera)

    def _render(self, T_camera_meshes, sun_camera):
        import moderngl

        ctx = self.ctx
        self.fbo.use()
        self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE)
        sun = np.zeros(3, dtype=np.float32) if sun_camera is None else np.asarray(sun_camera, dtype=np.float32)
        self.program["sun_camera"].write(sun.tobytes())
        self.program["ambient"].value = self.ambient
        self.program["lamp"].value = self.lamp
        for (vao, _, texture), T in zip(self.meshes, T_camera_meshes):
            if T is None:
                continue
            self.program["T_camera_mesh"].write(np.asarray(T, dtype=np.float64).T.astype("f4").tobytes())
            self.program["textured"].value = texture is not None
            if texture is not None:
                texture.use(location=0)
            vao.render(moderngl.TRIANGLES)
        rgba = np.frombuffer(self.fbo.read(components=4, attachment=0, dtype="f1"), dtype=np.uint8)
        depth = np.frombuffer(self.fbo.read(components=1, attachment=1, dtype="f4"), dtype=np.float32)
        rgb = rgba.reshape(self.height, self.width, 4)[:, :, :3].copy()
        return rgb, depth.reshape(self.height, self.width).copy()

    def release(self) -> None:
        """Free the GL objects and the context."""
        with self.ctx:
            for vao, buffer, texture in self.meshes:
                vao.release()
                buffer.release()
                if texture is not None:
                    texture.release()
            self.meshes = []
            for thing in (self.fbo, self.colour_buffer, self.depth_buffer, self.z_buffer, self.program):
                thing.release()
        self.ctx.release()
