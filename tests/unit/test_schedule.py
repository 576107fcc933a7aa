"""The lockstep rules (components/schedule.py) and the in-process loop built on them, no processes."""
from __future__ import annotations

import numpy as np
import pytest

from components.schedule import Route, initialization_order, next_due, routes, row_tag
from orchestrator.config import load
from orchestrator.inprocess import run_in_process


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
        found = {r.source: r for r in routes("b", inputs, connections, outputs, {"a": 1, "c": 2},
                                            ["a", "b", "c"], algorithm)}
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


@pytest.mark.parametrize("algorithm, second", [
    ("jacobi", lambda k: k * (k - 1) / 2),        # one-step delay: sum of 0..k-1
    ("gauss-seidel", lambda k: k * (k + 1) / 2),  # same-step value: sum of 1..k
])
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


def test_only_components_off_every_loop_batch_their_outputs():
    from components.schedule import feeds_back
    # the paper's demo: orbit -> dynamics <-> controller; a self-connection is not a loop
    demo = [("dynamics", "r_eci", "orbit", "r_eci"), ("dynamics", "tau", "controller", "tau"),
            ("controller", "q", "dynamics", "q"), ("orbit", "u", "orbit", "y")]
    assert [feeds_back(n, demo) for n in ("orbit", "dynamics", "controller")] == [False, True, True]
    ring = [("b", "u", "a", "y"), ("c", "u", "b", "y"), ("a", "u", "c", "y")]
    assert all(feeds_back(n, ring) for n in "abc")
    assert not any(feeds_back(n, ring[:2]) for n in "abc")


def test_dedicated_cpus_are_handed_out_from_the_top_keeping_one_for_the_rest():
    from orchestrator.supervisor import place
    two = place(["dynamics"], {0, 1})
    assert two.dedicated == {"dynamics": 1} and two.shared == {0} and two.unplaced == ()
    four = place(["a", "b"], {0, 1, 2, 3})
    assert four.dedicated == {"a": 3, "b": 2} and four.shared == {0, 1}
    # an orchestrator restricted to CPUs 2 and 5 hands out only those
    assert place(["a"], {2, 5}).dedicated == {"a": 5}
    alone = place(["a", "b"], {0})
    assert alone.dedicated == {} and alone.shared == {0} and alone.unplaced == ("a", "b")
    assert place(["a", "b"], {0, 1}).unplaced == ("b",)
    assert place([], {0, 1}).shared == {0, 1}


def test_fed_inputs_names_the_variables_a_route_feeds():
    from components.schedule import fed_inputs
    offsets = {"a": slice(0, 3), "b": slice(3, 4), "c": slice(4, 8)}
    route = Route("s", np.arange(2), np.array([4, 5, 6, 7, 3]), 1, 0)
    assert fed_inputs(route, offsets) == ["b", "c"]


def test_a_fault_overtaking_earlier_batches_keeps_the_progress_it_reported(tmp_path):
    """A fault message (progress raised to its step) can arrive before the batches sent ahead of it
    under another key; a late batch must not lower the progress, or the salvage of the rows up to
    the fault stops short (seen: a run recording rows 0-32 of 0-50)."""
    import shutil

    from components import bus
    from orchestrator.engine import Member, Run

    path = tmp_path / "one.yaml"
    path.write_text("run: {name: one, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 10 ms}\n"
                    "components: {bad: {type: test.counter}}\n")
    config = load(path)
    run = Run(config)
    member = run.members["bad"] = Member(spec=config.components["bad"], generation=0, process=None,
                                         log_path=None, ratio=1, progress=50)
    tags = np.arange(1, 33)
    batch = bus.encode_batch(0, tags, np.zeros((32, 2)), np.zeros((32, member.spec.outputs.size)))
    run._handle(("o", bus.batch_key(run.run_id, "bad"), batch), {})
    shutil.rmtree(run.log_dir)
    assert member.progress == 50 and [t for t, _ in member.received] == tags.tolist()
