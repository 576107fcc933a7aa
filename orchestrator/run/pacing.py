"""The step horizon: how far the components may run ahead, and, for a realtime run, how fast.

The window is sized by time: at least ``WINDOW`` steps, more when steps are fast, so that the
components run ``WINDOW_S`` of wall time ahead of the recorded rows (a window of a few batches
stalls a fast run at every grant: the last component waits for its own rows to be recorded). It is
granted in chunks of a quarter window, so that a fast run sends few horizon messages and a
component always holds most of a window; a realtime run lets step k start once k steps' worth of
time has passed on the wall clock. Pacing decides how fast, never what: the same config gives the
same numbers with any window."""

from __future__ import annotations

from components.constants import NS_PER_S

WINDOW = 256  # steps a component may run ahead of the recorded rows, at least ...
WINDOW_S = 0.05  # ... or this long at the rate rows are recorded ...
WINDOW_MAX = 4096  # ... up to this many (what a consumer holds of a source running ahead)
RATE_SPAN_S = 0.02  # the rate is measured over at least this long
IDLE_WAKE_S = 0.2  # the loop looks again at least this often
REALTIME_CHUNK_S = 0.005


def window(rate: float) -> int:
    """Steps the components may run ahead when rows are recorded at ``rate`` a second."""
    return max(WINDOW, min(WINDOW_MAX, int(rate * WINDOW_S)))


def grant(
    row: int, horizon: int, limit: int, realtime: float, step_ns: int, elapsed_s: float, rate: float = 0.0
) -> tuple[int | None, float]:
    """(the new horizon, or None to keep ``horizon``; how long the loop may sleep before it must look
    again). ``row``: the last recorded row; ``limit``: the boundary the run must stop at next;
    ``realtime``: the wanted real-time factor (0: as fast as possible); ``elapsed_s``: wall time
    since the loop started (read only when ``realtime`` > 0); ``rate``: rows recorded a second
    lately (:class:`Rate`; 0 when not known yet)."""
    ahead = window(rate)
    target = min(limit, row + ahead)
    chunk = ahead // 4
    wake = IDLE_WAKE_S
    if realtime > 0:
        step_s = step_ns / NS_PER_S / realtime
        target = min(target, int(elapsed_s / step_s) + 1)
        chunk = max(1, int(REALTIME_CHUNK_S / step_s))
        wake = min(wake, max(step_s * chunk - (elapsed_s % (step_s * chunk)), 0.0005))
    if target > horizon and (target - horizon >= chunk or target == limit or horizon - row < chunk):
        return target, wake
    return None, wake


class Rate:
    """Rows recorded a second, over the last span of at least ``RATE_SPAN_S`` (wall time; it sizes
    the window, nothing else)."""

    def __init__(self, row: int, now: float):
        self.row, self.since, self.rate = row, now, 0.0

    def update(self, row: int, now: float) -> float:
        """The rate, measured anew once ``RATE_SPAN_S`` has passed since the last measure."""
        if row < self.row:  # a restart went back to a checkpoint
            self.row, self.since = row, now
        elif now - self.since >= RATE_SPAN_S:
            self.rate = (row - self.row) / (now - self.since)
            self.row, self.since = row, now
        return self.rate
