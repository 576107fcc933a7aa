"""Changing the run's members under way: a swap, a checkpoint, a restart from it; and what leads to
them: a hung member, the restart policy (docs/design.md §5, §7).

The procedures act at a step boundary, where every component is (the horizon is held there), and
drive the run through its state (:mod:`.state`), the crew that starts and asks its members and
the listener that waits for their answers; the decisions are pure functions.
"""

from __future__ import annotations

import time

import numpy as np

from components import protocol
from components.constants import NS_PER_S
from components.units import duration_ns, duration_text
from orchestrator.config.connections import handover_problem, hands_over
from orchestrator.config.specs import ComponentSpec
from orchestrator.run import wiring, wording
from orchestrator.run.control import SwapFailed
from orchestrator.run.listener import Listener
from orchestrator.run.members import Crew, Member, RunFailure, at_fault, terminate, terminate_all
from orchestrator.run.state import Checkpoint, RunState


def next_checkpoint(last: Checkpoint | None, checkpoint_ns: int | None, step_ns: int) -> int | None:
    """The step of the next periodic checkpoint (run.checkpoint_every), or None."""
    if last is None or checkpoint_ns is None:
        return None
    every = checkpoint_ns // step_ns
    return (last.row // every + 1) * every


def may_restart(failure: RunFailure, checkpoint: Checkpoint | None, live: dict[str, Member]) -> bool:
    """A live member that died or hung, and asked to be restarted."""
    member = failure.member
    return (
        failure.lost
        and member is not None
        and member.spec.on_failure == "restart"
        and checkpoint is not None
        and member.name in live
    )


def hung(live: dict[str, Member], horizon: int, horizon_at: float, now: float, timeout: float) -> Member | None:
    """A member that has held every input of its next step for ``timeout`` seconds (since its own,
    its sources' last output or the last grant, the latest of them) without stepping."""
    for m in live.values():
        k = m.progress
        if k >= horizon:
            continue
        sources = [live[r.source] for r in m.routes]
        if any(s.progress < r.tag(k) for s, r in zip(sources, m.routes)):
            continue
        since = max([m.progress_at, horizon_at, *(s.progress_at for s in sources)])
        if now - since > timeout:
            return m
    return None


class Recovery:
    """The run's checkpoints and restarts, and its swaps, on ``run`` (its state) with ``crew`` and
    ``listener``. ``restartable``: a component may restart, so checkpoints are taken: at the
    start, every run.checkpoint_every, after a swap."""

    def __init__(self, run: RunState, crew: Crew, listener: Listener, out):
        self.run, self.crew, self.listener, self.out = run, crew, listener, out
        self.restartable = any(s.on_failure == "restart" for s in run.config.components.values())

    def next_checkpoint(self) -> int | None:
        return next_checkpoint(self.run.checkpoint, self.run.config.checkpoint_ns, self.run.config.step_ns)

    def at_boundary(self) -> None:
        """At a step boundary every component has reached: the config's swaps due there, then the
        periodic checkpoint if it is due."""
        run = self.run
        while (event := run.take_due_event()) is not None:
            try:
                self.swap(event.spec, planned=True)
            except SwapFailed as failure:  # a swap the config asks for is part of the experiment
                raise RunFailure(str(failure)) from None
        if run.rows.row == self.next_checkpoint():
            self.take_checkpoint()

    def take_checkpoint(self) -> None:
        """Every component's state at this step boundary, where they all are (docs/design.md §7)."""
        run = self.run
        live = list(run.members.values())
        self.crew.ask(live, protocol.GetState(), "get_state (checkpoint)", run.config.step_timeout_s)
        run.keep_checkpoint({m.name: m.answer().blob for m in live})
        run.log("checkpoint", step=run.rows.row, time=run.rows.row * run.config.step_ns / NS_PER_S)

    def may_restart(self, failure: RunFailure) -> bool:
        return may_restart(failure, self.run.checkpoint, self.run.members)

    def restart(self, failure: RunFailure) -> None:
        """Stop every component and start them all again, in new processes, from the last checkpoint;
        RunFailure after run.max_restarts."""
        run, crew, checkpoint, failed = self.run, self.crew, self.run.checkpoint, failure.member
        assert checkpoint is not None and failed is not None, "may_restart holds"
        config = run.config
        step_ns = config.step_ns
        if run.restarts >= config.max_restarts:
            raise RunFailure(
                f"{failure} (after {wording.count(run.restarts, 'restart')}: run.max_restarts)", failed
            ) from None
        began = time.perf_counter()
        if failed.process is not None and failed.process.poll() is None:
            failed.process.kill()  # hung: it would not answer terminate
        terminate_all([*run.members.values(), *run.joining.values()], timeout=2.0)
        generations = run.begin_restart(failed.name)
        run.log("fault", step=run.rows.row, component=failed.name, message=str(failure))
        print(
            f"warning: {failure}\nrestarting from step {checkpoint.row} (t = {checkpoint.row * step_ns / NS_PER_S:g} s; "
            f"restart {run.restarts} of at most {config.max_restarts})",
            file=self.out,
            flush=True,
        )
        self.listener.discard_stale()
        crew.start(checkpoint.specs, generations, run.members)
        for member in run.members.values():
            wiring.wire(crew, member, run.members, run.pending_faults, checkpoint.row)
        for member in run.members.values():
            member.control(protocol.SetState(checkpoint.states[member.name]))
        self.listener.wait({m: "set_state" for m in run.members}, config.step_timeout_s, "set_state (restart)")
        run.restart_from_checkpoint(time.monotonic())
        self.listener.sync(list(run.members.values()))
        for member in run.members.values():
            wiring.go(member, run.members, run.horizon)
        run.log(
            "restart",
            step=checkpoint.row,
            time=checkpoint.row * step_ns / NS_PER_S,
            component=failed.name,
            restart=run.restarts,
            wall_s=round(time.perf_counter() - began, 4),
        )

    def check_hung(self) -> None:
        """Fail with a member that hung (see :func:`hung`), after salvaging the rows it completes."""
        run = self.run
        timeout = run.config.step_timeout_s
        m = hung(run.members, run.horizon, run.horizon_at, time.monotonic(), timeout)
        if m is not None:
            m = at_fault(m)  # in a process group, the member whose step holds the others up
            k = m.progress
            self.listener.salvage(m, lost=True)
            raise RunFailure(
                f"component {m.name!r} did not answer step {k} within {timeout:g} s "
                f"(hung? raise run.step_timeout if it is just slow)",
                m,
                lost=True,
            )

    def swap(self, spec: ComponentSpec, planned: bool = False) -> int:
        """Replace a component at the current step boundary (docs/design.md §5); the new generation.

        Every component is at the boundary (the horizon is held there). The new generation is
        started and wired on the side. One of the same type, or of a type that takes its state
        (``Component.takes_state_of``: another engine of the same ``state_form``), takes over the
        old one's state, never initialized (initialize would re-anchor what the state already
        holds), and its outputs at this step are the old ones; one of another type is initialized
        there. Only then does it take
        over and its consumers are rewired to it. If it fails to get there, it is stopped and
        SwapFailed is raised: the old generation runs on. ``planned``: an event of the config
        (else the recorded config gains one, so that it replays the run).
        """
        run = self.run
        old, row = run.members[spec.name], run.rows.row
        same_type = spec.type == old.spec.type
        handed_over = hands_over(old.spec, spec.type, spec.cls)
        problem = handover_problem(old.spec, spec) if handed_over else None
        if problem:
            raise SwapFailed(problem)
        began = time.perf_counter()
        new = self._new_generation(spec, old, handed_over)
        self._take_over(old, new)
        parameters = spec.cls.schema.plain(spec.resolved)
        if run.rows.recording is not None:
            if not same_type:  # (a same-type swap goes on writing the table its type has, if any)
                run.rows.new_table(new)
            if not planned:
                self._record_event(new, parameters)
        run.log(
            "swap",
            component=spec.name,
            type=spec.type,
            parameters=parameters,
            generation=new.generation,
            step=row,
            time=row * run.config.step_ns / NS_PER_S,
            state_handed_over=handed_over,
            wall_s=round(time.perf_counter() - began, 4),
        )
        if self.restartable:
            self.take_checkpoint()  # a restart never goes back across a swap
        return new.generation

    def _new_generation(self, spec: ComponentSpec, old: Member, handed_over: bool) -> Member:
        """The new generation started and wired on the side, with the old one's state (``handed_over``)
        or initialized at this step; on a failure it is stopped and SwapFailed raised, unless the old
        generation is gone too."""
        run, crew, config = self.run, self.crew, self.run.config
        row = run.rows.row
        try:
            new = crew.start([spec], {spec.name: old.generation + 1}, run.joining)[0]
            joined = {**run.members, spec.name: new}
            wiring.wire(crew, new, joined, run.pending_faults, row)
            if handed_over:
                crew.ask([old], protocol.GetState(), "get_state", config.step_timeout_s)
                crew.ask([new], protocol.SetState(old.answer().blob), "set_state", config.step_timeout_s)
                outputs = old.latest
            else:
                outputs = wiring.initialize(crew, new, joined, row * config.step_ns)
        except RunFailure as failure:
            if old.process is not None and old.process.poll() is not None:
                raise  # the old generation is gone too: nothing to run on
            joining = run.drop_joining(spec.name)
            if joining is not None:
                terminate(joining, timeout=2.0)
            run.log("warning", message=f"swap of {spec.name} to {spec.type} failed: {failure}", step=row)
            raise SwapFailed(str(failure)) from None
        new.tag, new.latest, new.progress, new.initialized = row, np.array(outputs), row, True
        return new

    def _take_over(self, old: Member, new: Member) -> None:
        """The new generation in the old one's place: its row columns, the old process stopped, its
        consumers rewired to it; then both let go."""
        run, name = self.run, new.name
        run.rows.values[old.out_dst] = np.nan  # the old type's columns the new one lacks: NaN from here on
        run.rows.take(new)
        run.take_over(name)
        terminate(old)  # its late messages carry the old generation: ignored from here on
        consumers = [m for m in run.members.values() if m is not new and any(r.source == name for r in m.routes)]
        for consumer in consumers:
            wiring.rewire(consumer, run.members, run.config, name)
        self.listener.wait({m.name: "rewire" for m in consumers}, run.config.step_timeout_s, "rewire")
        self.listener.sync([new, *consumers])
        wiring.go(new, run.members, run.horizon)

    def _record_event(self, new: Member, parameters: dict) -> None:
        """A swap from the CLI becomes an event of the recorded config, so that it replays the run."""
        run = self.run
        assert run.rows.recording is not None, "only a recorded run keeps its config"
        resolved = run.config.resolved
        resolved["events"] = sorted(
            [
                *resolved["events"],
                {
                    "at": duration_text(run.rows.row * run.config.step_ns),
                    "swap": new.name,
                    "type": new.spec.type,
                    "parameters": parameters,
                },
            ],
            key=lambda e: duration_ns(e["at"], "at"),
        )
        run.rows.recording.write_config(resolved)
