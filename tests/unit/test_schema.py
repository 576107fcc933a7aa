"""The typed declarations (components/schema.py): conversion to SI, errors naming the key, and the
tables, describe output and resolved config that come from the one declaration."""

from pathlib import Path

import numpy as np
import pytest

from components import registry
from components.errors import ConfigError
from components.schema import (
    Duration,
    Float,
    ListOf,
    MapOf,
    OneOf,
    Parameter,
    Problems,
    Record,
    Str,
    Tagged,
    UtcTime,
    Vector,
    markdown,
)

ROOT = Path(__file__).resolve().parents[2]

GAINS = Record(
    "Gains",
    (
        Parameter("p", Float("N*m/rad", minimum=0.0), description="proportional"),
        Parameter("d", Float("N*m*s/rad", minimum=0.0), default=0.0, description="derivative"),
    ),
)
MOVE = Tagged(
    "Move",
    "type",
    (
        Record("still", ()),
        Record(
            "line",
            (
                Parameter("length", Float("m", positive=True), description="how far"),
                Parameter("after", Duration(positive=False), default="1 s", description="when"),
            ),
        ),
    ),
)
ROBOT = Record(
    "robot",
    (
        Parameter("gains", MapOf(GAINS, "joint", min_items=1), description="per joint"),
        Parameter(
            "kp", OneOf((Float("1/s^2", minimum=0.0), Vector(6, "1/s^2"))), default=100.0, description="one or six"
        ),
        Parameter("joint", OneOf((Float("rad"), Float("m"))), default=0.0, description="revolute or prismatic"),
        Parameter("move", MOVE, default={"type": "still"}, description="what it does"),
        Parameter("path", ListOf(Vector(3, "m"), min_items=1), default=None, description="points"),
        Parameter("since", UtcTime(), default=None, description="a time"),
        Parameter("mode", Str(("a", "b")), default="a", description="a or b"),
    ),
)


def test_nested_values_convert_to_si_with_defaults_filled():
    out = ROBOT.convert(
        {
            "gains": {"elbow": {"p": "2 N*m/deg"}},
            "kp": [1, 2, 3, 4, 5, "6 Hz^2"],
            "joint": "5 cm",
            "move": {"type": "line", "length": "3 km"},
            "path": [["1 km", 0, 0]],
            "since": "2022-09-18T13:00:00+01:00",
        },
        "robot",
    )
    assert out["gains"] == {"elbow": {"p": pytest.approx(2 * 180 / np.pi), "d": 0.0}}
    assert out["kp"].tolist() == [1, 2, 3, 4, 5, 6] and out["joint"] == pytest.approx(0.05)
    assert out["move"] == {"type": "line", "length": 3000.0, "after": 1_000_000_000}
    assert out["path"][0].tolist() == [1000.0, 0.0, 0.0] and out["since"] == "2022-09-18T12:00:00Z"
    assert out["mode"] == "a"
    assert ROBOT.convert({"gains": {"e": {"p": 1}}}, "")["move"] == {"type": "still"}


