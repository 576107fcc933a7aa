"""The lockstep loop of a run (:mod:`.engine` starts and ends it): grant steps up to the next
boundary that needs everyone (the end, a config event, a swap, a checkpoint), apply the inbox,
assemble the recorded rows, watch for hangs and deaths, serve control at a boundary, and, for a
member that asks for it, restart the run from its last checkpoint."""

from __future__ import annotations

import queue
import time
from typing import TextIO

from components import protocol
from orchestrator.run import pacing, report
from orchestrator.run.control import ControlServer
from orchestrator.run.listener import Listener
from orchestrator.run.members import RunFailure
from orchestrator.run.recovery import Recovery
from orchestrator.run.state import RunState


class Loop:
    """``run()`` steps until the last row is in or a stop is asked for; ``seconds`` is the wall time
    it took (set however it ended). ``progress``: print the progress line to ``out``."""

    def __init__(
        self,
        state: RunState,
        listener: Listener,
        recovery: Recovery,
        controls: ControlServer,
        progress: bool,
        out: TextIO,
    ):
        self.config, self.state = state.config, state
        self.listener, self.recovery, self.controls = listener, recovery, controls
        self.progress, self.out = progress, out
        self.seconds = 0.0
        self.rate = pacing.Rate(0, 0.0)  # rows a second lately: the horizon's window

    def run(self) -> None:
        """Grant, record and watch until the last row is in or a stop is asked for."""
        steps = self.config.steps
        wall_start = time.perf_counter()
        try:
            while True:
                try:
                    self._step_until(steps, wall_start)
                    return
                except RunFailure as failure:
                    if not self.recovery.may_restart(failure):
                        raise
                    self.recovery.restart(failure)  # or, past run.max_restarts, fail
        finally:
            self.seconds = time.perf_counter() - wall_start

    def _step_until(self, steps: int, wall_start: float) -> None:
        last_progress = last_check = time.monotonic()
        self.rate = pacing.Rate(self.state.rows.row, time.perf_counter())
        expect: dict[str, str] = {}
        state, listener, rows = self.state, self.listener, self.state.rows
        while rows.row < steps and not state.stop_reason:
            if rows.row == state.horizon:  # everyone is at this boundary: control happens here
                self.recovery.at_boundary()
                self.controls.serve(quiescent=True)
            elif self.controls.queries:
                self.controls.serve(quiescent=False)
            wake = self._grant(wall_start)
            try:
                listener.handle(state.inbox.get(timeout=wake), expect)
                while True:
                    listener.handle(state.inbox.get_nowait(), expect)
            except queue.Empty:
                pass
            rows.advance(state.members, state.horizon)
            now = time.monotonic()
            if now - last_check > 0.2:
                last_check = now
                self.recovery.check_hung()
                listener.check_processes(list(state.members))
            if self.progress and now - last_progress > 0.5:
                last_progress = now
                print(
                    report.progress(
                        rows.row, self.config.step_ns, self.config.duration_ns, time.perf_counter() - wall_start
                    ),
                    end="",
                    file=self.out,
                    flush=True,
                )

    def _grant(self, wall_start: float) -> float:
        """Extend the horizon (pacing.grant) and tell everyone; how long the loop may sleep."""
        config, state = self.config, self.state
        limit = config.steps  # the step boundary the run must stop at next: the end, an event, a swap, a checkpoint
        for boundary in (state.next_event_step(), self.controls.swap_boundary(), self.recovery.next_checkpoint()):
            if boundary is not None:
                limit = min(limit, max(boundary, state.rows.row))
        realtime, now = config.realtime, time.perf_counter()
        horizon, wake = pacing.grant(
            state.rows.row,
            state.horizon,
            limit,
            realtime,
            config.step_ns,
            now - wall_start,
            self.rate.update(state.rows.row, now),
        )
        if horizon is not None:
            state.grant(horizon, time.monotonic())
            grant = protocol.Horizon(horizon).encode()
            for member in state.members.values():
                member.command.put(grant)
        return wake
