"""The process every live view of a run runs in (Rerun: components/viewer/observer.py, Foxglove:
components/viewer/foxglove_observer.py, ROS 2: components/ros2/observer.py); a :class:`View`
holds only what that view does with the rows and frames.

    python -m components.viewer.observer --connect tcp/127.0.0.1:7447 --run-id demo-1a2b3c4d --setup viewer.json

The orchestrator starts it and writes the setup JSON (``columns``, ``config`` resolved,
``config_dir``, and what the view needs). The process subscribes to ``zenorbit/<run_id>/signals``,
lets the view :meth:`View.prepare` (camera frames are subscribed here, and the mesh links to their
cameras waited for), then declares its liveliness token (the orchestrator waits for it before the
first step): no row can be missed, and rows wait in the FIFO channel while the view
:meth:`View.start` s. Each sample is ``<qd`` (step, time in s) then one float64 per column, already
decimated by the orchestrator; ``END`` ends the run: the view finishes, and may keep serving
(:meth:`View.linger`) until the orchestrator's token goes away. It also exits when that token goes.
The publisher drops rather than waits and this process runs niced, so a slow view never holds up
the lockstep. All work happens on the main thread, polling FIFO channels; rows go to the view in
batches (at most every ``View.batch_s``: batches are far cheaper per row).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from components import bus, bus_security

if TYPE_CHECKING:
    import zenoh

    from components.ros_frames import LiveFrames

HEADER = bus.SIGNALS_HEADER  # k, time in s
END = bus.SIGNALS_END
LIVE_BATCH_S = 0.2  # live views: at most 5 batches a second
MAX_BATCH_ROWS = 4096
POLL_S = 0.01  # idle poll of the FIFO channels (about 0.5 % of a core)
LINGER_POLL_S = 0.1
NICENESS = 10


class Stop(Exception):
    """SIGTERM or SIGINT: flush and leave."""


def raise_stop(signum, frame):
    raise Stop()


class ViewError(Exception):
    """The view cannot go on (said in one line); ``code``: the process's exit code."""

    def __init__(self, message: str, code: int):
        super().__init__(message)
        self.code = code


def logger(prefix: str) -> Callable[[str], None]:
    def log(message: str) -> None:
        print(f"{prefix}: {message}", file=sys.stderr, flush=True)

    return log


def once(log: Callable[[str], None]) -> Callable[[str], None]:
    """``log`` saying each message once (a view's builders run per batch)."""
    said: set[str] = set()

    def warn(message: str) -> None:
        if message not in said:
            said.add(message)
            log(message)

    return warn


class RowBuffer:
    """Decodes signal payloads and accumulates rows until they go to the view as one batch."""

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


class View:
    """What one live view does with the run; the :class:`Shell` does the rest. ``name``: the
    prefix of its messages; ``mesh``: its session joins the run's mesh as a peer (camera frames
    come straight from the cameras) rather than only linking to the orchestrator."""

    name = "viewer"
    mesh = True
    batch_s = LIVE_BATCH_S

    def __init__(self, shell: Shell):
        self.shell, self.log = shell, shell.log

    def alive_key(self, run_id: str) -> str:
        return bus.viewer_alive_key(run_id)

    def prepare(self) -> None:
        """Before the liveliness token: what must be in place when the run's first step goes."""

    def start(self) -> None:
        """After the token: what may take its time (rows wait in the FIFO meanwhile)."""

    def step(self, batch) -> None:
        """Every poll: ``batch`` is the rows due, (steps, times, rows), or None."""

    def finish(self, ended: bool) -> None:
        """After the last rows; ``ended``: the run's END came (else the orchestrator went)."""

    def linger(self) -> str | None:
        """After END: the line to say while serving on (:meth:`step` with None) until the
        orchestrator goes; None: leave at once."""
        return None

    def close(self, completed: bool) -> None:
        """Always, last; ``completed``: no error stopped the view (a signal may have)."""


