"""estimator.fiducial at capture distance: its pose error against the truth and its time per
640x480 frame, in process (no bus).

    python benchmarks/bench_fiducial.py [--poses 40] [--repeat 5] [--threads 1]

Pictures: the capture target's marker layout (models/capture/grapple_markers.yaml) drawn by the
homography warp of tests/fiducial_scenes.py at ``--poses`` random poses per distance band (the
camera 0.1-0.2, 0.2-0.3, 0.3-0.5 and 0.5-1 m in front of the grapple's tip, up to 5 cm off its
axis, tilted up to 8 deg, any roll), white pixel noise of 2 grey levels, the wrist camera's mount
in E of the tests. Error: position (mm) and attitude (deg) of G in E, median and worst per band;
frames refused counted. Time: the thread's CPU time (``time.thread_time_ns``) and the wall time of
``FiducialEstimator.estimate`` per frame, the lowest median of ``--repeat`` passes over the frames
(OpenCV's threads: ``--threads``, ``cv2.setNumThreads``; the wall time counts them, the thread's
CPU time does not).
"""

from __future__ import annotations

import argparse
import math
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import cv2  # noqa: E402

from components.estimators.fiducial import FiducialEstimator  # noqa: E402
from components.estimators.marker_layout import read_layout  # noqa: E402
from components.rotations import exp_so3, log_so3, quat_to_matrix  # noqa: E402
from tests import fiducial_scenes as scenes  # noqa: E402

BANDS = ((0.1, 0.2), (0.2, 0.3), (0.3, 0.5), (0.5, 1.0))
P_EE_CAMERA = np.array([0.0, 0.07, -0.05])
R_EE_CAMERA = exp_so3([0.12, 0.0, 0.02])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=40)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--min-markers", type=int, default=1)
    args = parser.parse_args(argv)
    cv2.setNumThreads(args.threads)
    layout = read_layout(scenes.LAYOUT)
    estimator = FiducialEstimator(layout, args.min_markers, 1.5)
    rng = np.random.Generator(np.random.PCG64(2026))
    print(f"{platform.processor() or platform.machine()}, OpenCV {cv2.__version__}, {args.threads} OpenCV thread(s)")
    print(
        "| distance (m) | frames | refused | position median / worst (mm) | attitude median / worst (deg) "
        "| markers (median) |"
    )
    print("|---|---|---|---|---|---|")
    images = []
    for low, high in BANDS:
        dps, das, refused, counts = [], [], 0, []
        for _k in range(args.poses):
            distance = rng.uniform(low, high)
            offset = rng.uniform(-0.05, 0.05, 2)
            tilt = rng.uniform(-1.0, 1.0, 2) * math.radians(8.0)
            R_C_G, p_C_G = scenes.camera_pose(distance, offset, tilt, rng.uniform(-math.pi, math.pi))
            image = scenes.noisy(scenes.warp(layout, R_C_G, p_C_G), 2.0, seed=int(rng.integers(1 << 30)))
            images.append(image)
            estimate = estimator.estimate(image, scenes.K, np.zeros(0), P_EE_CAMERA, R_EE_CAMERA)
            if not estimate.valid:
                refused += 1
                continue
            counts.append(estimate.markers)
            R = quat_to_matrix(estimate.q_ee_grasp)
            dps.append(1e3 * np.linalg.norm(estimate.p_ee_grasp - (R_EE_CAMERA @ p_C_G + P_EE_CAMERA)))
            das.append(math.degrees(np.linalg.norm(log_so3((R_EE_CAMERA @ R_C_G).T @ R))))
        print(
            f"| {low}-{high} | {args.poses} | {refused} | {np.median(dps):.2f} / {max(dps):.2f} | "
            f"{np.median(das):.3f} / {max(das):.3f} | {np.median(counts):.0f} |"
        )
    cpu, wall = [], []
    for _ in range(args.repeat):
        c, w = [], []
        for image in images:
            t0, c0 = time.perf_counter_ns(), time.thread_time_ns()
            estimator.estimate(image, scenes.K, np.zeros(0), P_EE_CAMERA, R_EE_CAMERA)
            c.append(time.thread_time_ns() - c0)
            w.append(time.perf_counter_ns() - t0)
        cpu.append(np.median(c))
        wall.append(np.median(w))
    print(
        f"\nper 640x480 frame ({len(images)} frames, lowest median of {args.repeat} passes): "
        f"{min(cpu) / 1e6:.1f} ms CPU (this thread), {min(wall) / 1e6:.1f} ms wall"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
