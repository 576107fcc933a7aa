"""The lockstep master of a run: starts the components, wires them to each other, grants steps,
records, and stops the run on the first fault (or, for a component with ``on_failure: restart``
that dies or hangs, sends the whole run back to its last checkpoint).

The orchestrator is off the per-step path. Components exchange their outputs directly (see
:mod:`components.bus`) and each steps ``k`` as soon as it holds the inputs tagged for ``k`` and
``k`` lies below the *horizon* the orchestrator grants (rules: :mod:`components.schedule`). The
orchestrator receives every output, assembles the recorded rows, and checks for deaths
(liveliness) and hangs (a component that holds its inputs but does not step within
``run.step_timeout``). Control (swap, stop, events) and checkpoints happen at a step boundary:
the horizon is held there until every component has reached it. A component with no input from the loop (an
orbit) runs ahead up to the horizon, which hides its cost.

Components send the orchestrator their outputs in batches (see :mod:`components.process`).
Every message the orchestrator receives lands in one inbox queue (callbacks only enqueue) and the
main thread does all the work. Times are integer nanoseconds, step k covers [k*h, (k+1)*h).

This module is the run's life and what the control server sees; the parts it drives:
:mod:`.starting` (the start), :mod:`.loop` (the lockstep loop), :mod:`.ending` (the clean-up and
what is printed), :mod:`.state` (what the run holds), :mod:`.messages` (decoding the inbox),
:mod:`.listener` (applying it), :mod:`.members` (the processes), :mod:`.wiring` (who feeds whom),
:mod:`.pacing` (the horizon), :mod:`.rows` (the recorded row), :mod:`.recovery` (swap,
checkpoint, restart), :mod:`.viewer_link` and :mod:`.report`.
"""

from __future__ import annotations

import os
import secrets
import signal
import sys
import tempfile
import time
import traceback
import uuid
from pathlib import Path
from typing import TYPE_CHECKING

from components import bus, queries
from components.constants import NS_PER_S
from orchestrator.config import groups
from orchestrator.config.specs import ComponentSpec, Ros2Spec, RunConfig, ViewerSpec
from orchestrator.hosts.run_bus import BusUnavailable, RunBus
from orchestrator.run import ending, recovery, runs, starting, supervisor
from orchestrator.run.control import ControlServer, StopRequested, raise_stop
from orchestrator.run.listener import Listener
from orchestrator.run.loop import Loop
from orchestrator.run.members import Crew, RunFailure
from orchestrator.run.messages import subscribe
from orchestrator.run.recording import RecordingError
from orchestrator.run.state import RunState
from orchestrator.run.viewer_link import ViewerLink

if TYPE_CHECKING:
    import zenoh


