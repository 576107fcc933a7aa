"""The in-process harness and the SDK's layouts and state encoding."""

import numpy as np
import pytest

from components.errors import ConfigError
from components.sdk import ComponentOutputError, Layout, Variable
from components.testing.harness import Harness


def test_integrator_closed_form_through_the_harness():
    h = Harness("test.integrator", {"gain": 2.0, "x0": 1.0})
    assert h.initialize()["x"] == 1.0
    h.inputs["u"] = 3.0
    for _ in range(4):
        h.step(250_000_000)  # 0.25 s
    assert h.outputs["x"] == pytest.approx(1.0 + 2.0 * 3.0 * 1.0, rel=1e-15)
    assert h.t_ns == 1_000_000_000


def test_unconnected_input_holds_its_start_value():
    """u unconnected with a start value of 2.5 and x from x0 = 1: each 1 s step adds gain * 2.5. An
    input ignored, or fed 0 instead of its start value, would leave x at 1; x0 ignored, at 5 and 10."""
    from dataclasses import replace

    from components.testing.blocks import Integrator

    class StartsAt2_5(Integrator):
        @classmethod
        def declare(cls, params, run):
            return [replace(v, start=2.5) if v.name == "u" else v for v in super().declare(params, run)]

    h = Harness(StartsAt2_5, {"gain": 2.0, "x0": 1.0})
    assert h.inputs["u"] == 2.5
    assert h.step(1_000_000_000)["x"] == 6.0  # 1 + 2 * 2.5 * 1
    assert h.step(1_000_000_000)["x"] == 11.0  # held over the next step too


def test_state_round_trip_restarts_exactly():
    a = Harness("test.integrator", {"gain": 0.1})
    a.inputs["u"] = 0.7
    for _ in range(3):
        a.step(1_000_000)
    b = Harness("test.integrator", {"gain": 0.1}, t0_ns=a.t_ns)
    b.set_state(a.get_state())  # never initialized: a restore, as a swap or restart does
    b.inputs["u"] = 0.7
    assert a.step(1_000_000)["x"] == b.step(1_000_000)["x"]


def test_harness_reports_parameter_errors_with_the_key():
    with pytest.raises(ConfigError) as e:
        Harness("test.faulty", {"fault": "melt", "at_step": 1})
    assert e.value.key == "fault" and "melt" in str(e.value)


def test_layout_packs_and_checks_sizes():
    layout = Layout([Variable("a", "output", (), "1", 1.0, ""), Variable("b", "output", (3,), "m", 0.0, "")])
    assert layout.size == 4 and list(layout.start_vector()) == [1.0, 0.0, 0.0, 0.0]
    vector = np.zeros(4)
    layout.pack({"a": 5.0, "b": [1, 2, 3]}, vector)
    assert list(vector) == [5.0, 1.0, 2.0, 3.0]
    assert layout.unpack(vector)["b"].shape == (3,)
    with pytest.raises(ComponentOutputError, match="'b' has 2 values"):
        layout.pack({"a": 1.0, "b": [1, 2]}, vector)
    with pytest.raises(ComponentOutputError, match="'a' missing"):
        layout.pack({"b": [1, 2, 3]}, vector)
    # arrays (the fast path) of the right size in any shape, of the wrong size refused
    layout.pack({"a": np.array(7.0), "b": np.array([[4.0], [5.0], [6.0]])}, vector)
    assert list(vector) == [7.0, 4.0, 5.0, 6.0]
    with pytest.raises(ComponentOutputError, match="'b' has 4 values"):
        layout.pack({"a": 1.0, "b": np.zeros(4)}, vector)


def test_a_step_may_return_its_outputs_as_one_vector_in_declaration_order():
    layout = Layout([Variable("a", "output", (), "1", 1.0, ""), Variable("b", "output", (3,), "m", 0.0, "")])
    vector = np.zeros(4)
    layout.pack(np.array([5.0, 1.0, 2.0, 3.0]), vector)
    assert list(vector) == [5.0, 1.0, 2.0, 3.0] and layout.unpack(vector)["a"] == 5.0
    for wrong in (np.zeros(3), np.zeros(5), np.zeros((1, 4)), np.zeros(4, dtype=np.float32)):
        with pytest.raises(ComponentOutputError, match=r"expected 4 float64 values \(a, b, in that order\), got"):
            layout.pack(wrong, vector)
    assert list(vector) == [5.0, 1.0, 2.0, 3.0]  # a refused vector changes nothing
    rgb = Variable("rgb", "output", (2, 2, 3), "1", 0, "", frame=True, dtype="uint8")
    framed = Layout([Variable("a", "output", (), "1", 1.0, ""), rgb])
    with pytest.raises(ComponentOutputError, match="not with frame outputs \\(rgb\\)"):
        framed.pack(np.zeros(1), np.zeros(1))


@pytest.mark.filterwarnings("ignore:invalid value encountered in dot")  # as components.sdk's own filter
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_layout_names_the_first_variable_holding_a_non_finite_value(bad):
    layout = Layout(
        [
            Variable("a", "output", (), "1", 1.0, ""),
            Variable("b", "output", (3,), "m", 0.0, ""),
            Variable("c", "output", (2,), "m", 0.0, ""),
        ]
    )
    vector = np.array([1e308, -1e308, 1e308, 5e-324, 0.0, -0.0])  # finite, however large or small
    assert layout.first_non_finite(vector) is None
    for index, name in ((0, "a"), (3, "b"), (5, "c")):
        broken = vector.copy()
        broken[index] = bad
        assert layout.first_non_finite(broken) == name
    assert layout.first_non_finite(np.full(6, bad)) == "a"
