"""The pose of a marked frame from one camera image (no I/O): ArUco markers detected by OpenCV,
a perspective-n-point solve over every marker seen, checks that refuse a doubtful answer.

Frames: the camera's is OpenCV's (z along the optical axis, x right, y down in the image); the
grasp frame G is the layout's link (components/estimators/marker_layout.py), each marker placed
in it; E is the frame the camera is mounted in (the end effector), ``T_E_C`` = (``p_ee_camera``,
``R_ee_camera``). The answer is G's pose in E: ``p_ee_grasp`` (m, E axes) and ``q_ee_grasp``
(q_E_G, [x, y, z, w], w >= 0: a series' sign continuity is its caller's).

The solve:

1. Detection (``cv2.aruco.ArucoDetector``, corners refined to sub-pixel) on the grey image; ids
   not in the layout, and ids seen more than once (which one is the marker?), are dropped.
2. A first pose from each marker alone: IPPE for a square (``SOLVEPNP_IPPE_SQUARE``) gives both
   poses that fit its four corners (a small or distant square is ambiguous); each, moved to G,
   is scored by the reprojection error over every marker's corners, and the best kept.
3. Levenberg-Marquardt (``solvePnPRefineLM``) on all the corners from that pose.
4. Refused (``valid`` False, ``reason`` saying why): fewer than ``min_markers`` markers, an RMS
   reprojection error above ``max_reprojection_error`` (pixels), or G behind the camera.

With one marker the pose is that of a 4-point square (its ambiguity is resolved only by the
score above: keep ``min_markers`` at 2 when the markers are small in the image); several markers
off one plane (the layout's tip and root markers) give a well-conditioned solve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from components.estimators.marker_layout import MarkerLayout
from components.rotations import matrix_to_quat


@dataclass(frozen=True)
class Estimate:
    """One image's answer. ``p_ee_grasp`` (m), ``q_ee_grasp`` ([x, y, z, w]) are NaN when no pose
    was solved; ``markers``: the layout's markers used; ``reprojection_error``: RMS over their
    corners (px, NaN without a pose); ``reason``: why it is not valid ("" when it is)."""

    valid: bool
    p_ee_grasp: np.ndarray
    q_ee_grasp: np.ndarray
    markers: int
    reprojection_error: float
    reason: str


class FiducialEstimator:
    """Grasp-frame pose from images of the layout's markers; thresholds ``min_markers`` (>= 1)
    and ``max_reprojection_error`` (px RMS)."""

    def __init__(self, layout: MarkerLayout, min_markers: int, max_reprojection_error: float):
        import cv2  # heavy: only when an estimator is built

        self.cv2 = cv2
        if min_markers < 1:
            raise ValueError(f"min_markers: expected at least 1, got {min_markers}")
        self.layout, self.min_markers, self.max_error = layout, int(min_markers), float(max_reprojection_error)
        parameters = cv2.aruco.DetectorParameters()
        parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        # a marker's white quiet zone on a darker surface is a second square a cell outside its
        # black one: OpenCV's default (0.125 of the perimeter) groups the two and at times keeps
        # the white one (607 of 625 markers found in 160 random views at 0.1-1 m; 624 with 0.05;
        # 0.02 finds some markers twice)
        parameters.minMarkerDistanceRate = 0.05
        self.detector = cv2.aruco.ArucoDetector(
            cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, layout.dictionary)), parameters
        )
        self.markers = layout.by_id()
        # each marker's corners in its own frame (IPPE_SQUARE's order) and in G
        self.square = {i: _square(m.size) for i, m in self.markers.items()}
        self.corners_G = {i: m.corners() for i, m in self.markers.items()}

    def detect(self, rgb: np.ndarray) -> dict[int, np.ndarray]:
        """The layout's markers seen once each: id -> its 4 corners (px, 4 x 2, OpenCV's order)."""
        if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
            raise ValueError(f"expected an H x W x 3 uint8 RGB image, got {rgb.dtype} {rgb.shape}")
        gray = self.cv2.cvtColor(rgb, self.cv2.COLOR_RGB2GRAY)
        corners, ids, _ = self.detector.detectMarkers(gray)
        if ids is None:
            return {}
        found = [int(i) for i in ids.ravel()]
        return {
            i: c.reshape(4, 2).astype(np.float64)
            for i, c in zip(found, corners)
            if i in self.markers and found.count(i) == 1
        }

    def estimate(
        self, rgb: np.ndarray, K: np.ndarray, distortion: np.ndarray, p_ee_camera: np.ndarray, R_ee_camera: np.ndarray
    ) -> Estimate:
        """G's pose in E from one image (RGB, H x W x 3 uint8) taken with intrinsics ``K`` (3x3,
        px) and ``distortion`` (OpenCV's k1, k2, p1, p2[, k3]; empty: none) by a camera at
        ``p_ee_camera`` (m), ``R_ee_camera`` in E."""
        cv2 = self.cv2
        K = np.asarray(K, dtype=np.float64)
        distortion = np.asarray(distortion, dtype=np.float64).ravel()
        seen = self.detect(rgb)
        if len(seen) < self.min_markers:
            return _invalid(len(seen), np.nan, f"{len(seen)} marker(s) seen, {self.min_markers} needed")
        ids = sorted(seen)
        points_G = np.concatenate([self.corners_G[i] for i in ids])
        pixels = np.concatenate([seen[i] for i in ids])
        best = None
        for i in ids:
            marker = self.markers[i]
            count, rvecs, tvecs, _ = cv2.solvePnPGeneric(
                self.square[i], seen[i], K, distortion, flags=cv2.SOLVEPNP_IPPE_SQUARE
            )
            for rvec, tvec in zip(rvecs[:count], tvecs[:count]):
                R_C_M = cv2.Rodrigues(rvec)[0]
                R_C_G = R_C_M @ marker.R_link_marker.T
                p_C_G = tvec.ravel() - R_C_G @ marker.p_link_marker
                error = self._rms(points_G, pixels, R_C_G, p_C_G, K, distortion)
                if best is None or error < best[0]:
                    best = (error, R_C_G, p_C_G)
        assert best is not None, "IPPE_SQUARE gives each marker seen its poses"
        _, R_C_G, p_C_G = best
        rvec, tvec = cv2.solvePnPRefineLM(points_G, pixels, K, distortion, cv2.Rodrigues(R_C_G)[0], p_C_G.reshape(3, 1))
        R_C_G, p_C_G = cv2.Rodrigues(rvec)[0], tvec.ravel()
        error = self._rms(points_G, pixels, R_C_G, p_C_G, K, distortion)
        if not np.all((points_G @ R_C_G.T + p_C_G)[:, 2] > 0.0):
            return _invalid(len(ids), error, "the solved pose puts markers behind the camera")
        if not error <= self.max_error:
            return _invalid(len(ids), error, f"reprojection error {error:.3g} px above {self.max_error:g} px")
        R_E_G = R_ee_camera @ R_C_G
        p_E_G = R_ee_camera @ p_C_G + p_ee_camera
        return Estimate(True, p_E_G, matrix_to_quat(R_E_G), len(ids), error, "")

    def _rms(self, points_G, pixels, R_C_G, p_C_G, K, distortion) -> float:
        projected, _ = self.cv2.projectPoints(points_G, self.cv2.Rodrigues(R_C_G)[0], p_C_G, K, distortion)
        return float(np.sqrt(np.mean(np.sum((projected.reshape(-1, 2) - pixels) ** 2, axis=1))))


def _square(size: float) -> np.ndarray:
    """A square's corners in its own frame, as SOLVEPNP_IPPE_SQUARE wants them (m)."""
    h = 0.5 * size
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def _invalid(markers: int, error: float, reason: str) -> Estimate:
    return Estimate(False, np.full(3, np.nan), np.full(4, np.nan), markers, error, reason)
