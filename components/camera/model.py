"""The camera model: bodies, a mount, a renderer and the Sun, with no bus and no I/O.

:class:`CameraModel` places every body's visuals (:mod:`components.camera.scene`) at the link
poses its base pose and joint positions give, puts the camera on its mount link
(``T_W_camera = T_W_link T_link_camera``) and renders (:mod:`components.camera.render`), lit by
the Sun unless the camera is in the Earth's shadow (:mod:`components.camera.sun`); a lens with
distortion resamples a larger pinhole render (:mod:`components.camera.lens`). W is the
dynamics' world frame, ECI axes, so the Sun direction in ECI is the one in W.

:func:`add_pixel_noise`: white pixel noise (counts of 0..255, 1-sigma, rounded to the nearest count
and clipped); :func:`add_depth_noise`: white depth noise (m, 1-sigma, only where something is hit);
both from standard normals the caller draws.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from components.camera.lens import Lens
from components.camera.render import Renderer
from components.camera.scene import BodyPoses, pose_matrix, visual_meshes
from components.viewer.robot import Geometry

MAX_RENDER = 16384  # pixels: the largest framebuffer side the camera asks OpenGL for


@dataclass(frozen=True)
class Intrinsics:
    """A camera: ``width`` x ``height`` pixels, focal lengths and principal point (pixels), clip
    distances ``near`` and ``far`` (m), plumb_bob ``distortion`` [k1, k2, p1, p2, k3] (None: a
    pinhole)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    near: float
    far: float
    distortion: tuple[float, ...] | None = None

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


class CameraModel:
    """Renders the ``bodies`` (name -> Geometry) from a camera on link ``link`` of body ``body``,
    at ``T_link_camera`` (4x4, OpenCV axes: z forward, x right, y down)."""

    def __init__(
        self,
        bodies: Mapping[str, Geometry],
        body: str,
        link: str,
        T_link_camera: np.ndarray,
        intrinsics: Intrinsics,
        ambient: float,
        lamp: float = 0.0,
    ):
        self.intrinsics = intrinsics
        self.T_link_camera = np.asarray(T_link_camera, dtype=np.float64)
        self.lens = None
        K, width, height = intrinsics.K, intrinsics.width, intrinsics.height
        if intrinsics.distortion is not None and any(intrinsics.distortion):
            # twice the focal length (a quarter pixel at most off) while the render stays within 16384
            supersample = 2 if 2.5 * max(width, height) <= MAX_RENDER else 1
            self.lens = Lens(K, width, height, intrinsics.distortion, supersample)
            K, width, height = self.lens.K_render, self.lens.render_width, self.lens.render_height
            if max(width, height) > MAX_RENDER:
                raise ValueError(
                    f"the distortion needs a pinhole render of {width}x{height} pixels, above OpenGL's {MAX_RENDER}"
                )
        self.renderer = Renderer(K, width, height, intrinsics.near, intrinsics.far, ambient, lamp)
        self.poses = {name: BodyPoses(geometry) for name, geometry in bodies.items()}
        self.mount = (body, bodies[body].links.index(link))
        self.drawn: list[tuple[str, int]] = []  # per renderer mesh: (body, link index)
        self.notes: list[str] = []
        for name, geometry in bodies.items():
            meshes, notes = visual_meshes(geometry)
            self.notes += notes
            for mesh in meshes:
                self.renderer.add_mesh(
                    mesh.vertices,
                    np.arange(len(mesh.vertices)).reshape(-1, 3),
                    mesh.normals,
                    mesh.colours,
                    mesh.uv,
                    mesh.texture,
                )
                self.drawn.append((name, mesh.link))

    def camera_pose(self, links: Mapping[str, np.ndarray]) -> np.ndarray:
        """T_W_camera from the bodies' link transforms (name -> (L, 4, 4))."""
        body, link = self.mount
        return links[body][link] @ self.T_link_camera

    def render(self, states: Mapping[str, tuple[np.ndarray, np.ndarray, np.ndarray]], sun_W: np.ndarray | None):
        """``states``: body -> (base position (m, W), q_W_base [x, y, z, w], joint positions);
        ``sun_W``: unit vector towards the Sun in W, or None (eclipse). Returns rgb (H, W, 3)
        uint8, depth (H, W) float32 (m, 0: nothing hit) and T_W_camera (4x4)."""
        links = {name: self.poses[name].link_transforms(*states[name]) for name in self.poses}
        T_W_camera = self.camera_pose(links)
        T_camera_W = np.linalg.inv(T_W_camera)
        T_camera_meshes = [T_camera_W @ links[name][link] for name, link in self.drawn]
        sun_camera = None if sun_W is None else T_camera_W[:3, :3] @ sun_W
        rgb, depth = self.renderer.render(T_camera_meshes, sun_camera)
        if self.lens is not None:
            rgb, depth = self.lens.apply(rgb, depth)
        return rgb, depth, T_W_camera

    def release(self) -> None:
        self.renderer.release()


def mount_transform(position, orientation) -> np.ndarray:
    """T_link_camera of the camera's ``position`` (m) and ``orientation`` (q_link_camera [x, y, z, w])."""
    return pose_matrix(position, orientation)


def add_pixel_noise(rgb: np.ndarray, z: np.ndarray, sigma: float) -> np.ndarray:
    """rgb (uint8) + sigma z (z: standard normals of rgb's shape), rounded to the nearest count and
    clipped to 0..255."""
    return np.clip(np.rint(rgb.astype(np.float32) + np.float32(sigma) * z), 0, 255).astype(np.uint8)


def add_depth_noise(depth: np.ndarray, z: np.ndarray, sigma: float) -> np.ndarray:
    """depth (float32, m) + sigma z where something is hit (depth > 0); 0 stays 0."""
    return np.where(depth > 0.0, depth + np.float32(sigma) * z, np.float32(0.0)).astype(np.float32)
