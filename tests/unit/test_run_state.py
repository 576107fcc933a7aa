"""RunState (orchestrator/run/state.py) changes only through its methods, each keeping one
invariant: the horizon never goes back but in a restart, a checkpoint is taken at the horizon with
every live member's state, a swap's new generation takes over only from a newer one, a restart
counts itself and goes back to the checkpoint whole."""

from __future__ import annotations

import numpy as np
import pytest

from orchestrator.config.load import load
from orchestrator.run.members import Member
from orchestrator.run.state import RunState

MS = 1_000_000


@pytest.fixture
def state(tmp_path) -> RunState:
    """A run of two counters at 10 ms, a swap of b due at 50 ms (step 5), a crash of a at 80 ms."""
    path = tmp_path / "two.yaml"
    path.write_text(
        "run: {name: two, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 10 ms}\n"
        "components: {a: {type: test.counter}, b: {type: test.counter}}\n"
        "events: [{at: 50 ms, swap: b}]\n"
        "faults: [{at: 80 ms, component: a, kind: crash}]\n"
    )
    state = RunState.of(load(path))
    for name in ("a", "b"):
        state.members[name] = member(state, name, 0)
    return state


def member(state: RunState, name: str, generation: int) -> Member:
    spec = state.config.components[name]
    m = Member(spec=spec, generation=generation, process=None, log_path=None, ratio=1)
    m.latest, m.tag = spec.outputs.start_vector(), 0
    m.out_dst, m.out_src = state.rows.placement(spec)
    return m


def test_the_horizon_only_grows(state):
    state.grant(40, 1.5)
    state.grant(40, 2.0)  # the same horizon, granted again later
    assert (state.horizon, state.horizon_at) == (40, 2.0)
    with pytest.raises(ValueError, match="goes back from 40 to 39"):
        state.grant(39, 3.0)
    assert (state.horizon, state.horizon_at) == (40, 2.0)


def test_a_stop_has_a_reason(state):
    assert state.stop_reason is None
    state.stop("stopped by request")
    assert state.stop_reason == "stopped by request"
    with pytest.raises(ValueError, match="a reason"):
        state.stop("")


def test_a_configured_swap_is_taken_once_at_its_step(state):
    assert state.next_event_step() == 5  # 50 ms at 10 ms steps
    state.rows.row = 4
    assert state.take_due_event() is None
    state.rows.row = 5
    event = state.take_due_event()
    assert (event.swap, event.at_ns) == ("b", 50 * MS)
    assert state.take_due_event() is None and state.next_event_step() is None


def test_a_checkpoint_is_taken_at_the_horizon_with_every_members_state(state):
    state.rows.row = 3
    with pytest.raises(ValueError, match="row 3, not at the horizon 0"):
        state.keep_checkpoint({"a": b"A", "b": b"B"})
    state.grant(3, 0.0)
    with pytest.raises(ValueError, match=r"states of \['a'\], not of \['a', 'b'\]"):
        state.keep_checkpoint({"a": b"A"})
    state.rows.values[:] = 7.0
    checkpoint = state.keep_checkpoint({"a": b"A", "b": b"B"})
    assert state.checkpoint is checkpoint and checkpoint.row == 3 and checkpoint.states == {"a": b"A", "b": b"B"}
    state.rows.values[:] = 8.0  # the run goes on; the checkpoint keeps what was
    assert np.all(checkpoint.values == 7.0)
    assert [e.swap for e in checkpoint.events] == ["b"]


def test_only_a_newer_joining_generation_takes_over(state):
    with pytest.raises(ValueError, match="no newer generation of 'b'"):
        state.take_over("b")
    state.joining["b"] = member(state, "b", 0)
    with pytest.raises(ValueError, match="no newer generation of 'b'"):
        state.take_over("b")
    old, new = state.members["b"], member(state, "b", 1)
    state.joining["b"] = new
    assert state.take_over("b") is old
    assert state.members["b"] is new and state.joining == {}
    assert state.drop_joining("b") is None


def test_a_restart_counts_itself_and_goes_back_to_the_checkpoint_whole(state):
    with pytest.raises(ValueError, match="without a checkpoint"):
        state.begin_restart("a")
    state.grant(2, 0.0)
    state.rows.row = 2
    state.members["a"].latest, state.members["a"].tag = np.array([2.0]), 2
    state.rows.take(state.members["a"])
    checkpoint = state.keep_checkpoint({"a": b"A", "b": b"B"})
    assert state.take_due_event() is None  # due at 5
    state.grant(9, 1.0)
    state.rows.row = 6
    assert state.take_due_event().swap == "b"  # taken after the checkpoint: the rerun takes it again
    state.joining["b"] = member(state, "b", 1)

    generations = state.begin_restart("a")  # a crashed at 80 ms, below the horizon 9
    assert generations == {"a": 1, "b": 1} and state.restarts == 1
    assert state.members == {} and state.joining == {} and state.pending_faults == ()
    with pytest.raises(ValueError, match=r"a restart of \[\] from a checkpoint of \['a', 'b'\]"):
        state.restart_from_checkpoint(5.0)

    for name in ("a", "b"):
        state.members[name] = member(state, name, generations[name])
    state.restart_from_checkpoint(5.0)
    a = state.members["a"]
    assert (state.rows.row, state.horizon, state.horizon_at) == (2, 2, 5.0)
    assert (a.tag, a.progress, a.progress_at, a.initialized) == (2, 2, 5.0, True)
    assert a.latest.tolist() == [2.0] and a.latest is not checkpoint.latest["a"][1]
    assert np.array_equal(state.rows.values, checkpoint.values)
    assert state.next_event_step() == 5
