"""The run's component processes: a live member, starting one (launch, wait for its liveliness
token, instantiate), asking it something, stopping it, and how their deaths and faults read. A
process group's members share one process (:class:`SharedProcess`)."""

from __future__ import annotations

import collections
import subprocess
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from components import bus, protocol
from components.constants import NS_PER_S
from components.group import read_mark
from components.schedule import Route
from orchestrator.config import groups
from orchestrator.config.specs import ComponentSpec, RunConfig
from orchestrator.run import supervisor
from orchestrator.run.messages import Outputs


class RunFailure(Exception):
    """The run cannot go on: a component crashed, hung, or produced a non-finite value.
    ``lost``: ``member`` died or hung (a restart may cure that), rather than reported a fault.
    ``silent_s``: for a member lost with its link, how long nothing had come from it."""

    def __init__(self, message: str, member: Member | None = None, lost: bool = False, silent_s: float | None = None):
        super().__init__(message)
        self.member = member
        self.lost = lost
        self.silent_s = silent_s


def _no_index() -> np.ndarray:
    return np.zeros(0, dtype=np.int64)


def _no_outputs() -> np.ndarray:
    return np.zeros(0)


@dataclass
class Member:
    """A live component: its spec, its process, its routes, and the outputs seen from it."""

    spec: ComponentSpec
    generation: int
    process: subprocess.Popen | None
    log_path: Path | None
    ratio: int  # its step in run steps
    command: Any = None  # zenoh.Publisher of its command key (set by Crew.launch)
    routes: list[Route] = field(default_factory=list)
    frame_routes: list = field(default_factory=list)  # schedule.FrameRoute: its frame inputs' sources
    # set by Crew.launch; empty until then
    out_dst: np.ndarray = field(default_factory=_no_index)  # where its outputs go in the recorded row ...
    out_src: np.ndarray = field(default_factory=_no_index)  # ... from these indices of its output vector
    tag: int = 0  # the tag of ``latest``: what the recorded rows hold now
    latest: np.ndarray = field(default_factory=_no_outputs)
    initialized: bool = False  # ``latest`` holds its outputs (not its start values)
    received: collections.deque = field(default_factory=collections.deque)  # (tag, outputs), not yet recorded
    progress: int = 0  # the highest tag it has published
    progress_at: float = 0.0  # wall time of its last output
    compute_s: float = 0.0
    idle_s: float = 0.0
    steps: int = 0
    reply: protocol.Reply | None = field(default=None, repr=False)  # its last
    host: str = ""  # where an external member joined from
    zid: str = ""  # the Zenoh id of its session, when linked to ours directly
    heard_at: float = 0.0  # wall time of its last message (heartbeats included)
    cut: bool = False  # Zenoh closed the link to it
    token_gone: bool = False  # its liveliness token went: all it sent before has come
    ended: bool = False  # asked to terminate
    shared: SharedProcess | None = field(default=None, repr=False)  # its process group's process

    @property
    def name(self) -> str:
        return self.spec.name

    def answer(self) -> protocol.Reply:
        """Its reply to the command last asked, which a completed ``Crew.ask`` holds."""
        assert self.reply is not None, f"{self.name} has not answered"
        return self.reply

    def control(self, message: protocol.Message) -> None:
        self.command.put(message.encode())

    def receive(self, message: Outputs) -> None:
        """Take a batch of its outputs (to be recorded); Malformed if not of this generation and size."""
        if message.generation != self.generation:
            raise bus.Malformed(f"generation {message.generation}, the live one is {self.generation}")
        tags, outputs = message.tags, message.outputs
        if outputs.shape[1] != self.spec.outputs.size:
            raise bus.Malformed(f"{outputs.shape[1]} outputs per step, {self.name} has {self.spec.outputs.size}")
        tags = tags.tolist()
        self.received.extend(zip(tags, outputs))
        # max: a fault message (which raises progress to its step) may overtake the batches
        # sent before it, which travel under another key
        self.progress, self.progress_at = max(self.progress, tags[-1]), time.monotonic()
        compute_s, idle_s = message.timings.sum(axis=0).tolist()  # Python floats: cheaper to add up
        self.compute_s += compute_s
        self.idle_s += idle_s
        self.steps += len(tags)


