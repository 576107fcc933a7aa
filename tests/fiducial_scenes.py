"""Independent pictures of a marker layout at a known pose, for the fiducial estimator's tests.

Two renderers, neither of which shares code with the estimator:

- ``warp``: each marker's picture (OpenCV's ``generateImageMarker``, quiet zone added) mapped onto
  the projection of its quad's corners (``cv2.projectPoints`` of the layout's corners) by a
  homography (``cv2.warpPerspective``), far markers first. Pinhole only.
- ``ray_cast``: the committed meshes of the markers' white and black cells (OBJ, read by trimesh)
  intersected by one ray per sub-pixel (Moeller-Trumbore in numpy), the nearest hit's colour;
  rays from ``cv2.undistortPoints``, so a distorted lens is imaged exactly. 2 x 2 sub-pixels a pixel.

Poses: ``camera_pose(distance, ...)`` puts the camera on the servicer's side of the grasp frame G
(``distance`` back along -z of G from its origin, looking along +z with a tilt and a roll), and
returns ``R_C_G``, ``p_C_G`` (the truth the estimator must find).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from components.estimators.marker_layout import MarkerLayout
from components.extras import missing
from components.rotations import exp_so3

cv2 = pytest.importorskip("cv2", reason=missing("vision", "testing the fiducial estimator"))

ROOT = Path(__file__).resolve().parents[1]
LAYOUT = ROOT / "models" / "capture" / "grapple_markers.yaml"
WIDTH, HEIGHT = 640, 480
# an off-centre principal point, square pixels
K = np.array([[520.0, 0.0, 331.7], [0.0, 520.0, 229.4], [0.0, 0.0, 1.0]])
BACKGROUND = 110


def camera_pose(distance: float, offset=(0.0, 0.0), tilt=(0.0, 0.0), roll: float = 0.0):
    """(R_C_G, p_C_G) of a camera at (offset, -distance) in G (m), its optical axis along G's +z
    turned by ``tilt`` (rad about G's x then y) and rolled by ``roll`` (rad about the axis)."""
    R_G_C = exp_so3([tilt[0], 0.0, 0.0]) @ exp_so3([0.0, tilt[1], 0.0]) @ exp_so3([0.0, 0.0, roll])
    p_G_C = np.array([offset[0], offset[1], -distance])
    R_C_G = R_G_C.T
    return R_C_G, -R_C_G @ p_G_C


def marker_tile(layout: MarkerLayout, marker_id: int, cell: int = 24) -> np.ndarray:
    """A marker's picture with its quiet zone (grey uint8), top row first."""
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, layout.dictionary))
    image = cv2.aruco.generateImageMarker(dictionary, marker_id, layout.cells * cell, borderBits=1)
    return np.pad(image, layout.quiet_zone * cell, constant_values=255)


def warp(layout: MarkerLayout, R_C_G, p_C_G, K=K, size=(HEIGHT, WIDTH), shift=None) -> np.ndarray:
    """RGB image (uint8) of the layout's markers seen from (R_C_G, p_C_G). ``shift``: id -> an
    offset (m, G) to draw that marker displaced from where the layout says."""
    image = np.full(size, float(BACKGROUND))
    rvec = cv2.Rodrigues(np.asarray(R_C_G, dtype=np.float64))[0]
    order = sorted(layout.markers, key=lambda m: -(R_C_G @ m.p_link_marker + p_C_G)[2])  # far first
    for marker in order:
        corners = marker.corners(marker.size * layout.quad_scale) + (shift or {}).get(marker.id, 0.0)
        if np.any((corners @ np.asarray(R_C_G).T + p_C_G)[:, 2] <= 0.01):
            continue
        projected, _ = cv2.projectPoints(corners, rvec, np.asarray(p_C_G, dtype=np.float64), K, None)
        tile = marker_tile(layout, marker.id).astype(np.float64)
        n = tile.shape[0]
        # pixel centres of the tile's corners -> the projected corners (OpenCV: centre of pixel 0 is 0)
        source = np.array([[0, 0], [n, 0], [n, n], [0, n]], dtype=np.float32) - 0.5
        H = cv2.getPerspectiveTransform(source, projected.reshape(4, 2).astype(np.float32))
        drawn = cv2.warpPerspective(tile, H, (size[1], size[0]), flags=cv2.INTER_LINEAR, borderValue=-1.0)
        inside = cv2.warpPerspective(np.ones_like(tile), H, (size[1], size[0]), flags=cv2.INTER_LINEAR)
        inside = np.clip(inside, 0.0, 1.0)
        image = image * (1.0 - inside) + np.where(drawn < 0, 0.0, drawn) * inside
    return _rgb(image)