class Run:
    """One execution of a validated config. ``execute()`` returns the exit code (0, 1, 130; 3: the
    run ended normally in another outcome than ``expect``, validated by the caller)."""

    def __init__(
        self,
        config: RunConfig,
        *,
        record: str | Path | None = None,
        profile: bool = False,
        progress: bool = False,
        out=sys.stderr,
        viewer: ViewerSpec | None = None,
        ros2: Ros2Spec | None = None,
        expect: str | None = None,
    ):
        self.config = config
        self.expect = expect or config.expect
        self.viewer = viewer or config.viewer
        self.ros2 = ros2 or config.ros2
        self.record_dir = Path(record) if record else None
        self.profile = profile
        self.progress = progress
        self.out = out
        self.run_id = f"{config.name}-{uuid.uuid4().hex[:8]}"
        self.secret = secrets.token_hex(32)  # the run's processes hold it; nothing else can join (§7)
        self.child_env = {**os.environ, bus.SECRET_ENV: self.secret}
        self.state = RunState.of(config)
        self.controls = ControlServer(self)
        # component logs: kept with the recording, else in a temporary directory removed after a clean run
        self.log_dir = (
            (self.record_dir / "logs") if self.record_dir else Path(tempfile.mkdtemp(prefix=f"zenorbit-{self.run_id}-"))
        )
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.loop_s = 0.0
        processes = groups.processes(list(config.components.values()))
        self.placement = supervisor.place(
            [[s.name for s in specs] for specs in processes if groups.dedicated_cpu(specs)], os.sched_getaffinity(0)
        )
        # set once the bus is open (_open_bus); None before, which the clean-up checks
        self.session: zenoh.Session | None = None
        self.hosts: RunBus | None = None
        self.viewer_link: ViewerLink | None = None
        self.listener: Listener | None = None
        self.crew: Crew | None = None
        self.recovery: recovery.Recovery | None = None
        self.ros2_line: str | None = None  # the ROS 2 view's summary, printed before the run's
        self.subscriptions: list = []

    # ---------------------------------------------------------------- what the control server sees

    @property
    def row(self) -> int:
        """The last recorded row = the step boundary reached."""
        return self.state.rows.row

    def specs(self) -> dict[str, ComponentSpec]:
        return {n: m.spec for n, m in self.state.members.items()}

    def status(self) -> queries.RunStatus:
        return queries.RunStatus(
            self.run_id,
            self.config.name,
            self.row,
            self.config.steps,
            self.row * self.config.step_ns / NS_PER_S,
            {n: queries.Running(m.spec.type, m.generation, m.spec.shadow_of) for n, m in self.state.members.items()},
        )

    def request_stop(self, reason: str) -> None:
        self.state.stop(reason)

    def swap(self, spec: ComponentSpec, planned: bool = False) -> int:
        assert self.recovery is not None, "a swap comes through the control server, which the open bus starts"
        return self.recovery.swap(spec, planned)

    # ---------------------------------------------------------------- the run's life

    def execute(self) -> int:
        """Run to the end (0), or until a failure (1) or an interruption (130); clean up in every case."""
        previous = {sig: signal.signal(sig, raise_stop) for sig in (signal.SIGTERM,)}
        # Ctrl-C is ours whatever was inherited: a run started with `&` from a script has SIGINT
        # ignored (POSIX), and would otherwise go on under a Ctrl-C or `kill -INT`
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, signal.default_int_handler)
        code, message = 0, None
        own_cpus = os.sched_getaffinity(0)
        run_start = time.perf_counter()
        try:
            supervisor.keep_to(self.placement.shared)  # this thread, and the bus threads it starts
            self._open_bus()
            starting.start(self, len(own_cpus))
            self._loop()
        except (RunFailure, RecordingError, BusUnavailable) as failure:
            code, message = 1, str(failure)
            # who and when, as numbers: the wall seconds since the start (and how long a lost
            # link had been silent) say how soon the run ended after a cut
            member, silent_s = getattr(failure, "member", None), getattr(failure, "silent_s", None)
            self.state.log(
                "fault",
                step=self.row,
                message=message,
                **({"component": member.name} if member is not None else {}),
                **({"silent_s": round(silent_s, 3)} if silent_s is not None else {}),
                wall_s=round(time.perf_counter() - run_start, 3),
            )
        except (KeyboardInterrupt, StopRequested):
            self.state.stop("interrupted")
            code = 130
        except Exception as error:  # a bug of ours: still a clean end, and no "completed" in events.jsonl
            traceback.print_exc(file=self.out)
            code, message = 1, f"internal error: {type(error).__name__}: {error}"
            self.state.log("fault", step=self.row, message=message)
        finally:
            # no second Ctrl-C/SIGTERM in the middle of the clean-up: it has bounded waits of its own
            for sig in (signal.SIGINT, signal.SIGTERM):
                signal.signal(sig, signal.SIG_IGN)
            code, message = ending.clean_up(self, code, message, run_start)
            signal.signal(signal.SIGINT, signal.default_int_handler)
            for sig, handler in previous.items():
                signal.signal(sig, handler)
            supervisor.keep_to(frozenset(own_cpus))
        return ending.tell(self, code, message, run_start)

    def _loop(self) -> None:
        assert self.listener is not None and self.recovery is not None, "the loop runs once the bus is open"
        loop = Loop(self.state, self.listener, self.recovery, self.controls, self.progress, self.out)
        try:
            loop.run()
        finally:
            self.loop_s = loop.seconds

    def _open_bus(self) -> None:
        """The orchestrator's Zenoh session, its subscriptions, and the run's entry for `ps`."""
        self.hosts = hosts = RunBus(self.config, self.run_id, self.secret, self.record_dir, runs.directory(), self.out)
        self.child_env.update(hosts.child_env(None))
        self.session = session = hosts.open()
        run_id = self.run_id
        self.subscriptions = subscribe(session, run_id, self.state.inbox.put)
        self.viewer_link = viewer_link = ViewerLink(self.viewer, session, run_id, ros2=self.ros2)
        self.listener = listener = Listener(self.state, self.controls, hosts, viewer_link, self.out)
        self.crew = crew = Crew(
            self.config,
            run_id=run_id,
            session=session,
            endpoint=hosts.local,
            secret=self.secret,
            env=self.child_env,
            log_dir=self.log_dir,
            placement=self.placement,
            out=self.out,
            place=self.state.rows.placement,
            wait=listener.wait,
            hosts=hosts,
            frames_dir=self.record_dir / "frames" if self.record_dir else None,
        )
        self.recovery = recovery.Recovery(self.state, crew, listener, self.out)
        runs.register(run_id, self.config.name, hosts.local, self.config.path, self.secret, hosts.settings("cli"))