@dataclass
class SharedProcess:
    """The process of a process group: its members in the runner's ``--member`` order, and the
    file where it marks the member whose code runs (components.group)."""

    group: str
    members: list[Member]
    stepping: Path

    def running(self) -> Member | None:
        """The member whose code the process was in (its step, a command), if any."""
        index = read_mark(self.stepping)
        return self.members[index] if index is not None and index < len(self.members) else None


def at_fault(member: Member) -> Member:
    """Who a death or hang of ``member``'s process is due to: the member of its process group whose
    code was running, if one was (and is still live); else ``member``."""
    running = member.shared.running() if member.shared is not None else None
    return running if running is not None and not running.ended else member


Wait = Callable[[dict, float, str], None]


class Crew:
    """Starts, asks and stops members. ``wait(expect, timeout, what)`` is the engine's: it handles
    inbox messages until every member named in ``expect`` (name -> op) has answered, or raises
    RunFailure. ``place(spec)`` says where a member's outputs go in the recorded row."""

    def __init__(
        self,
        config: RunConfig,
        *,
        run_id: str,
        session,
        endpoint: str,
        secret: str,
        env: dict,
        log_dir: Path,
        placement: supervisor.Placement,
        out,
        place: Callable[[ComponentSpec], tuple[np.ndarray, np.ndarray]],
        wait: Wait,
        hosts,
        frames_dir: Path | None = None,
    ):
        self.config, self.run_id, self.session, self.endpoint = config, run_id, session, endpoint
        self.secret, self.env, self.log_dir, self.placement, self.out = secret, env, log_dir, placement, out
        self.place, self.wait, self.hosts = place, wait, hosts  # hosts: the run's bus (orchestrator.hosts.run_bus)
        self.frames_dir = frames_dir  # DIR/frames with --record DIR: the members' _frames are in it
        self.launches: dict[str, int] = {}  # process group -> its processes started so far (their log names)

    def launch(self, specs: list[ComponentSpec], generation: dict[str, int]) -> list[Member]:
        """Start the process of a member, or of a process group's members (or ask the user to,
        for an external one)."""
        spec = specs[0]  # a group's members agree on launch (config.groups)
        process = log_path = shared = None
        if spec.launch == "local":
            args = supervisor.runner_arguments(
                self.endpoint, self.run_id, [(s.name, generation[s.name]) for s in specs]
            )
            args += ["--orchestrator", str(self.session.zid())]
            if len(specs) > 1:
                group = spec.process
                assert group is not None, "members launched together are a process group's"
                launches = self.launches[group] = self.launches.get(group, -1) + 1
                log_path = self.log_dir / f"group.{group}.{launches}.log"
                shared = SharedProcess(group, [], log_path.with_suffix(".stepping"))
                shared.stepping.write_bytes(bytes(4))  # the process maps it: no member running yet
                args += ["--stepping", str(shared.stepping)]
            else:
                log_path = self.log_dir / f"{spec.name}.{generation[spec.name]}.log"
            listen = self.hosts.component_listen()
            cpu = self.placement.dedicated.get(spec.name)
            args += (["--listen", listen] if listen else []) + (["--cpu", str(cpu)] if cpu is not None else [])
            whole = cpu is not None and groups.dedicated_cpu(specs) == "process"  # its bus threads on its CPU too
            # a group's process holds its first member's certificate: any component's may do what one does
            process = supervisor.start_component(
                args,
                log_path,
                frozenset({cpu}) if whole and cpu is not None else self.placement.shared,
                {**self.env, **self.hosts.child_env(spec.name)},
            )
        members = []
        for spec in specs:
            member = Member(
                spec=spec,
                generation=generation[spec.name],
                process=process,
                log_path=log_path,
                ratio=spec.step_ns // self.config.step_ns,
                latest=spec.outputs.start_vector(),
                shared=shared,
            )
            if spec.launch != "local":
                self.hosts.invite(member)  # writes its join file and says where
            member.command = bus.publisher(self.session, bus.command_key(self.run_id, spec.name, member.generation))
            member.out_dst, member.out_src = self.place(spec)
            members.append(member)
        if shared is not None:
            shared.members = members
        return members

    def start(self, specs: list[ComponentSpec], generation: dict[str, int], into: dict[str, Member]) -> list[Member]:
        """Launch, wait for and instantiate members, registered in ``into`` (the engine's members,
        or those joining) as soon as launched, so that their messages are taken. The members of a
        process group started together share one process."""
        launched = {m.name: m for together in groups.processes(specs) for m in self.launch(together, generation)}
        started = [launched[spec.name] for spec in specs]  # in config order, as the run lists them
        into.update((m.name, m) for m in started)
        timeout = self.config.start_timeout_s
        expect = {m.name: "alive" for m in started}
        external = any(m.spec.launch == "external" for m in started)
        try:
            self.wait(expect, max(timeout, self.config.join_timeout_s) if external else timeout, "start-up")
        except RunFailure as failure:
            late = [n for n in expect if into[n].spec.launch == "external"]
            if late and "did not answer" in str(failure):
                raise RunFailure(self.hosts.late(late)) from None
            raise
        for member in started:
            member.control(instantiate_message(member.spec, self.config, self.frames_dir))
        self.wait({m.name: "instantiate" for m in started}, timeout, "instantiate")
        return started

    def ask(self, members: list[Member], message: protocol.Message, what: str, timeout: float) -> None:
        """Send each member the same command and wait for every answer (in ``member.reply``)."""
        for member in members:
            member.control(message)
        self.wait({m.name: message.OP for m in members}, timeout, what)


