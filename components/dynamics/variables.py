"""The dynamics types' inputs and outputs, from their validated parameters (their ``declare``):
per body its torques, state and per-link outputs, and with their switches its CoM frame, IMU,
sun sensor and magnetic field; the grasp's."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from components.dynamics.specs import load_models
from components.robots.urdf import UrdfModel
from components.sdk import RunSettings, Variable
from components.signals import body_signals, orbit_signals, torque_signal


def grasp_variables(grasp: Mapping[str, Any]) -> list[Variable]:
    """The grasp's input and outputs (``grasp.*``)."""
    c, t = grasp["chaser"], grasp["target"]
    return [
        Variable(
            "grasp.close",
            "input",
            (),
            "1",
            0.0,
            "close the grasp (>= 0.5) as soon as the errors are within tolerance; unconnected: never",
        ),
        Variable("grasp.p_ee_grasp", "output", (3,), "m", 0.0, "grasp frame origin in the end-effector frame E"),
        Variable("grasp.q_ee_grasp", "output", (4,), "1", [0.0, 0.0, 0.0, 1.0], "q_E_G [x, y, z, w], sign continuous"),
        Variable(
            "grasp.twist_ee_grasp",
            "output",
            (6,),
            "m/s, rad/s",
            0.0,
            "rate of p_ee_grasp seen in E, then G's angular velocity relative to E, E axes",
        ),
        Variable("grasp.closed", "output", (), "1", 0.0, "1 once the grasp has closed (the bodies are one assembly)"),
        Variable(
            "grasp.wrench",
            "output",
            (6,),
            "N, N*m",
            0.0,
            "wrench the end effector applies to the target: force, torque about the weld point, E axes "
            "(what a wrist force/torque sensor reads; 0 while open)",
        ),
        Variable("grasp.p_c_t", "output", (3,), "m", 0.0, f"{t}'s CoM relative to {c}'s CoM, in {c}'s base axes (F_c)"),
        Variable("grasp.q_c_t", "output", (4,), "1", [0.0, 0.0, 0.0, 1.0], f"q_Fc_Ft: {t}'s base attitude in {c}'s"),
        Variable("grasp.v_c_t", "output", (3,), "m/s", 0.0, "rate of p_c_t seen in F_c, F_c axes"),
        Variable("grasp.w_c_t", "output", (3,), "rad/s", 0.0, f"{t}'s angular velocity relative to {c}, F_c axes"),
    ]


def frame_variables(name: str) -> list[Variable]:
    """The body's CoM frame (the paper's F_c, F_t: origin at the CoM, base link axes) relative to LVLH."""
    return [
        Variable(
            f"{name}.p_lvlh_com",
            "output",
            (3,),
            "m",
            0.0,
            "CoM relative to the LVLH origin (the orbit point), LVLH axes",
        ),
        Variable(
            f"{name}.q_lvlh_body",
            "output",
            (4,),
            "1",
            [0.0, 0.0, 0.0, 1.0],
            "q_LVLH_base [x, y, z, w], sign continuous",
        ),
        Variable(
            f"{name}.v_lvlh_com", "output", (3,), "m/s", 0.0, "rate of p_lvlh_com seen in LVLH (rotating), LVLH axes"
        ),
        Variable(
            f"{name}.w_lvlh_body", "output", (3,), "rad/s", 0.0, "base angular velocity relative to LVLH, LVLH axes"
        ),
    ]


def imu_variables(name: str) -> list[Variable]:
    """What an IMU at the base link origin senses, true values (a sensor component adds noise)."""
    return [
        Variable(f"{name}.imu_rate", "output", (3,), "rad/s", 0.0, "base angular velocity (inertial), base axes"),
        Variable(
            f"{name}.specific_force",
            "output",
            (3,),
            "m/s^2",
            0.0,
            "non-gravitational acceleration of the base origin (acceleration minus gravity there), base axes",
        ),
    ]