def ray_cast(
    layout: MarkerLayout, R_C_G, p_C_G, K=K, distortion=None, size=(HEIGHT, WIDTH), sub: int = 2
) -> np.ndarray:
    """RGB image (uint8) of the layout's committed meshes (white cells 255, black cells 0, vertices
    in G, read by trimesh) from (R_C_G, p_C_G)."""
    import trimesh

    from components.estimators.marker_meshes import mesh_path

    h, w = size
    # sub-pixel (r, c) of the (h sub) x (w sub) grid: its centre at u = (c + 0.5) / sub - 0.5, and its ray
    c, r = np.meshgrid((np.arange(w * sub) + 0.5) / sub - 0.5, (np.arange(h * sub) + 0.5) / sub - 0.5)
    rays = cv2.undistortPoints(np.stack([c, r], axis=-1).reshape(-1, 1, 2), K, distortion).reshape(h * sub, w * sub, 2)
    d = np.concatenate([rays, np.ones((h * sub, w * sub, 1))], axis=-1)
    depth = np.full((h * sub, w * sub), np.inf)
    value = np.full((h * sub, w * sub), float(BACKGROUND))
    rvec = cv2.Rodrigues(np.asarray(R_C_G, dtype=np.float64))[0]
    for colour, grey in (("white", 255.0), ("black", 0.0)):
        mesh = trimesh.load(str(mesh_path(layout, colour)), force="mesh", process=False)
        vertices = np.asarray(mesh.vertices) @ np.asarray(R_C_G).T + p_C_G  # camera frame
        if np.any(vertices[:, 2] <= 0.0):
            raise ValueError("a marker reaches behind the camera")
        projected, _ = cv2.projectPoints(
            np.asarray(mesh.vertices, dtype=np.float64), rvec, np.asarray(p_C_G, dtype=np.float64), K, distortion
        )
        projected = projected.reshape(-1, 2)
        for face in np.asarray(mesh.faces):
            # only the sub-pixels around the triangle's image (2 pixels of margin for the lens)
            lo = np.floor((projected[face].min(axis=0) - 2.0 + 0.5) * sub).astype(int)
            hi = np.ceil((projected[face].max(axis=0) + 2.0 + 0.5) * sub).astype(int)
            c0, r0 = max(lo[0], 0), max(lo[1], 0)
            c1, r1 = min(hi[0], w * sub), min(hi[1], h * sub)
            if c0 >= c1 or r0 >= r1:
                continue
            ray = d[r0:r1, c0:c1]
            a, b, cc = vertices[face]
            e1, e2 = b - a, cc - a
            # Moeller-Trumbore, the ray from the camera centre along d
            pvec = np.cross(ray, e2)
            det = pvec @ e1
            with np.errstate(divide="ignore", invalid="ignore"):
                inv = 1.0 / det
                s = (pvec @ -a) * inv
                qvec = np.cross(-a, e1)
                t_ = (ray @ qvec) * inv
                z = (qvec @ e2) * inv
            window = depth[r0:r1, c0:c1]
            hit = (np.abs(det) > 1e-15) & (s >= 0) & (t_ >= 0) & (s + t_ <= 1) & (z > 0) & (z < window)
            value[r0:r1, c0:c1][hit] = grey
            window[hit] = z[hit]
    return _rgb(value.reshape(h, sub, w, sub).mean(axis=(1, 3)))


def noisy(rgb: np.ndarray, sigma: float, seed: int) -> np.ndarray:
    """``rgb`` plus white Gaussian noise of ``sigma`` grey levels, rounded and clipped."""
    noise = np.random.Generator(np.random.PCG64(seed)).standard_normal(rgb.shape[:2]) * sigma
    return _rgb(rgb[:, :, 0].astype(np.float64) + noise)


def _rgb(gray: np.ndarray) -> np.ndarray:
    g = np.clip(np.rint(gray), 0, 255).astype(np.uint8)
    return np.repeat(g[:, :, None], 3, axis=2)
