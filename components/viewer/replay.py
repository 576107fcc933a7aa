"""``orchestrator view DIR``: replay a recording (``orchestrator run --record DIR``) into Rerun.

    orchestrator view DIR [--view spawn|web|save:FILE.rrd] [--rate HZ] [--open-browser]

Reads ``DIR/config.yaml`` (the resolved config: which components, which URDFs) and
``DIR/signals.parquet`` in batches, keeps the rows the live view would have shown (every n-th step,
n = round(1 / (rate * step)), default 30 Hz of sim time) and logs them with the same
``SceneLogger`` as the live observer: same entities, same layout. URDF paths in the config are
resolved as ``dynamics.dart`` resolves them: relative to the original config file, found through
``DIR/events.jsonl`` (its ``start`` event, whose path may be relative to where the run was
started: looked up from the current directory, then from the project root; the current directory
without one), else to the project root.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from pathlib import Path

from components.constants import NS_PER_S
from components.extras import missing
from components.outputs import output_problem

USAGE_ERROR = 2
DEFAULT_RATE_HZ = 30.0
BATCH_ROWS = 8192


class ReplayError(Exception):
    """The directory is not a readable recording."""


def read_recording(directory: str | Path) -> tuple[dict, Path | None, str]:
    """(resolved config, directory of the original config file or None, run id) of a recording."""
    import yaml

    directory = Path(directory)
    if not (directory / "signals.parquet").exists():
        raise ReplayError(
            f"{directory}: no signals.parquet here (record one with `orchestrator run CONFIG --record DIR`)"
        )
    try:
        config = yaml.safe_load((directory / "config.yaml").read_text()) or {}
    except (OSError, yaml.YAMLError) as e:
        raise ReplayError(f"{directory / 'config.yaml'}: cannot read the resolved config ({e})") from None
    config_dir, run_id = None, f"{(config.get('run') or {}).get('name', 'run')}"
    try:
        for line in (directory / "events.jsonl").read_text().splitlines():
            event = json.loads(line)
            if event.get("event") == "start":
                run_id = event.get("run_id", run_id)
                if event.get("config"):
                    config_dir = _config_dir(event["config"])
                break
    except (OSError, ValueError):
        pass
    return config, config_dir, run_id


def _config_dir(path: str) -> Path:
    """The directory of the run's config file as the start event names it: absolute, or relative to
    the current directory, else to the project root (a run started there); the first if none exists."""
    from components.robots.model import PROJECT_ROOT

    recorded = Path(path)
    for candidate in (recorded, PROJECT_ROOT / recorded):
        if candidate.is_file():
            return candidate.resolve().parent
    return recorded.resolve().parent


def decimation(config: dict, rate_hz: float, times=None) -> int:
    """Every how many steps the live view logs a row (as the orchestrator decides it)."""
    from components.units import duration_ns

    step_ns = None
    try:
        step_ns = duration_ns((config.get("run") or {}).get("step"), "step")
    except Exception:
        if times is not None and len(times) > 1:
            step_ns = int(round((times[1] - times[0]) * NS_PER_S))
    if not step_ns:
        return 1
    return max(1, round(NS_PER_S / (rate_hz * step_ns)))


def replay(
    directory: str | Path,
    mode: str = "spawn",
    file: str | Path | None = None,
    *,
    rate_hz: float = DEFAULT_RATE_HZ,
    open_browser: bool = False,
    out=sys.stderr,
) -> int:
    """Log a recording into Rerun; returns the number of rows logged. Web mode serves until Ctrl-C."""
    from components.viewer.scene import SceneLogger
    from components.viewer.sinks import close_stream, open_stream

    config, config_dir, run_id = read_recording(directory)
    parquet, columns = _signals(directory)
    n = decimation(config, rate_hz)
    scene = SceneLogger(
        columns,
        config,
        config_dir,
        warn=lambda m: print(f"view: {m}", file=out, flush=True),
        frames_dir=Path(directory) / "frames",
    )
    stream, url = open_stream(
        mode,
        recording_id=f"{run_id}-replay",
        file=file,
        blueprint=scene.blueprint(),
        open_browser=open_browser,
        name=f"{(config.get('run') or {}).get('name', run_id)} (replay)",
    )
    scene.rec = stream
    try:
        scene.log_static()
        _log_rows(scene, parquet, columns, n)
        stream.flush(timeout_sec=60.0)
        if url:
            print(f"Rerun web viewer at {url}\n{scene.rows_logged} rows; serving until Ctrl-C", file=out, flush=True)
            _serve_until_interrupted()
    finally:
        close_stream(stream)
    return scene.rows_logged


def _signals(directory: str | Path):
    """(the recording's signals.parquet as a pyarrow dataset, its recorded columns after step and
    time); ReplayError for one with no rows or other first columns."""
    import pyarrow.dataset as ds

    parquet = ds.dataset(Path(directory) / "signals.parquet", format="parquet")  # a file, or a dataset directory
    names = parquet.schema.names
    if not names or not parquet.count_rows():
        raise ReplayError(
            f"{directory}/signals.parquet: the recording holds no rows (the run wrote none before it ended: its events.jsonl says why)"
        )
    if names[:2] != ["step", "time"]:
        raise ReplayError(f"{directory}/signals.parquet: expected the columns step, time first, got {names[:2]}")
    return parquet, names[2:]


def _log_rows(scene, parquet, columns: list[str], n: int) -> None:
    """Log every ``n``-th step's row of the recording, read in batches."""
    import numpy as np

    for batch in parquet.to_batches(batch_size=BATCH_ROWS):
        steps = batch.column(0).to_numpy()
        keep = np.flatnonzero(steps % n == 0)
        if not len(keep):
            continue
        times = batch.column(1).to_numpy()[keep]
        rows = (
            np.column_stack([batch.column(j).to_numpy()[keep] for j in range(2, batch.num_columns)])
            if columns
            else np.zeros((len(keep), 0))
        )
        scene.log_rows(steps[keep], times, rows)


