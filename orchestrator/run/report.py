"""What a run prints: the summary line at its end, the progress line while it runs, the profile,
the error it ended with."""

from __future__ import annotations

from pathlib import Path

from components.constants import NS_PER_S
from orchestrator.run import wording


def summary(
    name: str,
    status: str,
    row: int,
    steps: int,
    step_ns: int,
    wall_s: float,
    loop_s: float,
    restarts: int,
    record_dir: Path | None,
    outcome: str | None = None,
) -> str:
    """One line for the end of every run: how it ended, how far it got, how fast, where it went, and
    the outcome its components declare (``outcome``: its words), last so that a script's tail reads it."""
    sim_s = row * step_ns / NS_PER_S
    factor = sim_s / loop_s if loop_s > 0 else 0.0
    rate = f", real-time factor {factor:.{2 if factor < 100 else 0}f}" if factor else ""
    where = f"recording in {record_dir}" if record_dir is not None else "not recorded (no --record)"
    status += f" after {wording.count(restarts, 'restart')}" if restarts else ""
    return (
        f"run {name} {status}: {wording.count(row, 'step')} of {steps}, "
        f"{sim_s:g} s simulated; {wall_s:.1f} s wall ({loop_s:.1f} s stepping{rate}); {where}"
        + (f"; {outcome}" if outcome else "")
    )


def progress(row: int, step_ns: int, duration_ns: int, wall_s: float) -> str:
    sim = row * step_ns / NS_PER_S
    return (
        f"\r  t = {sim:9.3f} / {duration_ns / NS_PER_S:g} s   {row / wall_s:8.0f} steps/s   "
        f"real-time factor {sim / wall_s:6.2f}"
    )


def profile(members, row: int, step_ns: int, loop_s: float, algorithm: str) -> list[str]:
    """Lines: the stepping rate, then each member's compute and waiting time per step."""
    wall = loop_s
    lines = [
        f"profile: {row} steps in {wall:.3f} s wall ({row / wall if wall else 0:.0f} steps/s, "
        f"real-time factor {row * step_ns / NS_PER_S / wall if wall else 0:.2f}), {algorithm}",
        f"  {'component':<16}{'compute/step':>14}{'waiting/step':>14}{'busy':>8}",
    ]
    for m in members:
        steps = max(m.steps, 1)
        lines.append(
            f"  {m.name:<16}{m.compute_s / steps * 1e6:>11.1f} us{m.idle_s / steps * 1e6:>11.1f} us"
            f"{100 * m.compute_s / wall if wall else 0:>7.1f}%"
        )
    lines.append("  waiting: for inputs or the horizon, and the bus (a component's own compute not included)")
    return lines


def error(message: str, members) -> str:
    """The error a run ended with, and where the logs of its components are."""
    logs = ", ".join(dict.fromkeys(str(m.log_path) for m in members if m.log_path))  # a process group's once
    return f"error: {message}" + (f"\ncomponent logs: {logs}" if logs else "")
