"""Plausible ranges: a value outside its declared range is a warning said in the unit people use
(issue 44); --strict and run.strict: true make warnings errors."""

from pathlib import Path

import pytest

from components.schema import Float, OneOf, Parameter, Record, Vector, implausible_values
from components.units import DEG
from orchestrator.config.load import load
from orchestrator.config.yaml_file import ConfigErrors
from tests.conftest import shipped_configs

ROOT = Path(__file__).resolve().parents[2]
CAPTURE = ROOT / "configs" / "capture_tumbling_target.yaml"
RATE_KEY = "components.dynamics.parameters.bodies.target.twist.rate"


def found_for(kind, value):
    with implausible_values() as found:
        kind.convert(value, "k")
    return [str(f) for f in found]


def test_a_bare_tumble_rate_meant_in_degrees_is_said_in_degrees():
    config = load(CAPTURE, [f"{RATE_KEY}=8"])
    assert config.notes == [
        f"{CAPTURE}: {RATE_KEY}: 8 (read as rad/s) = 458 deg/s, outside the plausible "
        f"0 to 60 deg/s; write '8 deg/s' for degrees"
    ]
    assert config.components["dynamics"].resolved["bodies"]["target"]["twist"]["rate"] == 8.0  # taken as SI


def test_a_value_with_its_unit_is_said_in_that_unit():
    config = load(CAPTURE, [f"{RATE_KEY}=500 deg/s"])
    assert config.notes == [f"{CAPTURE}: {RATE_KEY}: 500 deg/s, outside the plausible 0 to 60 deg/s"]
    config = load(CAPTURE, [f"{RATE_KEY}=2 rad/s"])
    assert config.notes == [f"{CAPTURE}: {RATE_KEY}: 2 rad/s = 115 deg/s, outside the plausible 0 to 60 deg/s"]


def test_strict_makes_the_warnings_errors():
    with pytest.raises(ConfigErrors) as e:
        load(CAPTURE, [f"{RATE_KEY}=8"], strict=True)
    assert e.value.errors == [
        f"{CAPTURE}: {RATE_KEY}: 8 (read as rad/s) = 458 deg/s, outside the plausible 0 to 60 deg/s; "
        f"write '8 deg/s' for degrees",
        f"{CAPTURE}: --strict makes the warning above an error",
    ]
    with pytest.raises(ConfigErrors) as e:
        load(CAPTURE, [f"{RATE_KEY}=8", "run.strict=true", "bus.lease=2 h"])
    assert len(e.value.errors) == 3, e.value.errors
    assert e.value.errors[0] == f"{CAPTURE}: bus.lease: 2 h, outside the plausible 100 ms to 1 h"
    assert e.value.errors[2] == f"{CAPTURE}: run.strict: true makes the 2 warnings above errors"
    assert load(CAPTURE, ["run.strict=true"]).notes == []


def test_the_range_edges_are_plausible_and_just_beyond_them_not():
    rate = Float("rad/s", minimum=0.0, plausible=(0.0, 60 * DEG))
    assert found_for(rate, "60 deg/s") == [] and found_for(rate, 0) == []
    assert found_for(rate, "60.1 deg/s") == ["k: 60.1 deg/s, outside the plausible 0 to 60 deg/s"]
    config = load(CAPTURE, [f"{RATE_KEY}=60 deg/s"])
    assert config.notes == []


def test_each_element_of_a_vector_is_checked_in_its_own_unit():
    twist = Vector(6, units=("m/s",) * 3 + ("rad/s",) * 3, plausible=((-100.0, 100.0),) * 3 + ((-1.0, 1.0),) * 3)
    assert found_for(twist, [0, 0, 150, 0, 0, -3]) == [
        "k[2]: 150 (read as m/s), outside the plausible -100 to 100 m/s",
        "k[5]: -3 (read as rad/s) = -172 deg/s, outside the plausible -57.3 to 57.3 deg/s; write '-3 deg/s' for degrees",
    ]


def test_times_and_lengths_are_said_by_magnitude_with_the_unit_meant():
    step = Float("s", plausible=(1e-6, 1.0))
    assert found_for(step, 10) == [
        "k: 10 (read as s), outside the plausible 1 us to 1 s; write '10 ms' for milliseconds"
    ]
    axis = Float("m", plausible=(6.3e6, 1e9))
    assert found_for(axis, 6778) == [
        "k: 6778 (read as m), outside the plausible 6300 to 1e+06 km; write '6778 km' for kilometres"
    ]
    noise = Float(plausible=(0.0, 64.0))
    assert found_for(noise, 300) == ["k: 300, outside the plausible 0 to 64"]


def test_an_option_that_fails_leaves_no_warning_behind():
    rec = Record("r", (Parameter("a", Float("m", plausible=(0.0, 1.0))), Parameter("b", Float("m"))))
    kind = OneOf((rec, Record("s", (Parameter("a", Float("m")),))))
    assert found_for(kind, {"a": 5}) == []  # rec took a = 5, then failed on the missing b


def test_a_default_outside_its_range_is_a_declaration_error():
    with pytest.raises(
        ValueError, match=r"its default is not plausible: mass: 0 .*outside the plausible 0\.001 to 10 kg"
    ):
        Parameter("mass", "float", unit="kg", default=0.0, plausible=(1e-3, 10.0))
    with pytest.raises(ValueError, match="plausible= goes with kind 'float' or 'vector'"):
        Parameter("n", "int", plausible=(0, 1))


@pytest.mark.parametrize("config", shipped_configs())
def test_every_shipped_config_is_clean_under_strict(config):
    assert load(config, full=True, strict=True).notes == []


def test_ranges_are_in_the_parameter_tables():
    from components.registry import load as load_type
    from components.schema import markdown

    text = markdown(load_type("dynamics.dart").schema)
    assert "| rate | float [rad/s]; plausible 0 to 60 deg/s | required | angular rate about the axis |" in text
