import math

import pytest

from components.errors import ConfigError
from components.units import duration_ns, to_si


@pytest.mark.parametrize("text, unit, expected", [
    ("6778 km", "m", 6_778_000.0),
    ("51.64 deg", "rad", math.radians(51.64)),
    ("7.66 km/s", "m/s", 7660.0),
    ("0.5 N*m", "N*m", 0.5),
    ("2 g", "kg", 0.002),
    (42, "m", 42.0),
    ("1e-3 kg*m^2", "kg*m^2", 1e-3),
])
def test_to_si_converts_to_the_declared_dimension(text, unit, expected):
    assert to_si(text, unit, "k") == pytest.approx(expected, rel=1e-15)


@pytest.mark.parametrize("text, unit", [("5 kg", "m"), ("3 furlongs", "m"), ("fast", "m/s"), ("1 deg", "m"),
                                        (True, "m"), ([1], "m")])
def test_to_si_rejects_bad_units_naming_the_key(text, unit):
    with pytest.raises(ConfigError) as e:
        to_si(text, unit, "orbit.semi_major_axis")
    assert e.value.key == "orbit.semi_major_axis"


@pytest.mark.parametrize("text, ns", [("1 ms", 1_000_000), ("20s", 20_000_000_000), ("90 min", 5_400_000_000_000),
                                      ("0.1 s", 100_000_000), (0.02, 20_000_000), (15, 15_000_000_000),
                                      ("250 us", 250_000), ("1 d", 86_400_000_000_000)])
def test_duration_is_exact_integer_nanoseconds(text, ns):
    assert duration_ns(text, "run.step") == ns


def test_duration_rejects_a_non_time_unit():
    with pytest.raises(ConfigError, match="unknown time unit 'km'"):
        duration_ns("3 km", "run.duration")
