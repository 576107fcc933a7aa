"""The run's start, once its bus is open: the recording and the start event, every component
started, wired and initialized (row 0 recorded), the viewer, the first checkpoint; then the
components are let go."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

from orchestrator.config import shadows
from orchestrator.config.specs import Ros2Spec, RunConfig, ViewerSpec
from orchestrator.run import supervisor, wiring
from orchestrator.run.listener import Listener
from orchestrator.run.members import Crew
from orchestrator.run.recording import Recording
from orchestrator.run.recovery import Recovery
from orchestrator.run.state import RunState
from orchestrator.run.viewer_link import ViewerLink


class Run(Protocol):
    """What the start reads of the engine's Run (which imports this module); the parts made when
    its bus opened are None before that."""

    config: RunConfig
    state: RunState
    run_id: str
    record_dir: Path | None
    log_dir: Path
    child_env: dict[str, str]
    placement: supervisor.Placement
    viewer: ViewerSpec | None
    ros2: Ros2Spec | None
    out: Any  # a text stream
    crew: Crew | None
    listener: Listener | None
    recovery: Recovery | None
    viewer_link: ViewerLink | None


def start(run: Run, cpus: int) -> None:
    """Start, wire and initialize every component, the recording and the viewer; let them go.
    ``cpus``: how many the run may use."""
    state, crew, listener, recovery, viewer_link = run.state, run.crew, run.listener, run.recovery, run.viewer_link
    # made when the bus opened, which the engine does first
    assert crew is not None and listener is not None and recovery is not None and viewer_link is not None
    if run.record_dir is not None:
        state.rows.recording = Recording(
            run.record_dir, state.rows.columns, run.config.resolved, flush_s=run.config.record_flush_s
        )
    _log_start(run, cpus)
    _start_members(run, crew)
    _start_viewer(run, crew, listener, viewer_link)
    listener.sync(list(state.members.values()))
    if recovery.restartable:
        recovery.take_checkpoint()
    for member in state.members.values():
        wiring.go(member, state.members, state.horizon)


def _log_start(run: Run, cpus: int) -> None:
    """The start event, and the warnings the run starts with: the check's notes, CPUs to spare."""
    config, state, placement = run.config, run.state, run.placement
    state.log(
        "start",
        run_id=run.run_id,
        config=str(config.path.resolve()),
        steps=config.steps,
        step_ns=config.step_ns,
        algorithm=config.algorithm,
        components={n: s.type for n, s in config.components.items()},
        shadows={n: s.shadow_of for n, s in config.components.items() if s.shadow_of},
        cpus={**placement.dedicated, "shared": sorted(placement.shared)},
    )
    for note in config.notes:  # suspect physics the check found (orchestrator check shows them too)
        print(f"warning: {note}", file=run.out)
        state.log("warning", message=note, step=0)
    if placement.unplaced:
        message = (
            f"no CPU to spare for {', '.join(placement.unplaced)} (dedicated_cpu; "
            f"{cpus} CPU(s) available): they share the others'"
        )
        print(f"note: {message}", file=run.out)
        state.log("warning", message=message, step=0)


def _start_members(run: Run, crew: Crew) -> None:
    """Every component started, wired, and initialized in the shadows' order; row 0 recorded."""
    config, state, rows = run.config, run.state, run.state.rows
    crew.start(list(config.components.values()), {n: 0 for n in config.components}, state.members)
    for member in state.members.values():
        wiring.wire(crew, member, state.members, state.pending_faults, 0)
    for name in shadows.initialization_order(config.components, config.connections):
        member = state.members[name]
        member.latest = wiring.initialize(crew, member, state.members, 0)
        member.initialized = True
        rows.take(member)
    if rows.recording is not None:
        rows.recording.append(0, 0.0, rows.values)


def _start_viewer(run: Run, crew: Crew, listener: Listener, viewer_link: ViewerLink) -> None:
    """The viewer and the ROS 2 view, if any; row 0 published to them."""
    state, rows = run.state, run.state.rows
    rows.decimation = viewer_link.start(
        run.config,
        rows.columns,
        setup=run.log_dir / "viewer.json",
        endpoint=crew.endpoint,
        run_id=run.run_id,
        env=run.child_env,
        cpus=run.placement.shared,
        wait=listener.wait,
        frames_dir=run.record_dir / "frames" if run.record_dir else None,
        record_dir=run.record_dir,
    )
    if not rows.decimation:
        return
    if run.viewer is not None:
        state.log("viewer", mode=run.viewer.mode, rate_hz=run.viewer.rate_hz)
    if run.ros2 is not None:
        state.log(
            "ros2",
            transport=run.ros2.transport,
            endpoint=run.ros2.endpoint,
            domain_id=run.ros2.domain_id,
            rate_hz=run.ros2.rate_hz,
        )
    rows.signals = viewer_link.signals
    rows.publish()