class Shell:
    """One run of a view: the bus side, the poll loop, the batches."""

    def __init__(self, view: type[View], connect: str, run_id: str, setup: dict, log: Callable[[str], None]):
        self.connect, self.run_id, self.setup, self.log = connect, run_id, setup, log
        self.warn = once(log)
        self.columns = list(setup["columns"])
        self.config = setup.get("config") or {}
        self.config_dir = setup.get("config_dir")
        self.session: zenoh.Session | None = None  # from run on
        self.frames: LiveFrames | None = None  # when the view asked for them
        self.view = view(self)

    def live_frames(self, typestore, topics: list[str] | None = None):
        """The run's camera frames from the bus, as ROS 2 messages (:class:`LiveFrames`)."""
        from components.ros_frames import LiveFrames

        self.frames = LiveFrames(self.session, self.run_id, self.config, self.config_dir, typestore, self.warn, topics)
        return self.frames

    def _open_session(self, mesh: bool):
        """The view's session: a peer of the run's mesh (``mesh``), else linked to ``connect`` alone."""
        secret, settings = os.environ.get(bus.SECRET_ENV), bus_security.from_env()
        if mesh:
            return bus.open_view_session(self.connect, secret, settings)
        return bus.open_session(connect=[self.connect], secret=secret, settings=settings)

    def run(self) -> int:
        """Until END (and the view's lingering) or the orchestrator is gone; the exit code."""
        import zenoh

        view, log = self.view, self.log
        self.session = session = self._open_session(view.mesh)
        token = watcher = signals = None
        completed = False
        try:
            signals = session.declare_subscriber(bus.signals_key(self.run_id), zenoh.handlers.FifoChannel(16384))
            watcher = session.liveliness().declare_subscriber(
                bus.orchestrator_alive_key(self.run_id), zenoh.handlers.FifoChannel(16)
            )
            view.prepare()
            if self.frames is not None and (unlinked := self.frames.wait_linked()):
                self.warn(f"no mesh link yet to {', '.join(unlinked)}: their first frames may be missing from the view")
            token = session.liveliness().declare_token(view.alive_key(self.run_id))
            view.start()
            buffer = RowBuffer(len(self.columns))
            last = time.monotonic()
            ended = gone = False
            while not ended and not gone:
                ended, empty = take_rows(signals, buffer)
                now = time.monotonic()
                due = buffer and (ended or now - last >= view.batch_s or len(buffer) >= MAX_BATCH_ROWS)
                view.step(buffer.take() if due else None)
                if due:
                    last = now
                gone = orchestrator_gone(watcher)
                if empty and not ended:
                    time.sleep(POLL_S)
            if buffer:  # the orchestrator went: what came still goes to the view
                view.step(buffer.take())
            if buffer.bad:
                log(f"ignored {buffer.bad} signal rows of an unexpected size (expected {buffer.size} bytes)")
            if self.frames is not None and (summary := self.frames.summary()):
                log(summary)
            view.finish(ended)
            if ended and not gone and (line := view.linger()):
                log(line)
                while not orchestrator_gone(watcher):
                    view.step(None)
                    time.sleep(LINGER_POLL_S)
            completed = True
        except Stop:
            completed = True
        finally:
            for declared in (token, watcher, signals, self.frames):
                if declared is not None:
                    try:
                        declared.undeclare()
                    except Exception:
                        pass
            session.close()
            view.close(completed)
        return 0


def main(view: type[View], argv: list[str] | None, prog: str, description: str) -> int:
    """The observer process of ``view``: its command line, signals, niceness and setup file."""
    log = logger(view.name)
    parser = argparse.ArgumentParser(prog=prog, description=description)
    parser.add_argument("--connect", required=True, help="the orchestrator's Zenoh endpoint, e.g. tcp/127.0.0.1:7447")
    parser.add_argument("--run-id", required=True)
    parser.add_argument("--setup", required=True, help="the JSON file the orchestrator wrote")
    args = parser.parse_args(argv)
    signal.signal(signal.SIGTERM, raise_stop)
    signal.signal(signal.SIGINT, raise_stop)
    try:
        os.nice(NICENESS)  # a best-effort observer: on a busy machine the lockstep processes go first
    except (AttributeError, OSError):
        pass
    try:
        setup = json.loads(Path(args.setup).read_text())
    except (OSError, ValueError) as e:
        log(f"cannot read the setup file {args.setup}: {e}")
        return 2
    try:
        return Shell(view, args.connect, args.run_id, setup, log).run()
    except Stop:
        return 0
    except ViewError as e:  # the run goes on without the view
        log(str(e))
        return e.code
    except Exception as e:  # one line, not a traceback; the run goes on without the view
        log(f"stopped: {type(e).__name__}: {e}")
        return 1
