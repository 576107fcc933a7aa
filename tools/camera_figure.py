"""A figure of what a camera saw in a recorded run: one frame's colour image beside its depth.

    python -m tools.camera_figure RUN_DIR --component wrist --time 3.2 --out figure.png

Reads ``RUN_DIR/frames/<component>/<k>.npz`` (``rgb``, ``depth``, the frame's time ``t`` in s) as
``sensor.camera`` writes them and draws the frame taken
nearest ``--time`` (s): the image on the left, the depth (m along the optical axis, black where
nothing is hit) on the right, titled with the frame's time. The README's vision figure
(docs/images/capture_vision.png) is made this way from configs/capture_vision.yaml.
"""
from __future__ import annotations

import argparse
import io
import sys
from pathlib import Path

import numpy as np


def nearest_frame(frames: Path, t: float) -> Path:
    """The recorded frame (``<k>.npz`` in ``frames``) taken nearest ``t`` (s)."""
    paths = sorted(frames.glob("*.npz"))
    if not paths:
        raise FileNotFoundError(f"no frames in {frames}")
    times = []
    for path in paths:
        with np.load(path) as frame:
            times.append(float(frame["t"]))
    return paths[int(np.argmin(np.abs(np.array(times) - t)))]


def draw(path: Path, out: Path, width_inches: float = 8.0) -> None:
    """Write ``out`` (PNG): the frame at ``path``, colour beside depth."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image

    with np.load(path) as frame:
        rgb, t = frame["rgb"], float(frame["t"])
        depth = frame["depth"] if "depth" in frame.files else None
    panels = 1 if depth is None else 2
    height, width = rgb.shape[:2]
    figure, axes = plt.subplots(1, panels, figsize=(width_inches, width_inches / panels * height / width + 0.5),
                                squeeze=False)
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tools.camera_figure", description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="a recorded run's directory (orchestrator run --record DIR)")
    parser.add_argument("--component", required=True, help="the camera's component name (its frames' folder)")
    parser.add_argument("--time", type=float, required=True, help="the frame taken nearest this time (s)")
    parser.add_argument("--out", type=Path, required=True, help="the PNG to write")
    args = parser.parse_args(argv)
    frames = args.run / "frames" / args.component
    try:
        path = nearest_frame(frames, args.time)
    except FileNotFoundError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    draw(path, args.out)
    print(f"{args.out}: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
