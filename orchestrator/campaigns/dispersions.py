"""Dispersions of a campaign: parsing ``{normal: [mean, sigma]}`` and the like, and drawing a case's value."""

from __future__ import annotations

import copy
import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from components.errors import ConfigError
from components.units import parse_quantity, parse_unit, to_si

DISTRIBUTIONS = {"normal": 2, "uniform": 2, "truncated_normal": 4, "choice": None, "direction": 0}
DISTRIBUTION_ARGS = {
    "normal": "[mean, sigma]",
    "uniform": "[low, high]",
    "truncated_normal": "[mean, sigma, low, high]",
    "choice": "[value, value, ...]",
    "direction": "uniform (a unit 3-vector, uniform on the sphere)",
}


# ---------------------------------------------------------------- distributions


@dataclass(frozen=True)
class Dispersion:
    """One dispersed key: ``kind`` over ``args`` (numbers in ``unit``; choice: the values as given)."""

    key: str
    kind: str
    args: tuple
    unit: str | None = None

    def draw(self, seed: int, sample: int) -> Any:
        """The value of draw ``sample``: a number (with its unit, as text) or a choice's value."""
        rng = np.random.Generator(
            np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(sample, zlib.crc32(self.key.encode()))))
        )
        if self.kind == "choice":
            return copy.deepcopy(self.args[int(rng.integers(len(self.args)))])
        if self.kind == "direction":  # three normal draws, normalized: uniform on the sphere
            v = rng.normal(size=3)
            return [float(x) for x in v / np.linalg.norm(v)]
        if self.kind == "normal":
            x = float(rng.normal(self.args[0], self.args[1]))
        elif self.kind == "uniform":
            x = float(rng.uniform(self.args[0], self.args[1]))
        else:  # truncated normal by the inverse CDF: one uniform draw, no rejection loop
            from scipy.special import ndtr, ndtri

            mean, sigma, low, high = self.args
            a, b = ndtr((low - mean) / sigma), ndtr((high - mean) / sigma)
            x = float(min(max(mean + sigma * ndtri(a + (b - a) * rng.random()), low), high))
        return x if self.unit is None else f"{x!r} {self.unit}"


def dispersion(key: str, spec: Any, where: str) -> Dispersion:
    """Parse ``{normal: [mean, sigma]}`` and the like; ConfigError naming ``where``."""
    if not isinstance(spec, dict) or len(spec) != 1:
        raise ConfigError(
            where,
            f"expected one distribution, e.g. {{normal: [0 rad/s, 0.001 rad/s]}} "
            f"({', '.join(DISTRIBUTIONS)}), got {spec!r}",
        )
    ((kind, args),) = spec.items()
    if kind not in DISTRIBUTIONS:
        raise ConfigError(f"{where}.{kind}", f"unknown distribution (known: {', '.join(DISTRIBUTIONS)})")
    here = f"{where}.{kind}"
    if kind == "direction":
        if args != "uniform":
            raise ConfigError(here, f"expected {DISTRIBUTION_ARGS[kind]}, got {args!r}")
        return Dispersion(key, kind, ())
    count = DISTRIBUTIONS[kind]
    if not isinstance(args, list) or (count is not None and len(args) != count) or not args:
        raise ConfigError(here, f"expected {DISTRIBUTION_ARGS[kind]}, got {args!r}")
    if kind == "choice":
        return Dispersion(key, kind, tuple(args))
    parsed = [parse_quantity(a, f"{here}[{i}]") for i, a in enumerate(args)]
    unit = next((u for _, u in parsed if u is not None), None)
    numbers = []
    for i, ((number, u), arg) in enumerate(zip(parsed, args)):
        if unit is None or u == unit:
            numbers.append(number)
            continue
        factor = parse_unit(unit)[0]
        if u is None:  # a bare number is SI
            numbers.append(number / factor)
            continue
        try:
            numbers.append(to_si(arg, unit, f"{here}[{i}]") / factor)
        except ConfigError:
            raise ConfigError(
                f"{here}[{i}]",
                f"unit {u!r} does not measure what {args[0]!r} does (the values of one distribution share a unit)",
            ) from None
    if kind in ("normal", "truncated_normal") and not numbers[1] > 0:
        raise ConfigError(f"{here}[1]", f"sigma must be positive, got {args[1]!r}")
    if kind == "uniform" and not numbers[0] < numbers[1]:
        raise ConfigError(here, f"low must be below high, got {args!r}")
    if kind == "truncated_normal" and not numbers[2] < numbers[3]:
        raise ConfigError(here, f"low must be below high, got {args[2]!r}, {args[3]!r}")
    return Dispersion(key, kind, tuple(numbers), unit)
