"""What the controllers of one body share (``controller.computed_torque``, ``controller.joint_pd``):
the body's URDF read as ``dynamics.dart`` reads it, joint names checked against it, and the signals
of the loop.

Both types read one body of the dynamics: the body's position, orientation, twist, q and qd (every
non-fixed joint of the URDF, file order, locked ones included). Connect them as
``controller.q: dynamics.<body>.q`` etc. and ``dynamics.<body>.tau: controller.tau``. ``tau``
covers the same n joints; joints the controller does not drive get zero.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from components.errors import ConfigError
from components.robots.model import read_model
from components.sdk import RunSettings, Variable
from components.signals import BODY_STATE, body_signals, torque_signal


def read_body_urdf(params: Mapping[str, Any], run: RunSettings):
    """The parsed URDF of ``params['urdf']``, found as ``dynamics.dart`` finds it; ConfigError naming ``urdf``."""
    return read_model(params["urdf"], run.config_dir, "urdf", run.packages)


def check_names(names: list[str], key: str, allowed: list[str], what: str) -> list[str]:
    """``names`` (a list the schema checked) each in ``allowed``; ConfigError naming the key otherwise."""
    for name in names:
        if name not in allowed:
            raise ConfigError(key, f"{name!r} is not a {what} of the URDF (expected one of: {', '.join(allowed)})")
    return list(names)


def loop_signals(model) -> list[Variable]:
    """The body state read (inputs) and the joint torques published (output ``tau``)."""
    return body_signals("input", model, names=BODY_STATE) + [
        torque_signal("output", model, note="zero on joints not driven")
    ]
