"""The control server (orchestrator/run/control.py) against a stand-in run: all it needs of a run is
the small Controlled interface."""

from __future__ import annotations

import json

from orchestrator.config.load import load
from orchestrator.run.control import ControlServer


class Query:
    """A Zenoh query as the server sees it."""

    def __init__(self, request: dict):
        self.key_expr, self.answer = "ctl", None
        self.payload = type("Payload", (), {"to_bytes": lambda _: json.dumps(request).encode()})()

    def reply(self, key, text: str) -> None:
        self.answer = json.loads(text)

    def drop(self) -> None:
        pass


class StandIn:
    def __init__(self, config):
        self.config, self.row, self.stopped, self.swapped = config, 4, None, []

    def specs(self):
        return dict(self.config.components)

    def status(self) -> dict:
        return {"step": self.row}

    def request_stop(self, reason: str) -> None:
        self.stopped = reason

    def swap(self, spec) -> int:
        self.swapped.append(spec)
        return 1


def test_a_swap_waits_for_the_components_own_step_boundary(tmp_path):
    path = tmp_path / "two.yaml"
    path.write_text(
        "run: {name: two, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 10 ms}\n"
        "components: {fast: {type: test.counter}, slow: {type: test.counter, step: 30 ms}}\n"
    )
    run = StandIn(load(path))
    server = ControlServer(run)
    swap, status, stop = Query({"op": "swap", "component": "slow"}), Query({"op": "status"}), Query({"op": "stop"})
    for query in (swap, status, stop):
        server.add(query)
    assert server.swap_boundary() == 6  # slow steps every 3 run steps; the run is at 4
    server.serve(quiescent=True)
    assert status.answer == {"ok": True, "step": 4} and stop.answer == {"ok": True}
    assert run.stopped == "stopped by request" and swap.answer is None and server.queries == [swap]
    run.row = 6
    server.serve(quiescent=False)  # not every component at the boundary yet
    assert swap.answer is None
    server.serve(quiescent=True)
    assert swap.answer == {"ok": True, "step": 6, "generation": 1} and server.swap_boundary() is None
    assert [s.name for s in run.swapped] == ["slow"] and run.swapped[0].step_ns == 30_000_000
    unknown = Query({"op": "swap", "component": "nope"})
    server.add(unknown)
    server.serve(quiescent=True)
    assert unknown.answer["ok"] is False and "components: fast, slow" in unknown.answer["error"]


def test_a_swap_naming_no_component_by_a_string_is_refused_not_fatal(tmp_path):
    """A request whose component is a list (or a number) is answered with an error; the run, which
    asks swap_boundary on every loop, is not ended by it."""
    path = tmp_path / "one.yaml"
    path.write_text(
        "run: {name: one, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 10 ms}\n"
        "components: {c: {type: test.counter}}\n"
    )
    run = StandIn(load(path))
    server = ControlServer(run)
    bad = [Query({"op": "swap", "component": ["c"]}), Query({"op": "swap", "component": 3})]
    for query in bad:
        server.add(query)
    assert server.swap_boundary() is None
    server.serve(quiescent=True)
    assert all(q.answer is not None and q.answer["ok"] is False for q in bad)
    assert run.swapped == []
