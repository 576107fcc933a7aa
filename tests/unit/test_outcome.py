"""The run's outcome (orchestrator/config/outcomes.py, orchestrator/run/outcome.py): declared as data on a component type, derived
from that component's own events, checked against what --expect names."""

from __future__ import annotations

import pytest

from components.controller.capture_component import CaptureComponent
from components.sdk import Component, Outcome
from orchestrator.config import outcomes
from orchestrator.run import outcome

CAPTURE = outcomes.Declared("controller", "controller.capture", CaptureComponent.outcomes)


def ev(kind: str, component: str = "controller", **fields) -> dict:
    return {"event": kind, "component": component, **fields}


def test_with_no_deciding_event_the_capture_is_undecided_by_the_end():
    events = [ev("start", component=None), ev("capture_approach", time=0.7, attempt=1)]
    assert outcome.derive(CAPTURE, events, 40.0) == ("undecided", "undecided: neither captured nor aborted by 40 s")


def test_the_capture_is_captured_at_the_controllers_event_time():
    events = [
        ev("capture_approach", time=0.7),
        ev("capture", component="dynamics", time=3.74),
        ev("capture_closed", time=3.74, attempt=1),
    ]
    assert outcome.derive(CAPTURE, events, 12.0) == ("captured", "captured at 3.74 s")


def test_an_abort_says_when_and_why():
    events = [ev("capture_aborted", time=0.7, attempts=0, reason="no window in a whole turn")]
    assert outcome.derive(CAPTURE, events, 40.0) == ("aborted", "capture aborted at 0.7 s: no window in a whole turn")


def test_the_last_deciding_event_wins_a_grasp_lost_after_capture_is_undecided_again():
    events = [ev("capture_closed", time=3.74), ev("capture_retreat", time=5.0, reason="the grasp opened")]
    assert outcome.derive(CAPTURE, events, 40.0)[0] == "undecided"
    events.append(ev("capture_closed", time=9.5))
    assert outcome.derive(CAPTURE, events, 40.0) == ("captured", "captured at 9.5 s")


def test_events_of_another_component_decide_nothing():
    """A shadow of the controller (another name) or the dynamics' own 'capture' does not decide."""
    events = [
        ev("capture_aborted", component="controller_shadow", time=1.0, reason="x"),
        ev("capture_closed", component="other", time=2.0),
    ]
    assert outcome.derive(CAPTURE, events, 5.0)[0] == "undecided"


def test_a_missing_field_reads_as_a_question_mark_not_a_crash():
    assert outcome.derive(CAPTURE, [ev("capture_aborted", time=1.5)], 5.0) == ("aborted", "capture aborted at 1.5 s: ?")


def test_a_restart_goes_back_to_the_checkpoints_outcome():
    tracker = outcome.Tracker(CAPTURE)
    saved = tracker.state()
    tracker.hear("capture_closed", {"component": "controller", "time": 3.0})
    assert tracker.result(4.0)[0] == "captured"
    tracker.restore(saved)
    assert tracker.result(4.0)[0] == "undecided"


class _Spec:
    def __init__(self, type_name, cls, shadow_of=None):
        self.type, self.cls, self.shadow_of = type_name, cls, shadow_of


class _Plain(Component):
    type_name = "test.plain"
    variables = ()


def test_the_first_declaring_component_not_a_shadow_gives_the_outcomes():
    specs = {
        "orbit": _Spec("test.plain", _Plain),
        "shadow": _Spec("controller.capture", CaptureComponent, "controller"),
        "controller": _Spec("controller.capture", CaptureComponent),
    }
    found = outcomes.declared(specs)
    assert found.component == "controller" and found.names == ["undecided", "captured", "aborted"]
    assert outcomes.expect_problem(specs, "captured") is None
    assert outcomes.expect_problem(specs, "capturd") == (
        "'capturd' is not an outcome of controller (controller.capture); its outcomes: undecided, captured, aborted"
    )
    assert "no component of this run declares outcomes" in outcomes.expect_problem(
        {"orbit": specs["orbit"]}, "captured"
    )


def test_a_type_whose_outcomes_share_an_event_is_refused():
    with pytest.raises(TypeError, match="an event deciding one outcome at most"):

        class Twice(Component):
            type_name = "test.twice"
            variables = ()
            outcomes = (Outcome("a", "a"), Outcome("b", "b", ("e",)), Outcome("c", "c", ("e",)))


def test_run_expect_is_checked_against_the_declared_outcomes(tmp_path):
    """run.expect: an unknown outcome is a config error listing the declared ones."""
    from orchestrator.config.load import load
    from orchestrator.config.yaml_file import ConfigErrors
    from tests.conftest import ROOT

    config = ROOT / "configs" / "capture_tumbling_target.yaml"
    assert load(config, ["run.expect=aborted"]).expect == "aborted"
    with pytest.raises(ConfigErrors) as error:
        load(config, ["run.expect=detumbled"])
    assert any(
        "run.expect: 'detumbled' is not an outcome of controller (controller.capture); its outcomes: "
        "undecided, captured, aborted" in line
        for line in error.value.errors
    ), error.value.errors
