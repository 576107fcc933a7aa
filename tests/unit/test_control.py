"""The control server (orchestrator/run/control.py) against a stand-in run: all it needs of a run is
the small Controlled interface."""

from __future__ import annotations

import json
import signal
import struct

import pytest

from components import queries
from orchestrator.config.load import load
from orchestrator.run.control import ControlServer, StopRequested, raise_stop


class Query:
    """A Zenoh query as the server sees it: a request, or bytes that may not be one."""

    def __init__(self, request: queries.Message | bytes):
        self.key_expr, self.answer = "ctl", None
        payload = request if isinstance(request, bytes) else request.encode()
        self.payload = type("Payload", (), {"to_bytes": lambda _: payload})()

    def reply(self, key, payload: bytes) -> None:
        self.answer = queries.decode_control_answer(payload)

    def drop(self) -> None:
        pass


class StandIn:
    def __init__(self, config):
        self.config, self.row, self.stopped, self.swapped = config, 4, None, []

    def specs(self):
        return dict(self.config.components)

    def status(self) -> queries.RunStatus:
        return queries.RunStatus("two-1", "two", self.row, 100, self.row / 100, {})

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
    swap, status, stop = Query(queries.Swap("slow", None, [])), Query(queries.Status()), Query(queries.Stop())
    for query in (swap, status, stop):
        server.add(query)
    assert server.swap_boundary() == 6  # slow steps every 3 run steps; the run is at 4
    server.serve(quiescent=True)
    assert status.answer == queries.RunStatus("two-1", "two", 4, 100, 0.04, {}) and stop.answer == queries.Stopping()
    assert run.stopped == "stopped by request" and swap.answer is None and [q for q, _ in server.queries] == [swap]
    run.row = 6
    server.serve(quiescent=False)  # not every component at the boundary yet
    assert swap.answer is None
    server.serve(quiescent=True)
    assert swap.answer == queries.Swapped(step=6, generation=1) and server.swap_boundary() is None
    assert [s.name for s in run.swapped] == ["slow"] and run.swapped[0].step_ns == 30_000_000
    unknown = Query(queries.Swap("nope", None, []))
    server.add(unknown)
    server.serve(quiescent=True)
    assert type(unknown.answer) is queries.Refused and "components: fast, slow" in unknown.answer.error
    assert unknown.answer.usage


def test_a_swap_naming_no_component_by_a_string_is_refused_not_fatal(tmp_path):
    """A request whose component is a list (or a number), or that is no request, is answered with
    an error; the run, which asks swap_boundary on every loop, is not ended by it."""
    path = tmp_path / "one.yaml"
    path.write_text(
        "run: {name: one, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 10 ms}\n"
        "components: {c: {type: test.counter}}\n"
    )
    run = StandIn(load(path))
    server = ControlServer(run)
    bad = [Query(_framed({"op": "swap", "component": c, "type": None, "set": []})) for c in (["c"], 3)]
    bad += [Query(b'{"op": "status"}'), Query(_framed({"op": "explode"}))]
    for query in bad:
        server.add(query)
    assert server.swap_boundary() is None
    server.serve(quiescent=True)
    assert [type(q.answer) for q in bad] == [queries.Refused] * 4 and all(q.answer.usage for q in bad)
    assert "Swap.component: expected a string, got ['c']" in bad[0].answer.error
    assert "expected op one of status, stop, swap, got 'explode'" in bad[3].answer.error
    assert run.swapped == []


def _framed(body: dict) -> bytes:
    """A request framed as the codec frames one, whatever its body holds."""
    text = json.dumps(body).encode()
    return queries.REQUEST + struct.pack("<I", len(text)) + text


def test_a_sigterm_is_not_swallowed_by_code_that_catches_exceptions():
    """The run's SIGTERM handler raises where the main thread is; a broad ``except Exception`` there
    (as around a message decode) must let the stop through, as it does a Ctrl-C."""
    previous = signal.signal(signal.SIGTERM, raise_stop)
    swallowed = False
    try:
        with pytest.raises(StopRequested):
            try:
                signal.raise_signal(signal.SIGTERM)  # the handler runs before the next line
                swallowed = None
            except Exception:
                swallowed = True
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert swallowed is False