def sun_variables(name: str) -> list[Variable]:
    """What a sun sensor at the base origin senses, true values (a sensor component adds noise)."""
    return [
        Variable(
            f"{name}.sun_body",
            "output",
            (3,),
            "1",
            [1.0, 0.0, 0.0],
            "unit vector from the base origin to the Sun, base axes (geometric, no light time)",
        ),
        Variable(
            f"{name}.sunlit",
            "output",
            (),
            "1",
            1.0,
            "illumination factor at the base origin: 1 full sun, 0 umbra, between in penumbra (eclipse model)",
        ),
    ]


def magnetic_variables(name: str, magnetorquers: bool) -> list[Variable]:
    """The field at a body's base origin and, with magnetorquers, their command and torque."""
    variables = [
        Variable(
            f"{name}.b_body",
            "output",
            (3,),
            "T",
            0.0,
            "the Earth's magnetic field at the base origin, base axes (with magnetic_field)",
        )
    ]
    if magnetorquers:
        variables += [
            Variable(
                f"{name}.dipole",
                "input",
                (3,),
                "A*m^2",
                0.0,
                "commanded magnetic dipole, base axes (saturated per axis at max_dipole)",
            ),
            Variable(
                f"{name}.mtb_torque",
                "output",
                (3,),
                "N*m",
                0.0,
                "the magnetorquers' torque m x B over the last step, base axes (held over the step in W axes)",
            ),
        ]
    return variables


def link_variables(name: str, model: UrdfModel, third_bodies: bool) -> list[Variable]:
    """The body's per-link outputs (``link_outputs: true``)."""
    m = len(model.links)
    link_names = ", ".join(model.link_names)
    variables = [
        Variable(
            f"{name}.gg_torque",
            "output",
            (3 * m,),
            "N*m",
            0.0,
            f"gravity-gradient torque per link about its CoM, W axes, links: {link_names} "
            "(this and the next four only with link_outputs: true)",
        ),
        Variable(f"{name}.tidal_force", "output", (3 * m,), "N", 0.0, "tidal force per link, W axes"),
        Variable(f"{name}.drag_force", "output", (3 * m,), "N", 0.0, "drag force per link, W axes"),
        Variable(
            f"{name}.srp_force",
            "output",
            (3 * m,),
            "N",
            0.0,
            "solar radiation pressure force per link at its CoM, W axes",
        ),
        Variable(
            f"{name}.srp_torque",
            "output",
            (3 * m,),
            "N*m",
            0.0,
            "solar radiation pressure torque per link about its CoM, W axes",
        ),
        Variable(f"{name}.link_position", "output", (3 * m,), "m", 0.0, "link frame origins in W"),
        Variable(
            f"{name}.link_orientation",
            "output",
            (4 * m,),
            "1",
            np.tile([0.0, 0.0, 0.0, 1.0], m),
            "q_W_link per link [x, y, z, w]",
        ),
    ]
    if third_bodies:
        variables.append(
            Variable(
                f"{name}.third_body_force",
                "output",
                (3 * m,),
                "N",
                0.0,
                "the third bodies' (Sun's, Moon's) tidal force per link at its CoM, W axes "
                "(with link_outputs and third_bodies)",
            )
        )
    return variables


def dynamics_variables(params: Mapping[str, Any], run: RunSettings) -> list[Variable]:
    """Every input and output of a dynamics type with these parameters."""
    lvlh = "used at initialize for frame: lvlh bodies"
    variables = orbit_signals(
        "input",
        notes={"r_eci": "the origin of W; all zero: no orbit, no environment", "q_eci_lvlh": lvlh, "w_lvlh": lvlh},
    )
    links = params.get("link_outputs", False)
    for name, model in load_models(params, run).items():
        variables += [torque_signal("input", model, name)] + body_signals("output", model, name)
        if links:
            variables += link_variables(name, model, bool(params.get("third_bodies")))
    for name in load_models(params, run):
        if params.get("frame_outputs", False):
            variables += frame_variables(name)
        if name in params.get("imu", ()):
            variables += imu_variables(name)
        if name in params.get("sun_sensor", ()):
            variables += sun_variables(name)
    if params.get("grasp"):
        variables += grasp_variables(params["grasp"])
    if params.get("magnetic_field"):
        for name in load_models(params, run):
            variables += magnetic_variables(name, name in (params.get("magnetorquers") or {}))
    return variables
