"""The environment models' parameters as data, for the components that own a model (the dynamics'
drag on links, orbit.numerical's drag on the orbit): one declaration of each, one check.

| record / parameter | keys | meaning |
|---|---|---|
| ``ATMOSPHERE`` | model, altitude, density, scale_height, f107, f107a, ap | the drag's atmosphere (:mod:`components.space.atmosphere`) |
"""

from __future__ import annotations

from collections.abc import Mapping

from components.errors import ConfigError
from components.schema import Float, Record, Str
from components.sdk import EPOCH_KEY, Parameter

EXPONENTIAL_LAYER = ("altitude", "density", "scale_height")
SPACE_WEATHER = ("f107", "f107a", "ap")
ATMOSPHERE_MODELS = {"exponential": EXPONENTIAL_LAYER, "nrlmsise00": SPACE_WEATHER, "msis21": SPACE_WEATHER}
ATMOSPHERE = Record(
    "Atmosphere",
    (
        Parameter(
            "model",
            Str(tuple(ATMOSPHERE_MODELS)),
            default="exponential",
            description="exponential: one layer (altitude, density, scale_height), or the 0-1000 km table "
            "without them; nrlmsise00: NRLMSISE-00 at the run's time (f107, f107a, ap); "
            "msis21: NRLMSIS 2.1, the same inputs (components/space/atmosphere.py)",
        ),
        Parameter(
            "altitude",
            Float("m", plausible=(0.0, 2e6)),
            default=None,
            description="exponential: reference altitude above the sphere of radius R_E (6378.137 km)",
        ),
        Parameter(
            "density",
            Float("kg/m^3", minimum=0.0, plausible=(0.0, 1.3)),
            default=None,
            description="exponential: density at that altitude",
        ),
        Parameter(
            "scale_height",
            Float("m", positive=True, plausible=(1e3, 5e5)),
            default=None,
            description="exponential: height over which the density falls by e",
        ),
        Parameter(
            "f107",
            Float(positive=True, maximum=1000.0, plausible=(60.0, 400.0)),
            default=None,
            description="nrlmsise00, msis21: F10.7 solar radio flux of the previous day, sfu (1e-22 W/m^2/Hz)",
        ),
        Parameter(
            "f107a",
            Float(positive=True, maximum=1000.0, plausible=(60.0, 400.0)),
            default=None,
            description="nrlmsise00, msis21: F10.7's 81-day average centred on the day, sfu",
        ),
        Parameter(
            "ap",
            Float(minimum=0.0, maximum=400.0),
            default=None,
            description="nrlmsise00, msis21: daily geomagnetic index Ap (daily-Ap mode; no 3-hour history)",
        ),
    ),
    description="the drag's atmosphere: an exponential (one layer or the table) or NRLMSISE-00 / NRLMSIS 2.1",
)


def exponential_layer(atmosphere: Mapping | None) -> tuple[float, float, float] | None:
    """One exponential layer's (altitude, density, scale_height) (m, kg/m^3, m) of a checked
    ``ATMOSPHERE``; None for the 0-1000 km table: no atmosphere, or ``model: exponential`` without
    a layer, or a model that is not exponential."""
    if atmosphere is None or atmosphere["model"] != "exponential" or atmosphere["altitude"] is None:
        return None
    return atmosphere["altitude"], atmosphere["density"], atmosphere["scale_height"]


def check_atmosphere(atmosphere: Mapping | None, epoch) -> None:
    """ConfigError naming the key: a model's own parameters, all of them, and no other's; NRLMSISE-00
    needs the run's epoch (its time of day and year)."""
    if atmosphere is None:
        return
    model = atmosphere["model"]
    own = ATMOSPHERE_MODELS[model]
    for key in {k for keys in ATMOSPHERE_MODELS.values() for k in keys} - set(own):
        if atmosphere[key] is not None:
            raise ConfigError(
                f"atmosphere.{key}",
                f"not a parameter of model {model} (its parameters: {', '.join(own)}), got {atmosphere[key]!r}",
            )
    given = [k for k in own if atmosphere[k] is not None]
    if model != "exponential" or given:
        missing = [k for k in own if atmosphere[k] is None]
        if missing:
            raise ConfigError(
                f"atmosphere.{missing[0]}",
                f"model {model} needs {', '.join(own)}"
                f"{'' if model != 'exponential' else ' (or none: the table)'}, "
                f"got no {', '.join(missing)}",
            )
    if model != "exponential" and epoch is None:
        raise ConfigError(EPOCH_KEY, f"atmosphere model {model} needs the run's epoch (expected run.epoch)")