def instantiate_message(spec: ComponentSpec, config: RunConfig, frames_dir: Path | None = None) -> protocol.Instantiate:
    """The instantiate message: the type, its parameters and the run's settings (``frames``: the
    component's directory in ``frames_dir``, when the run records)."""
    run = replace(config.run_settings, frames=None if frames_dir is None else frames_dir / spec.name)
    return protocol.Instantiate(spec.type, bus.jsonable(spec.parameters), run.to_json())


def terminate(member: Member, timeout: float = 5.0, final: bool = False) -> None:
    """Ask a member to terminate and make sure its process is gone (killed after ``timeout``).
    ``final``: the run is over (an external member's `orchestrator join` then exits)."""
    member.ended = True
    member.control(protocol.Terminate(final))
    if member.shared is None or all(m.ended for m in member.shared.members):  # the last of a group ends its process
        supervisor.reap(member.process, timeout)
    member.command.undeclare()


def terminate_all(members: list[Member], timeout: float, final: bool = False) -> None:
    """:func:`terminate` each of ``members``, all asked at once and reaped within one ``timeout``:
    one that does not answer (its sending blocked on a cut link) holds up the others' end no longer."""
    for member in members:
        member.ended = True
        member.control(protocol.Terminate(final))
    deadline = time.monotonic() + timeout
    for member in members:
        if member.shared is None or all(m.ended for m in member.shared.members):
            supervisor.reap(member.process, max(deadline - time.monotonic(), 0.0))
        member.command.undeclare()


def exited(member: Member) -> str | None:
    """How the member's process ended, if it has; None while it runs (or is not ours)."""
    if member.process is not None and member.process.poll() is not None:
        return f"its process exited with code {member.process.returncode}"
    return None


def death(member: Member, how: str) -> str:
    where = f" on {member.host}" if member.host else ""
    if member.shared is not None:
        others = [m.name for m in member.shared.members if m is not member]
        where += f", in process group {member.shared.group!r} with {', '.join(others)},"
    return (
        f"component {member.name!r} ({member.spec.type}){where} died at step {member.progress}: {how}"
        f"{supervisor.last_words(member.log_path)}"
    )


def fault_message(member: Member, fault: protocol.Fault, step_ns: int) -> str:
    when = f"step {fault.k} (t = {fault.k * step_ns / NS_PER_S:g} s)"
    if fault.op == "nan":
        return f"component {member.name!r} produced a non-finite value in output {fault.error!r} at {when}"
    where = when if fault.op == "step" else fault.op
    return f"component {member.name!r} ({member.spec.type}) failed in {where}: {fault.error}"
