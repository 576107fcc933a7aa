"""The lockstep rules (components/schedule.py) and the in-process loop built on them, no processes."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from components.schedule import Route, first_step_at, initialization_order, next_due, routes, row_tag
from orchestrator.config.load import load
from orchestrator.run.inprocess import run_in_process


def route(ratio: int, ahead: int) -> Route:
    return Route("s", np.arange(1), np.arange(1), ratio, ahead)


def test_input_tags_jacobi_gauss_seidel_and_slower_sources():
    # Jacobi reads the values at t_k; Gauss-Seidel (source earlier in config order) those at t_(k+1)
    assert [route(1, 0).tag(k) for k in range(4)] == [0, 1, 2, 3]
    assert [route(1, 1).tag(k) for k in range(4)] == [1, 2, 3, 4]
    # a source stepping every 3 run steps holds its output until the next is due
    assert [route(3, 0).tag(k) for k in range(7)] == [0, 0, 0, 3, 3, 3, 6]
    assert [route(3, 1).tag(k) for k in range(7)] == [0, 0, 3, 3, 3, 6, 6]
    assert [row_tag(3, r) for r in range(7)] == [0, 0, 0, 3, 3, 3, 6]
    assert [next_due(3, k) for k in range(5)] == [0, 3, 3, 3, 6]


def test_routes_group_connections_by_source_and_mark_gauss_seidel_order():
    inputs = {"u": slice(0, 1), "v": slice(1, 4)}
    outputs = {"a": {"y": slice(0, 1), "w": slice(1, 4)}, "c": {"y": slice(0, 1)}}
    connections = [("b", "v", "a", "w"), ("b", "u", "c", "y"), ("x", "u", "a", "y")]
    for algorithm, ahead in (("jacobi", {"a": 0, "c": 0}), ("gauss-seidel", {"a": 1, "c": 0})):
        found = {
            r.source: r for r in routes("b", inputs, connections, outputs, {"a": 1, "c": 2}, ["a", "b", "c"], algorithm)
        }
        assert set(found) == {"a", "c"}
        assert found["a"].src.tolist() == [1, 2, 3] and found["a"].dst.tolist() == [1, 2, 3]
        assert found["c"].src.tolist() == [0] and found["c"].dst.tolist() == [0] and found["c"].ratio == 2
        assert {n: r.ahead for n, r in found.items()} == ahead


def test_initialization_order_puts_sources_first_and_breaks_cycles_in_config_order():
    connections = [("b", "u", "c", "y"), ("c", "u", "a", "y"), ("a", "u", "b", "y")]
    assert initialization_order(["a", "b", "c"], connections) == ["a", "c", "b"]
    assert initialization_order(["p", "q"], [("q", "u", "p", "y")]) == ["p", "q"]


def column(config, rows, name: str) -> np.ndarray:
    """The recorded column ``name`` of rows from run_in_process."""
    names = [c for spec in config.components.values() for v in spec.outputs.variables for c in v.columns(spec.name)]
    return rows[:, names.index(name)]


CHAIN = """
run: {{name: chain, epoch: 2022-09-18T12:00:00Z, duration: {steps} s, step: 1 s, algorithm: {algorithm}}}
components:
  source: {{type: test.constant, parameters: {{value: 1.0}}}}
  first: {{type: test.integrator}}
  second: {{type: test.integrator}}
connections: {{first.u: source.y, second.u: first.x}}
"""


@pytest.mark.parametrize(
    "algorithm, second",
    [
        ("jacobi", lambda k: k * (k - 1) / 2),  # one-step delay: sum of 0..k-1
        ("gauss-seidel", lambda k: k * (k + 1) / 2),  # same-step value: sum of 1..k
    ],
)
def test_in_process_loop_matches_the_closed_form_exactly(tmp_path, algorithm, second):
    path = tmp_path / "chain.yaml"
    path.write_text(CHAIN.format(steps=200, algorithm=algorithm))
    config = load(path)
    rows = run_in_process(config)
    k = np.arange(201)
    assert np.array_equal(column(config, rows, "first.x"), k.astype(float))
    assert np.array_equal(column(config, rows, "second.x"), second(k).astype(float))


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_in_process_loop_holds_a_slower_source(tmp_path, algorithm):
    path = tmp_path / "rates.yaml"
    path.write_text(f"""
