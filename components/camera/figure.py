"""A figure of what a camera saw in a recorded run: one frame's colour image beside its depth.

    orchestrator figure RUN_DIR --component wrist --time 3.2 --out figure.png

Reads ``RUN_DIR/frames/<component>/<k>.npz`` (``rgb``, ``depth``, the frame's time ``t`` in s) as
``sensor.camera`` writes them (:mod:`components.camera.frames`) and draws the frame taken
nearest ``--time`` (s): the image on the left, the depth (m along the optical axis, black where
nothing is hit) on the right, titled with the frame's time. The README's vision figure
(docs/images/capture_vision.png) is made this way from configs/capture_vision.yaml.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from components.camera.frames import frame_files, read_frame


def nearest_frame(frames: Path, t: float) -> Path:
    """The recorded frame (``<k>.npz`` in ``frames``) taken nearest ``t`` (s)."""
    paths = frame_files(frames)
    if not paths:
        raise FileNotFoundError(
            f"{frames}: expected the camera's frame files (NNNNNN.npz), got "
            + ("none" if frames.is_dir() else "no such directory")
        )
    times = [float(read_frame(path, ("t",))["t"]) for path in paths]
    return paths[int(np.argmin(np.abs(np.array(times) - t)))]


def draw(path: Path, out: Path, width_inches: float = 8.0) -> None:
    """Write ``out`` (PNG): the frame at ``path``, colour beside depth."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image

    frame = read_frame(path, ("rgb", "depth", "t"))
    rgb, t, depth = frame["rgb"], float(frame["t"]), frame.get("depth")
    panels = 1 if depth is None else 2
    height, width = rgb.shape[:2]
    figure, axes = plt.subplots(
        1, panels, figsize=(width_inches, width_inches / panels * height / width + 0.5), squeeze=False
    )
    axes[0, 0].imshow(rgb)
    axes[0, 0].set_title(f"colour, t = {t:.2f} s", fontsize=9)
    if depth is not None:
        shown = np.ma.masked_equal(depth, 0.0)
        colours = matplotlib.colormaps["viridis"].with_extremes(bad="black")
        image = axes[0, 1].imshow(shown, cmap=colours)
        axes[0, 1].set_title("depth (m along the optical axis)", fontsize=9)
        figure.colorbar(image, ax=axes[0, 1], fraction=0.035, pad=0.02)
    for axis in axes[0]:
        axis.set_xticks([])
        axis.set_yticks([])
    figure.tight_layout()
    buffer = io.BytesIO()
    figure.savefig(buffer, dpi=80)
    plt.close(figure)
    # a palette of 256 colours: a third of the bytes, for a figure committed beside the docs
    Image.open(buffer).convert("RGB").quantize(256).save(out, optimize=True)
