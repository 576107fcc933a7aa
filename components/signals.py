"""Signals several component types exchange, each declared once: the orbit an orbit component
publishes and the dynamics reads, the state of a body the dynamics publishes and a controller
reads, and the joint torques going the other way.

The functions give the variables with the causality asked for, so producer and consumers agree
on name, shape, unit and start. A consumer may add ``notes`` (name -> text) on how it uses a
signal; they are appended to the description.
"""

from __future__ import annotations

from collections.abc import Mapping

from components.robots.model import joint_units
from components.robots.urdf import UrdfModel
from components.sdk import Variable

ORBIT = ("r_eci", "v_eci", "q_eci_lvlh", "w_lvlh")
BODY = ("position", "orientation", "twist", "q", "qd", "com", "momentum")
BODY_STATE = ("position", "orientation", "twist", "q", "qd")  # what a controller reads


def _noted(description: str, note: str | None) -> str:
    return f"{description}; {note}" if note else description


def orbit_signals(causality: str, notes: Mapping[str, str] | None = None) -> list[Variable]:
    """``r_eci``, ``v_eci``, ``q_eci_lvlh``, ``w_lvlh`` (SI, ECI = GCRF axes)."""
    notes = notes or {}
    return [
        Variable(name, causality, shape, unit, start, _noted(description, notes.get(name)))
        for name, shape, unit, start, description in (
            ("r_eci", (3,), "m", [0.0, 0.0, 0.0], "position of the reference orbit point, ECI (GCRF axes)"),
            ("v_eci", (3,), "m/s", [0.0, 0.0, 0.0], "velocity of the reference orbit point, ECI"),
            (
                "q_eci_lvlh",
                (4,),
                "1",
                [0.0, 0.0, 0.0, 1.0],
                "attitude of LVLH: quaternion [x, y, z, w] rotating LVLH vectors into ECI",
            ),
            ("w_lvlh", (3,), "rad/s", [0.0, 0.0, 0.0], "angular velocity of LVLH with respect to ECI, in ECI axes"),
        )
    ]


def body_signals(causality: str, model: UrdfModel, prefix: str = "", names: tuple[str, ...] = BODY) -> list[Variable]:
    """The state of a free-floating body of ``model`` (``names`` of ``BODY``, in BODY's order),
    named ``<prefix>.<name>`` (or ``<name>`` without a prefix). W: the dynamics' world frame."""
    n = len(model.movable_joints)
    q_unit, qd_unit, _ = joint_units(model)
    joints = ", ".join(model.movable_joints)
    signals = (
        ("position", (3,), "m", 0.0, "base link origin in W"),
        ("orientation", (4,), "1", [0.0, 0.0, 0.0, 1.0], "q_W_base [x, y, z, w], sign continuous from step to step"),
        ("twist", (6,), "m/s, rad/s", 0.0, "base origin linear velocity then angular velocity, W axes"),
        ("q", (n,), q_unit, 0.0, f"joint positions, URDF order: {joints}"),
        ("qd", (n,), qd_unit, 0.0, "joint rates, URDF order"),
        ("com", (3,), "m", 0.0, "body CoM in W"),
        (
            "momentum",
            (6,),
            "kg*m/s, kg*m^2/s",
            0.0,
            "linear momentum, then angular momentum about the body CoM, W axes",
        ),
    )
    return [
        Variable(_named(prefix, name), causality, shape, unit, start, description)
        for name, shape, unit, start, description in signals
        if name in names
    ]


def torque_signal(causality: str, model: UrdfModel, prefix: str = "", note: str | None = None) -> Variable:
    """``tau``: the efforts on every movable joint of ``model`` (locked ones included), URDF order."""
    n = len(model.movable_joints)
    description = f"joint torques (N m, N for prismatic), URDF order: {', '.join(model.movable_joints)}"
    return Variable(_named(prefix, "tau"), causality, (n,), joint_units(model)[2], 0.0, _noted(description, note))


def _named(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name