def _serve_until_interrupted() -> None:
    """Keep the web viewer's server up until Ctrl-C or SIGTERM."""
    previous = signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, previous)


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt()


def add_view_command(subparsers) -> argparse.ArgumentParser:
    """Add ``view`` to the ``orchestrator`` command line (``subparsers`` of its parser)."""
    p = subparsers.add_parser("view", help="replay a recording (run --record DIR) in Rerun")
    p.add_argument("dir", metavar="DIR", help="a recording directory (signals.parquet, config.yaml)")
    p.add_argument(
        "--view",
        default="spawn",
        metavar="{spawn,web,save:FILE.rrd}",
        help="desktop viewer (default), web viewer on localhost, or an .rrd file",
    )
    p.add_argument(
        "--rate",
        type=float,
        default=DEFAULT_RATE_HZ,
        metavar="HZ",
        help=f"rows per second of sim time (default {DEFAULT_RATE_HZ:g}, as the live view)",
    )
    p.add_argument("--open-browser", action="store_true", help="web: open the page in the default browser")
    p.set_defaults(func=cmd_view)
    return p


def cmd_view(args) -> int:
    """``orchestrator view``: 0 done, 2 bad usage or not a recording, 1 failure."""
    mode, _, file = args.view.partition(":")
    if mode not in ("spawn", "web", "save") or (mode == "save") != bool(file) or (file and not file.endswith(".rrd")):
        print(f"error: --view: expected spawn, web or save:FILE.rrd, got {args.view!r}", file=sys.stderr)
        return USAGE_ERROR
    if problem := missing("view", "orchestrator view (Rerun)"):
        print(f"error: {problem}", file=sys.stderr)
        return USAGE_ERROR
    if mode == "spawn":
        from components.viewer.sinks import spawn_problem

        if spawn_problem():
            print(f"error: --view spawn: {spawn_problem()}", file=sys.stderr)
            return USAGE_ERROR
    if not args.rate > 0:
        print(f"error: --rate: must be positive, got {args.rate:g}", file=sys.stderr)
        return USAGE_ERROR
    if file and (problem := output_problem(file, "--view save:", "file")):
        print(f"error: {problem}", file=sys.stderr)
        return USAGE_ERROR
    try:
        rows = replay(args.dir, mode, file or None, rate_hz=args.rate, open_browser=args.open_browser)
    except ReplayError as e:
        print(f"error: {e}", file=sys.stderr)
        return USAGE_ERROR
    except KeyboardInterrupt:
        return 130
    except Exception as e:  # one line naming the cause, not a traceback
        print(f"error: replaying {args.dir}: {type(e).__name__}: {e}", file=sys.stderr)
        return 1
    if mode == "save":
        print(f"saved {rows} rows to {file}", file=sys.stderr)
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m components.viewer.replay DIR [...]``: the same as ``orchestrator view``."""
    parser = argparse.ArgumentParser(prog="python -m components.viewer.replay", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    add_view_command(sub)
    args = parser.parse_args(["view", *(sys.argv[1:] if argv is None else argv)])
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
