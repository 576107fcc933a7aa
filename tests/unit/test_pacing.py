"""The step horizon (orchestrator/run/pacing.py): how far ahead, in which chunks, how fast in real time."""

from __future__ import annotations

import pytest

from orchestrator.run.pacing import RATE_SPAN_S, WINDOW, WINDOW_MAX, WINDOW_S, Rate, grant, window

MS = 1_000_000


def test_as_fast_as_possible_the_horizon_goes_a_window_ahead_in_quarter_window_chunks():
    assert WINDOW == 256
    # (row, horizon, limit) -> the new horizon; the loop looks again within 0.2 s in any case
    assert grant(0, 0, 15_000, 0, MS, 0.0) == (256, 0.2)
    assert grant(60, 256, 15_000, 0, MS, 0.0) == (None, 0.2)  # 60 more: less than a chunk (64)
    assert grant(64, 256, 15_000, 0, MS, 0.0) == (320, 0.2)  # a whole chunk
    assert grant(256, 100, 15_000, 0, MS, 0.0) == (512, 0.2)  # row and horizon are not interchangeable
    assert grant(900, 1000, 1010, 0, MS, 0.0) == (1010, 0.2)  # the limit is granted even in a small piece
    assert grant(900, 1000, 950, 0, MS, 0.0) == (None, 0.2)  # never taken back
    assert grant(1000, 1000, 1000, 0, MS, 0.0) == (None, 0.2)  # held at a boundary (event, swap, checkpoint)


def test_fast_steps_get_a_window_of_fifty_milliseconds_up_to_the_cap():
    assert WINDOW_S == 0.05 and WINDOW_MAX == 4096
    assert window(0.0) == window(1000.0) == WINDOW  # slow or not yet measured: the floor
    assert window(20_000.0) == 1000  # 20,000 rows a second: 1,000 steps are 50 ms
    assert window(1e6) == WINDOW_MAX
    # 20,000 rows a second: a window of 1,000 ahead of the row, granted in chunks of 250
    assert grant(0, 0, 15_000, 0, MS, 0.0, 20_000.0) == (1000, 0.2)
    assert grant(249, 1000, 15_000, 0, MS, 0.0, 20_000.0) == (None, 0.2)
    assert grant(250, 1000, 15_000, 0, MS, 0.0, 20_000.0) == (1250, 0.2)
    assert grant(250, 1000, 1100, 0, MS, 0.0, 20_000.0) == (1100, 0.2)  # never past the limit
    # a realtime run is paced by the wall clock whatever the rate
    assert grant(0, 0, 15_000, 1.0, MS, 0.0123, 20_000.0)[0] == 13


def test_the_rate_is_measured_over_at_least_its_span_and_restarts_after_a_rollback():
    rate = Rate(100, 10.0)
    assert rate.update(150, 10.0 + RATE_SPAN_S / 2) == 0.0  # too soon: not measured yet
    assert rate.update(500, 10.0 + 2 * RATE_SPAN_S) == pytest.approx(400 / (2 * RATE_SPAN_S))
    assert rate.update(520, 10.0 + 2.5 * RATE_SPAN_S) == pytest.approx(400 / (2 * RATE_SPAN_S))  # held
    assert rate.update(900, 10.0 + 4 * RATE_SPAN_S) == pytest.approx(400 / (2 * RATE_SPAN_S))  # 400 in 2 spans
    assert rate.update(300, 10.0 + 5 * RATE_SPAN_S) == pytest.approx(400 / (2 * RATE_SPAN_S))  # a restart to 300
    assert rate.update(400, 10.0 + 7 * RATE_SPAN_S) == pytest.approx(100 / (2 * RATE_SPAN_S))  # from 300


def test_realtime_lets_step_k_start_once_k_steps_of_wall_time_have_passed():
    # 1 ms steps at real time: 12.3 ms after the start, steps 0..12 may run; chunks of 5 steps (5 ms),
    # the next due 2.7 ms later, at 15 ms
    horizon, wake = grant(0, 0, 15_000, 1.0, MS, 0.0123)
    assert horizon == 13 and wake == pytest.approx(0.0027)
    # twice real time: 24.6 steps of 0.5 ms have passed; chunks of 10 steps (5 ms)
    horizon, wake = grant(0, 0, 15_000, 2.0, MS, 0.0123)
    assert horizon == 25 and wake == pytest.approx(0.0027)
    # a 10 ms step at real time: chunks of one step, due at the next step
    horizon, wake = grant(0, 0, 15_000, 1.0, 10 * MS, 0.0123)
    assert horizon == 2 and wake == pytest.approx(0.0077)
    # less than a chunk since the last grant, with enough granted ahead: not yet
    assert grant(0, 12, 15_000, 1.0, MS, 0.0123)[0] is None
    # ... but when the components are about to run out of it, yes
    assert grant(9, 12, 15_000, 1.0, MS, 0.0123)[0] == 13
    # wall time never grants beyond the window or the limit
    assert grant(0, 0, 15_000, 1.0, MS, 10.0)[0] == WINDOW
    assert grant(0, 0, 40, 1.0, MS, 10.0)[0] == 40


def test_realtime_wakes_at_least_every_half_millisecond_and_at_most_every_0_2_s():
    assert grant(0, 0, 15_000, 1.0, MS, 0.00499)[1] == 0.0005  # the chunk is due now: not a busy loop
    assert grant(0, 0, 15_000, 0.001, MS, 0.0)[1] == 0.2  # 1 s steps, chunks of one: 1 s away
