"""The ``viewer.rerun`` observer process: signal rows from the bus into Rerun, live.

    python -m components.viewer.observer --connect tcp/127.0.0.1:7447 --run-id demo-1a2b3c4d --setup viewer.json

The orchestrator starts it when a run has a viewer (``--view spawn|web|save:FILE.rrd`` or a
``viewer:`` config section) and writes the setup JSON: ``columns``, ``config`` (resolved),
``config_dir``, ``step_ns``, ``epoch``, ``mode`` (spawn | web | save), ``file``, ``open_browser``.

The process subscribes to ``zenorbit/<run_id>/signals`` and then at once declares its liveliness
token ``alive/_viewer/0`` (the orchestrator waits for it before the first step): no row can be
missed, and rows wait in the FIFO channel while Rerun, the URDFs and the Pinocchio models load, so
the run does not wait for that. Each sample is ``<qd`` (step, time in s) then one float64 per
column, already decimated by the orchestrator; ``END`` ends the run: the data is flushed and the
process exits, except in web mode where it keeps serving until SIGINT/SIGTERM or until the
orchestrator's token goes away. It also exits when the orchestrator's liveliness token goes away.
The publisher drops rather than waits and this process runs niced, so a slow viewer never holds up
the lockstep. All work happens on the main thread, polling FIFO channels; rows are logged in
batches (a few per second live, every 2 s when saving: far cheaper per row).
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np

from components import bus, bus_security

HEADER = bus.SIGNALS_HEADER          # k, time in s
END = bus.SIGNALS_END
LIVE_BATCH_S = 0.2                   # live views: log at most 5 times a second (batches are far cheaper per row)
FILE_BATCH_S = 2.0                   # save: nobody watches, so larger batches still
MAX_BATCH_ROWS = 4096
POLL_S = 0.01                        # idle poll of the FIFO channels (about 0.5 % of a core)
NICENESS = 10


class Stop(Exception):
    """SIGTERM or SIGINT: flush and leave."""


def raise_stop(signum, frame):
    raise Stop()


def log(message: str) -> None:
    print(f"viewer: {message}", file=sys.stderr, flush=True)


class RowBuffer:
    """Decodes signal payloads and accumulates rows until they are logged as one batch."""

    def __init__(self, n_columns: int):
        self.n_columns = n_columns
        self.size = HEADER.size + 8 * n_columns
        self.steps: list[int] = []
        self.times: list[float] = []
        self.rows: list[np.ndarray] = []
        self.bad = 0

    def add(self, payload: bytes) -> bool:
        """Append one row; False (and counted) when the payload does not have the expected size."""
        if len(payload) != self.size:
            self.bad += 1
            return False
        k, t = HEADER.unpack_from(payload)
        self.steps.append(k)
        self.times.append(t)
        self.rows.append(np.frombuffer(payload, dtype=np.float64, offset=HEADER.size))
        return True

    def __len__(self) -> int:
        return len(self.rows)

    def take(self):
        """(steps, times, rows) of everything buffered, and empty the buffer."""
        batch = (np.array(self.steps, dtype=np.int64), np.array(self.times), np.vstack(self.rows))
        self.steps, self.times, self.rows = [], [], []
        return batch


def observe(connect: str, run_id: str, setup: dict) -> int:
    """Run the observer until END (or the orchestrator is gone); return the exit code."""
    import zenoh

    from components.viewer.scene import SceneLogger
    from components.viewer.sinks import close_stream, open_stream, spawn_problem

    mode = setup.get("mode", "save")
    columns = list(setup["columns"])
    config = setup.get("config") or {}
    settings = bus_security.from_env()
    session = bus.open_session(connect=[connect], secret=os.environ.get(bus.SECRET_ENV), settings=settings)
    token = watcher = signals = stream = None
    scene = None
    ended = False
    try:
        # subscribe and say so first: rows wait in the FIFO while Rerun and the robots load, and the
        # orchestrator does not wait for that
        signals = session.declare_subscriber(bus.signals_key(run_id), zenoh.handlers.FifoChannel(16384))
        watcher = session.liveliness().declare_subscriber(bus.orchestrator_alive_key(run_id),
                                                          zenoh.handlers.FifoChannel(16))
        token = session.liveliness().declare_token(bus.viewer_alive_key(run_id))
        if mode == "spawn" and spawn_problem():
            log(f"cannot spawn the desktop viewer: {spawn_problem()}")
            return 1
        scene = SceneLogger(columns, config, setup.get("config_dir"), warn=log, frames_dir=setup.get("frames_dir"))
        stream, url = open_stream(mode, recording_id=run_id, file=setup.get("file"), blueprint=scene.blueprint(),
                                  open_browser=bool(setup.get("open_browser")),
                                  name=(config.get("run") or {}).get("name") or run_id)
        scene.rec = stream
        scene.log_static()
        if url:
            log(f"Rerun web viewer at {url}")
        buffer = RowBuffer(len(columns))
        batch_s = FILE_BATCH_S if mode == "save" else LIVE_BATCH_S
        last_log = time.monotonic()
        gone = False
        while not ended and not gone:
            ended, empty = take_rows(signals, buffer)
            now = time.monotonic()
            if buffer and (ended or now - last_log >= batch_s or len(buffer) >= MAX_BATCH_ROWS):
                scene.log_rows(*buffer.take())
                last_log = now
            gone = orchestrator_gone(watcher)
            if empty and not ended:
                time.sleep(POLL_S)
        if buffer:
            scene.log_rows(*buffer.take())
        if buffer.bad:
            log(f"ignored {buffer.bad} signal rows of an unexpected size (expected {buffer.size} bytes)")
        stream.flush(timeout_sec=30.0)
        if ended and mode == "web" and not gone:
            log(f"run over ({scene.rows_logged} rows); still serving {url} until Ctrl-C")
            while not orchestrator_gone(watcher):
                time.sleep(0.1)
    except Stop:
        pass
    finally:
        for declared in (token, watcher, signals):
            if declared is not None:
                try:
                    declared.undeclare()
                except Exception:
                    pass
        session.close()
        if stream is not None:
            try:
                close_stream(stream)
            except Exception as e:  # a viewer that went away must not turn into a traceback
                log(f"closing the Rerun stream: {e}")
    if mode == "save" and setup.get("file") and scene is not None:
        log(f"saved {scene.rows_logged} rows to {setup['file']}")
    return 0


def take_rows(signals, buffer: RowBuffer) -> tuple[bool, bool]:
    """Move the rows waiting on the signals subscription into ``buffer``, up to MAX_BATCH_ROWS:
    (the run's END came, the subscription is empty now)."""
    sample = signals.try_recv()
    while sample is not None:
        payload = sample.payload.to_bytes()
        if payload == END:
            return True, False
        buffer.add(payload)
        if len(buffer) >= MAX_BATCH_ROWS:
            return False, False
        sample = signals.try_recv()
    return False, True


def orchestrator_gone(watcher) -> bool:
    import zenoh
    sample = watcher.try_recv()
    while sample is not None:
        if sample.kind == zenoh.SampleKind.DELETE:
            return True
        sample = watcher.try_recv()
    return False


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m components.viewer.observer", description=__doc__.splitlines()[0])
    parser.add_argument("--connect", required=True, help="the orchestrator's Zenoh endpoint, e.g. tcp/127.0.0.1:7447")
    parser.add_argument("--run-id", required=True)
    parser.add_argument("--setup", required=True, help="the JSON file the orchestrator wrote")
    args = parser.parse_args(argv)
    signal.signal(signal.SIGTERM, raise_stop)
    signal.signal(signal.SIGINT, raise_stop)
    try:
        os.nice(NICENESS)   # a best-effort observer: on a busy machine the lockstep processes go first
    except (AttributeError, OSError):
        pass
    try:
        setup = json.loads(Path(args.setup).read_text())
    except (OSError, ValueError) as e:
        log(f"cannot read the setup file {args.setup}: {e}")
        return 2
    try:
        return observe(args.connect, args.run_id, setup)
    except Stop:
        return 0
    except Exception as e:  # one line, not a traceback; the run goes on without the viewer
        log(f"stopped: {type(e).__name__}: {e}")
        return 1


if __name__ == "__main__":
    sys.exit(main())
