"""The step horizon: how far the components may run ahead, and, for a realtime run, how fast.

Granting is in chunks, so that a fast run sends few horizon messages; a realtime run lets step k
start once k steps' worth of time has passed on the wall clock."""

from __future__ import annotations

from components.constants import NS_PER_S

WINDOW = 256  # steps a component may run ahead of the recorded rows
IDLE_WAKE_S = 0.2  # the loop looks again at least this often
REALTIME_CHUNK_S = 0.005


def grant(
    row: int, horizon: int, limit: int, realtime: float, step_ns: int, elapsed_s: float
) -> tuple[int | None, float]:
    """(the new horizon, or None to keep ``horizon``; how long the loop may sleep before it must look
    again). ``row``: the last recorded row; ``limit``: the boundary the run must stop at next;
    ``realtime``: the wanted real-time factor (0: as fast as possible); ``elapsed_s``: wall time
    since the loop started (read only when ``realtime`` > 0)."""
    target = min(limit, row + WINDOW)
    chunk = WINDOW // 2
    wake = IDLE_WAKE_S
    if realtime > 0:
        step_s = step_ns / NS_PER_S / realtime
        target = min(target, int(elapsed_s / step_s) + 1)
        chunk = max(1, int(REALTIME_CHUNK_S / step_s))
        wake = min(wake, max(step_s * chunk - (elapsed_s % (step_s * chunk)), 0.0005))
    if target > horizon and (target - horizon >= chunk or target == limit or horizon - row < chunk):
        return target, wake
    return None, wake
