"""The Cartesian controller's gains, declared once for the computed-torque and the capture
controllers (both run the same task-space law: K_p and K_d per task axis, a null-space posture
term per arm joint, a damped pseudo-inverse near singularities)."""

from __future__ import annotations

import numpy as np

from components.errors import ConfigError
from components.schema import Float, OneOf, Vector
from components.sdk import Parameter

TASK_AXES = "x, y, z, rotation about x, y, z"


def gain(unit: str, plausible: tuple[float, float]) -> OneOf:
    """A non-negative gain in ``unit``: one number for all, or a list (one per axis or joint);
    ``plausible``: its range (SI)."""
    return OneOf((Float(unit, minimum=0.0, plausible=plausible), Vector(None, unit, minimum=0.0, plausible=plausible)))


# plausible: a stiffness whose natural frequency stays below 1 kHz (kp = w^2), a damping to match
STIFFNESS = (0.0, 4e7)
DAMPING = (0.0, 2e4)


def per_item(value: float | np.ndarray, n: int, key: str, each: str = "one per arm joint") -> np.ndarray:
    """One number for all n, or n numbers (``each`` says what they are)."""
    if np.ndim(value) == 0:
        return np.full(n, float(value))
    assert not isinstance(value, float)  # np.ndim is 0 for every float
    if len(value) != n:
        raise ConfigError(key, f"expected one number or {n} numbers ({each}), got {len(value)}")
    return np.array(value, dtype=np.float64)


CARTESIAN_GAINS = (
    Parameter(
        "kp",
        gain("1/s^2", STIFFNESS),
        default=100.0,
        description=f"Cartesian K_p, one for all six axes or per axis: {TASK_AXES} (W)",
    ),
    Parameter(
        "kd",
        gain("1/s", DAMPING),
        default=20.0,
        description=f"Cartesian K_d, one for all six axes or per axis: {TASK_AXES} (W)",
    ),
    Parameter(
        "null_kp",
        gain("1/s^2", STIFFNESS),
        default=4.0,
        description="null-space posture stiffness (towards the initial configuration), one or per arm joint",
    ),
    Parameter(
        "null_kd", gain("1/s", DAMPING), default=4.0, description="null-space joint damping, one or per arm joint"
    ),
    Parameter(
        "dls_threshold",
        Float(minimum=0.0),
        default=0.02,
        description="sigma_min(J_g) below which the pseudo-inverse is damped",
    ),
    Parameter("dls_damping", Float(minimum=0.0), default=0.05, description="damping at sigma_min = 0"),
)
"""kp, kd, null_kp, null_kd, dls_threshold, dls_damping: the parameters of the task-space law."""
