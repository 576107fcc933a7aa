import math

import pytest

from components.errors import ConfigError
from components.units import duration_ns, parse_quantity, parse_unit, to_si


@pytest.mark.parametrize(
    "text, unit, expected",
    [
        ("6778 km", "m", 6_778_000.0),
        ("51.64 deg", "rad", math.radians(51.64)),
        ("7.66 km/s", "m/s", 7660.0),
        ("0.5 N*m", "N*m", 0.5),
        ("2 g", "kg", 0.002),
        (42, "m", 42.0),
        ("1e-3 kg*m^2", "kg*m^2", 1e-3),
    ],
)
def test_to_si_converts_to_the_declared_dimension(text, unit, expected):
    assert to_si(text, unit, "k") == pytest.approx(expected, rel=1e-15)


@pytest.mark.parametrize(
    "text, unit", [("5 kg", "m"), ("3 furlongs", "m"), ("fast", "m/s"), ("1 deg", "m"), (True, "m"), ([1], "m")]
)
def test_to_si_rejects_bad_units_naming_the_key(text, unit):
    with pytest.raises(ConfigError) as e:
        to_si(text, unit, "orbit.semi_major_axis")
    assert e.value.key == "orbit.semi_major_axis"


@pytest.mark.parametrize(
    "text, ns",
    [
        ("1 ms", 1_000_000),
        ("20s", 20_000_000_000),
        ("90 min", 5_400_000_000_000),
        ("0.1 s", 100_000_000),
        (0.02, 20_000_000),
        (15, 15_000_000_000),
        ("250 us", 250_000),
        ("1 d", 86_400_000_000_000),
    ],
)
def test_duration_is_exact_integer_nanoseconds(text, ns):
    assert duration_ns(text, "run.step") == ns


def test_duration_rejects_a_non_time_unit():
    with pytest.raises(ConfigError, match="unknown time unit 'km'"):
        duration_ns("3 km", "run.duration")


@pytest.mark.parametrize(
    "value, expected",
    [
        ("0.1 rad/s", (0.1, "rad/s")),
        ("20s", (20.0, "s")),
        ("-3e2 kg*m^2", (-300.0, "kg*m^2")),
        ("3", (3.0, None)),
        (3, (3.0, None)),
        (2.5, (2.5, None)),
    ],
)
def test_parse_quantity_gives_the_number_as_written_and_its_unit(value, expected):
    assert parse_quantity(value, "k") == expected


@pytest.mark.parametrize(
    "value, words",
    [
        ("0 furlong", ["unknown unit 'furlong'", "expected symbols among", "km"]),
        ("fast", ["expected a number or a quantity like '0.1 rad/s', got 'fast'"]),
        (True, ["got True"]),
        ([1, "m"], ["got [1, 'm']"]),
        ("1e999 m", ["expected a finite number, got '1e999 m'"]),
        (math.nan, ["finite"]),
    ],
)
def test_parse_quantity_says_what_it_expected_and_what_it_got(value, words):
    with pytest.raises(ConfigError) as e:
        parse_quantity(value, "dispersions.x")
    assert str(e.value).startswith("dispersions.x: ") and all(w in str(e.value) for w in words), str(e.value)


def test_parse_unit_gives_the_factor_and_dimension_or_names_what_it_reads():
    assert parse_unit("km/s") == (1e3, (1, 0, -1, 0))
    with pytest.raises(ValueError, match=r"unknown unit 'parsec' \(expected symbols among 1, m, km"):
        parse_unit("parsec")
