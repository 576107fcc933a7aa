"""Lens distortion (ROS's plumb_bob, OpenCV's five-coefficient model) as a resampling of a pinhole
render: plain numpy, no I/O.

A point at normalized pinhole coordinates (x, y) = (X/Z, Y/Z) is seen at pixel
``u = fx x_d + cx``, ``v = fy y_d + cy`` with, for ``D = [k1, k2, p1, p2, k3]`` and r^2 = x^2 + y^2,

    x_d = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)
    y_d = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y

:class:`Lens` inverts that for every pixel centre of the image once (fixed-point iteration, as
OpenCV's undistortPoints does, checked to converge), renders a pinhole image at ``supersample``
times the focal lengths large enough to hold every ray the image needs, and takes each pixel from
the render's pixel nearest its ray: colour and depth (the depth along the optical axis does not
depend on the lens). The ray a pixel shows is off by at most half a render pixel: 1/4 of an image
pixel at the default supersample of 2.
"""

from __future__ import annotations

import math

import numpy as np

ITERATIONS = 100
RESIDUAL = 1e-9  # normalized units (rad, near the axis): the inversion must reach this


def distort(x: np.ndarray, y: np.ndarray, D) -> tuple[np.ndarray, np.ndarray]:
    """The plumb_bob model: normalized pinhole (x, y) -> normalized distorted (x_d, y_d)."""
    k1, k2, p1, p2, k3 = (float(c) for c in D)
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    return (
        x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
        y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
    )


def undistort(x_d: np.ndarray, y_d: np.ndarray, D) -> tuple[np.ndarray, np.ndarray, float]:
    """Normalized distorted -> pinhole coordinates by fixed-point iteration; and the largest
    residual |distort(x, y) - (x_d, y_d)| (inf where the iteration diverged)."""
    k1, k2, p1, p2, k3 = (float(c) for c in D)
    x, y = x_d.copy(), y_d.copy()
    with np.errstate(all="ignore"):
        for _ in range(ITERATIONS):
            r2 = x * x + y * y
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            x, y = (
                (x_d - 2.0 * p1 * x * y - p2 * (r2 + 2.0 * x * x)) / radial,
                (y_d - p1 * (r2 + 2.0 * y * y) - 2.0 * p2 * x * y) / radial,
            )
        xr, yr = distort(x, y, D)
        residual = np.hypot(xr - x_d, yr - y_d)
    worst = float(np.max(residual)) if residual.size else 0.0
    return x, y, worst if math.isfinite(worst) else math.inf


def pixel_grid(width: int, height: int, K: np.ndarray, step: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Normalized distorted coordinates of the pixel centres (every ``step``-th, and the last row
    and column), shape (rows, cols)."""
    us = np.unique(np.append(np.arange(0, width, step), width - 1)).astype(np.float64)
    vs = np.unique(np.append(np.arange(0, height, step), height - 1)).astype(np.float64)
    u, v = np.meshgrid(us, vs)
    return (u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1]


def inversion_problem(width: int, height: int, K: np.ndarray, D, step: int = 16) -> str | None:
    """Why ``D`` cannot be inverted over the image (checked on a grid of every ``step``-th pixel
    and the borders), or None."""
    x_d, y_d = pixel_grid(width, height, K, step)
    _, _, residual = undistort(x_d, y_d, D)
    if not residual <= RESIDUAL:
        return (
            f"the distortion does not invert over the image (residual {residual:.3g} after {ITERATIONS} "
            "iterations): too strong for this field of view"
        )
    return None


class Lens:
    """The resampling of a pinhole render into a distorted image of ``width`` x ``height`` with
    intrinsics ``K`` and plumb_bob coefficients ``D``. ``K_render``, ``render_width``,
    ``render_height``: the pinhole render it needs. ValueError when ``D`` does not invert."""

    def __init__(self, K: np.ndarray, width: int, height: int, D, supersample: int = 2):
        K = np.asarray(K, dtype=np.float64)
        x_d, y_d = pixel_grid(width, height, K)
        x, y, residual = undistort(x_d, y_d, D)
        if not residual <= RESIDUAL:
            raise ValueError(f"the distortion does not invert over the image (residual {residual:.3g})")
        fx, fy = supersample * K[0, 0], supersample * K[1, 1]
        # the render's pixel centres at integers; one pixel of margin around the rays needed
        u, v = fx * x, fy * y
        u0, v0 = math.floor(float(u.min())) - 1, math.floor(float(v.min())) - 1
        self.render_width = math.ceil(float(u.max())) + 2 - u0
        self.render_height = math.ceil(float(v.max())) + 2 - v0
        self.K_render = np.array([[fx, 0.0, -u0], [0.0, fy, -v0], [0.0, 0.0, 1.0]])
        self.rows = np.rint(v - v0).astype(np.intp)
        self.cols = np.rint(u - u0).astype(np.intp)

    def apply(self, rgb: np.ndarray, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The distorted image and depth from the pinhole render's."""
        return rgb[self.rows, self.cols], depth[self.rows, self.cols]
