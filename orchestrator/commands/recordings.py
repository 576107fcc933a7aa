"""``orchestrator plot``, ``export`` and ``figure``: what is made from a recording (run --record DIR)."""

from __future__ import annotations

from pathlib import Path

from components.outputs import output_problem
from orchestrator.commands.exits import fail


def cmd_plot(args) -> int:
    from components.plotting import PlotError
    from orchestrator.plots.recording import plot_recording

    out = Path(args.out) if args.out else Path(args.recording) / "plots"
    if problem := output_problem(out, "--out" if args.out else "plot: DIR/plots"):
        return fail(problem)
    signals = [name.strip() for name in args.signals.split(",") if name.strip()] if args.signals else None
    try:
        written = plot_recording(Path(args.recording), out, signals)
    except PlotError as e:
        return fail(str(e))
    except Exception as e:  # e.g. a truncated signals.parquet
        return fail(f"cannot plot {args.recording}: {type(e).__name__}: {e}")
    for path in written:
        print(f"wrote {path}")
    return 0


def cmd_export(args) -> int:
    from orchestrator.export.rosbag2 import ExportError, export_rosbag2

    if problem := output_problem(args.rosbag2, "--rosbag2"):
        return fail(problem)
    try:
        exported = export_rosbag2(Path(args.recording), Path(args.rosbag2), args.overwrite, args.all_signals)
    except ExportError as e:
        return fail(str(e))
    except OSError as e:
        return fail(f"cannot export {args.recording} to {args.rosbag2}: {e}")
    topics = ", ".join(f"{name} ({n})" for name, n in exported.counts.items())
    print(f"wrote {exported.path} (rosbag2, MCAP, {exported.size / 1e6:.1f} MB): {topics}")
    return 0


def cmd_figure(args) -> int:
    from components.camera.figure import draw, nearest_frame

    if problem := output_problem(args.out, "--out", "file"):
        return fail(problem)
    frames = Path(args.recording) / "frames" / args.component
    try:
        path = nearest_frame(frames, args.time)
    except FileNotFoundError as e:
        return fail(f"{e} (a recording of `orchestrator run --record DIR` with a camera {args.component!r})")
    draw(path, Path(args.out))
    print(f"wrote {args.out}: {path}")
    return 0
