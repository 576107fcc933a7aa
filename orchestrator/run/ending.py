"""The run's end: every process stopped, the viewer, the recording and the bus closed, the end
event written; then what the terminal is told (the error, the profile, the summary) and the exit
code, which an outcome other than the expected one turns to 3."""

from __future__ import annotations

import shutil
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from components.constants import NS_PER_S
from orchestrator.config.specs import RunConfig
from orchestrator.hosts.run_bus import RunBus
from orchestrator.run import outcome, report, runs
from orchestrator.run.members import terminate_all
from orchestrator.run.recording import RecordingError
from orchestrator.run.state import RunState
from orchestrator.run.viewer_link import ViewerLink

if TYPE_CHECKING:
    import zenoh


class Run(Protocol):
    """What the end reads of the engine's Run (which imports this module); the parts made when its
    bus opened are None if it never did. ``ros2_line`` is written here."""

    config: RunConfig
    state: RunState
    run_id: str
    expect: str | None
    record_dir: Path | None
    log_dir: Path
    profile: bool
    progress: bool
    out: Any  # a text stream
    loop_s: float
    subscriptions: list
    session: zenoh.Session | None
    hosts: RunBus | None
    viewer_link: ViewerLink | None
    ros2_line: str | None

    @property
    def row(self) -> int: ...


def outcome_of(run: Run, code: int) -> tuple[str | None, str | None]:
    """The run's outcome (name, words); none for a failed run or one whose components declare none."""
    if code == 1 or run.state.outcome is None:
        return None, None
    return run.state.outcome.result(run.row * run.config.step_ns / NS_PER_S)


def clean_up(run: Run, code: int, message: str | None, run_start: float) -> tuple[int, str | None]:
    """Stop every process, close the recording and the bus; the exit code and error message,
    which a recording that cannot be closed changes."""
    if run.progress:
        print(file=run.out)
    if run.hosts is not None:
        run.hosts.close()  # joins from now on are told the run is over
    state, rows = run.state, run.state.rows
    terminate_all(list(state.members.values()) + list(state.joining.values()), 2.0 if code else 5.0, final=True)
    if run.viewer_link is not None:
        run.viewer_link.stop(state.stop_reason == "interrupted", run.out)
        if stream := run.viewer_link.ros2_stream():
            event, run.ros2_line = stream
            state.log("ros2_stream", **event)
    name, words = outcome_of(run, code)
    state.log(
        "end",
        step=rows.row,
        time=rows.row * run.config.step_ns / NS_PER_S,
        status="failed" if code == 1 else (state.stop_reason or "completed"),
        wall_s=round(time.perf_counter() - run_start, 3),
        **({"outcome": name, "outcome_text": words} if name else {}),
    )
    if rows.recording is not None:
        try:
            rows.recording.close()
        except RecordingError as failure:
            code, message = 1, message or str(failure)
    runs.unregister(run.run_id)
    run.subscriptions.clear()
    if run.session is not None:
        run.session.close()
    if run.hosts is not None:
        run.hosts.remove(join_files=run.record_dir is None)
    if code == 0 and run.record_dir is None:
        shutil.rmtree(run.log_dir, ignore_errors=True)
    return code, message


def tell(run: Run, code: int, message: str | None, run_start: float) -> int:
    """Print the error, the profile, the ROS 2 view's line and the summary; the exit code (3 for an
    outcome other than the expected one)."""
    out, config = run.out, run.config
    if message:
        print(report.error(message, run.state.members.values()), file=out)
    if run.profile:
        lines = report.profile(run.state.members.values(), run.row, config.step_ns, run.loop_s, config.algorithm)
        print("\n".join(lines), file=out)
    if run.ros2_line:
        print(run.ros2_line, file=out)
    # as events.jsonl's end line says it ("stopped by request" ends with exit code 0 too)
    status = "failed" if code == 1 else (run.state.stop_reason or ("completed" if code == 0 else "interrupted"))
    name, words = outcome_of(run, code)
    if code == 0 and run.expect is not None and name != run.expect:
        code = outcome.EXPECT_MISMATCH
        print(f"error: the run's outcome is {name}, not {run.expect} as expected (exit code {code})", file=out)
    summary = report.summary(
        config.name,
        status,
        run.row,
        config.steps,
        config.step_ns,
        time.perf_counter() - run_start,
        run.loop_s,
        run.state.restarts,
        run.record_dir,
        words,
    )
    print(summary, file=out, flush=True)
    return code