@pytest.mark.parametrize(
    "raw, key, message",
    [
        ({"gains": {"elbow": {"p": 1, "i": 2}}}, "r.gains.elbow.i", "unknown key (known: p, d)"),
        ({"gains": {"elbow": {"d": 1}}}, "r.gains.elbow.p", "missing required key (proportional)"),
        ({"gains": {"elbow": {"p": -1}}}, "r.gains.elbow.p", "expected a quantity >= 0"),
        ({"gains": {"elbow": {"p": "1 m"}}}, "r.gains.elbow.p", "does not measure N*m/rad"),
        ({"gains": {}}, "r.gains", "expected at least 1 joint"),
        ({"gains": {"e": {"p": 1}}, "kp": [1, 2]}, "r.kp", "expected 6 values, got 2"),
        ({"gains": {"e": {"p": 1}}, "kp": {"x": 1}}, "r.kp", "expected float [1/s^2] or float[6] [1/s^2]"),
        ({"gains": {"e": {"p": 1}}, "joint": "1 kg"}, "r.joint", "does not measure rad"),
        ({"gains": {"e": {"p": 1}}, "move": {"type": "jump"}}, "r.move.type", "expected one of still, line"),
        ({"gains": {"e": {"p": 1}}, "move": {"type": "line"}}, "r.move.length", "missing required key"),
        ({"gains": {"e": {"p": 1}}, "move": {"type": "still", "length": 1}}, "r.move.length", "unknown key"),
        ({"gains": {"e": {"p": 1}}, "path": [[0, 0, 0], [0, "x", 0]]}, "r.path[1][1]", "expected a number with a unit"),
        ({"gains": {"e": {"p": 1}}, "since": "2022-09-18T12:00:00"}, "r.since", "give the time zone"),
        ({"gains": {"e": {"p": 1}}, "mode": "c"}, "r.mode", "expected one of a, b"),
    ],
)
def test_each_problem_names_its_key(raw, key, message):
    with pytest.raises(ConfigError) as error:
        ROBOT.convert(raw, "r")
    assert error.value.key == key and message in error.value.message, str(error.value)


def test_every_problem_of_a_record_is_reported_at_once():
    _, problems = ROBOT.resolve({"gains": {"a": {"p": -1}, "b": {}}, "mode": "c", "colour": 1})
    assert sorted(p.key for p in problems) == ["colour", "gains.a.p", "gains.b.p", "mode"]
    with pytest.raises(Problems) as error:
        ROBOT.convert({"gains": {"a": {"p": -1}, "b": {}}}, "")
    assert len(error.value.problems) == 2


def test_null_is_not_given_for_optional_fields_and_a_default_must_fit_its_kind():
    assert ROBOT.convert({"gains": {"e": {"p": 1}}, "mode": None, "path": None}, "")["mode"] == "a"
    with pytest.raises(ValueError, match="its default does not fit"):
        Parameter("x", Float("m"), default="3 kg")


def test_plain_writes_back_what_converts_to_the_same_values():
    """The resolved config.yaml is the declaration's plain form: reading it again gives the same values."""
    out = ROBOT.convert(
        {
            "gains": {"e": {"p": 1}},
            "kp": 3,
            "move": {"type": "line", "length": 2, "after": "1500 ms"},
            "path": [[1, 2, 3]],
        },
        "",
    )
    plain = ROBOT.plain(out)
    assert plain["move"] == {"type": "line", "length": 2.0, "after": "1500 ms"} and plain["path"] == [[1.0, 2.0, 3.0]]
    again = ROBOT.convert(plain, "")
    assert again["move"] == out["move"] and again["path"][0].tolist() == out["path"][0].tolist()


def test_tables_list_each_nested_record_once():
    text = markdown(ROBOT)
    assert text.count("| parameter | type | default | description |") == 4  # robot, Gains, still, line
    assert "| p | float [N*m/rad] | required | proportional |" in text
    assert "| after | duration | 1 s | when |" in text
    assert "| kp | float [1/s^2] or float[6] [1/s^2] | 100 | one or six |" in text


@pytest.mark.parametrize("type_name", [t for t in registry.TYPES])
def test_shipped_types_declare_every_parameter_typed_and_their_docstrings_carry_the_tables(type_name):
    cls = registry.load(type_name)
    for record in cls.schema.records():
        for p in record.fields:
            assert p.kind.text != "any", f"{type_name}: {record.name}.{p.name} is declared as any"
            assert p.description, f"{type_name}: {record.name}.{p.name} has no description"
    assert markdown(cls.schema) in cls.__doc__ if cls.parameters else "Parameters:" in cls.__doc__
    assert "| parameter | kind |" not in cls.__doc__, "a hand-written table is left"


def test_design_doc_holds_the_current_config_reference():
    from orchestrator.config.schema import CONFIG, DOCS_END, DOCS_START

    design = (ROOT / "docs" / "design.md").read_text()
    assert f"{DOCS_START}\n{markdown(CONFIG)}\n{DOCS_END}" in design, (
        "docs/design.md is out of date: run python -m orchestrator.config --docs"
    )