run: {{name: rates, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 10 ms, algorithm: {algorithm}}}
components:
  slow: {{type: test.counter, step: 50 ms}}
  sum: {{type: test.integrator}}
connections: {{sum.u: slow.n}}
""")
    config = load(path)
    rows = run_in_process(config)
    k = np.arange(101)
    assert np.array_equal(column(config, rows, "slow.n"), np.floor(k / 5))
    j = np.arange(100)
    u = np.floor(j / 5) if algorithm == "jacobi" else np.floor((j + 1) / 5)
    assert np.allclose(column(config, rows, "sum.x"), np.concatenate([[0.0], np.cumsum(0.01 * u)]), rtol=0, atol=1e-12)


def test_consumers_off_every_loop_back_get_batches():
    from components.schedule import batch_consumers

    # the paper's demo: orbit -> dynamics <-> controller; a self-connection is not a loop
    demo = [
        ("dynamics", "r_eci", "orbit", "r_eci"),
        ("dynamics", "tau", "controller", "tau"),
        ("controller", "q", "dynamics", "q"),
        ("orbit", "u", "orbit", "y"),
    ]
    assert [batch_consumers(n, demo) for n in ("orbit", "dynamics", "controller")] == [["dynamics"], [], []]
    # with a shadow of the controller (fed by dynamics, feeding nothing): dynamics batches to it alone
    shadowed = demo + [("controller_shadow", "q", "dynamics", "q")]
    assert batch_consumers("dynamics", shadowed) == ["controller_shadow"]
    ring = [("b", "u", "a", "y"), ("c", "u", "b", "y"), ("a", "u", "c", "y")]
    assert not any(batch_consumers(n, ring) for n in "abc")
    assert [batch_consumers(n, ring[:2]) for n in "abc"] == [["b"], ["c"], []]


def test_dedicated_cpus_are_handed_out_from_the_top_keeping_one_for_the_rest():
    from orchestrator.run.supervisor import place

    two = place([["dynamics"]], {0, 1})
    assert two.dedicated == {"dynamics": 1} and two.shared == {0} and two.unplaced == ()
    four = place([["a"], ["b"]], {0, 1, 2, 3})
    assert four.dedicated == {"a": 3, "b": 2} and four.shared == {0, 1}
    # an orchestrator restricted to CPUs 2 and 5 hands out only those
    assert place([["a"]], {2, 5}).dedicated == {"a": 5}
    alone = place([["a"], ["b"]], {0})
    assert alone.dedicated == {} and alone.shared == {0} and alone.unplaced == ("a", "b")
    assert place([["a"], ["b"]], {0, 1}).unplaced == ("b",)
    assert place([], {0, 1}).shared == {0, 1}
    # a process group takes one CPU, for all its members
    group = place([["dynamics", "controller"], ["orbit"]], {0, 1, 2})
    assert group.dedicated == {"dynamics": 2, "controller": 2, "orbit": 1} and group.shared == {0}


def test_fed_inputs_names_the_variables_a_route_feeds():
    from components.schedule import fed_inputs

    offsets = {"a": slice(0, 3), "b": slice(3, 4), "c": slice(4, 8)}
    route = Route("s", np.arange(2), np.array([4, 5, 6, 7, 3]), 1, 0)
    assert fed_inputs(route, offsets) == ["b", "c"]


def test_inbox_entries_decode_to_typed_messages():
    from components import bus, protocol
    from orchestrator.run.messages import LIVELINESS, OUTPUTS, REPLY, Liveliness, Outputs, Report, decode

    rid = "demo-1a2b3c4d"
    batch = bus.encode_batch(
        3, np.array([4, 5]), np.array([[1.0, 2.0], [3.0, 4.0]]), np.array([[7.0, 6.0], [8.0, 5.0]])
    )
    outputs = decode(OUTPUTS, bus.batch_key(rid, "int"), batch)
    assert type(outputs) is Outputs and (outputs.name, outputs.generation) == ("int", 3)
    assert outputs.tags.tolist() == [4, 5] and outputs.outputs.tolist() == [[7.0, 6.0], [8.0, 5.0]]
    assert outputs.timings.tolist() == [[1.0, 2.0], [3.0, 4.0]]  # (compute, idle) of each step
    out_key = bus.reply_key(rid, "int", 12)
    reply = protocol.Reply("wire", {"n": 2}, b"\x01\x02")
    assert decode(REPLY, out_key, reply.encode()) == Report("int", 12, reply)
    fault = protocol.Fault("step", 9, "boom")
    assert decode(REPLY, out_key, fault.encode()) == Report("int", 12, fault)
    assert decode(LIVELINESS, bus.alive_key(rid, "int", 7), False) == Liveliness("int", 7, False)
    assert decode(LIVELINESS, bus.viewer_alive_key(rid), True) == Liveliness(bus.VIEWER, 0, True)
    assert decode(LIVELINESS, bus.run_key(rid, "alive", "int", "x"), True) is None  # not a process's token


@pytest.mark.parametrize(
    "kind, key, payload, reason",
    [
        ("o", "r/int", b"junk", "expected a B message"),
        ("o", "r/int", "tag 0", "tag 0: the outputs of a step are tagged 1 or later"),
        ("r", "c/int/x/out", "reply", "not a component's reply key"),
        ("r", "c/int/\u00b2/out", "reply", "not a component's reply key"),  # "²".isdigit(), but no number
        ("r", "out", "reply", "not a component's reply key"),
        ("r", "c/int/0/out", b"X" + bytes(8), "expected first byte one of"),
        ("r", "c/int/0/out", "fault without k", "expected a field 'k'"),
        ("r", "c/int/0/out", b"R\xff\xff\xff\xff{", "announces"),
    ],
)
def test_malformed_inbox_entries_are_refused_with_a_reason(kind, key, payload, reason):
    from components import bus, protocol
    from orchestrator.run.messages import decode

    text = b'{"op": "step", "error": "x"}'

    payload = {
        "tag 0": bus.encode_batch(0, np.array([0, 1]), np.zeros((2, 2)), np.zeros((2, 1))),
        "reply": protocol.Reply("wire").encode(),
        "fault without k": b"E" + struct.pack("<I", len(text)) + text,
    }.get(payload, payload)
    with pytest.raises(bus.Malformed, match=reason):
        decode(kind, bus.run_key("demo-1a2b3c4d", *key.split("/")), payload)


def test_a_fault_overtaking_earlier_batches_keeps_the_progress_it_reported(tmp_path):
    """A fault message (progress raised to its step) can arrive before the batches sent ahead of it
    under another key; a late batch must not lower the progress, or the salvage of the rows up to
    the fault stops short (seen: a run recording rows 0-32 of 0-50)."""
    from components import bus
    from orchestrator.run.members import Member
    from orchestrator.run.messages import OUTPUTS, decode

    path = tmp_path / "one.yaml"
    path.write_text(
        "run: {name: one, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 10 ms}\n"
        "components: {bad: {type: test.counter}}\n"
    )
    spec = load(path).components["bad"]
    member = Member(spec=spec, generation=0, process=None, log_path=None, ratio=1, progress=50)
    tags = np.arange(1, 33)
    batch = bus.encode_batch(0, tags, np.full((32, 2), 0.5), np.zeros((32, spec.outputs.size)))
    member.receive(decode(OUTPUTS, bus.batch_key("one-1a2b3c4d", "bad"), batch))
    assert member.progress == 50 and [t for t, _ in member.received] == tags.tolist()
    assert (member.steps, member.compute_s, member.idle_s) == (32, 16.0, 16.0)
    for stale in (
        bus.encode_batch(1, tags, np.zeros((32, 2)), np.zeros((32, 1))),  # another generation
        bus.encode_batch(0, tags, np.zeros((32, 2)), np.zeros((32, 2))),
    ):  # another size
        with pytest.raises(bus.Malformed):
            member.receive(decode(OUTPUTS, bus.batch_key("one-1a2b3c4d", "bad"), stale))
    assert member.steps == 32


def test_first_step_at_is_the_step_at_or_after_the_time():
    ms = 1_000_000
    assert [first_step_at(t, ms) for t in (0, 1, ms - 1, ms, ms + 1, 5500 * ms)] == [0, 1, 1, 1, 2, 5500]
