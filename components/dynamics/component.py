"""Free-floating URDF multibodies in orbit: types ``dynamics.dart`` and ``dynamics.pinocchio``
(thin wrappers of :class:`components.dynamics.world.OrbitalWorld`, one per engine).

The two types have the same parameters, inputs, outputs and state; only the engine that computes
the bodies' forward dynamics differs, so a swap from one to the other mid-run hands the state over
(``state_form``). ``dynamics.pinocchio`` has no contact solver: ``integrator: dart`` is refused.

``declare`` reads the URDFs with xml.etree only (joint and link counts); the engine loads at
instantiate. State (``get_state``): the world's (per body base pose and twist, joint positions,
rates, torques and limit stops; orbit inputs; the grasp's weld) and the last output quaternions
(their signs continue).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from operator import itemgetter
from typing import Any

import numpy as np

from components.constants import MU_EARTH, NS_PER_S
from components.dynamics import plots as dynamics_plots
from components.dynamics import ros as dynamics_ros
from components.dynamics.bodies import THIRD_BODIES
from components.dynamics.capture import OVERLOAD_ACTIONS
from components.dynamics.view import DynamicsView
from components.errors import ComponentError, ConfigError
from components.robots.model import JOINT_RATE, JOINT_VALUE, body_items, read_model
from components.robots.urdf import UrdfModel
from components.rotations import continuous
from components.schema import Float, Int, ListOf, MapOf, OneOf, Record, Str, Vector
from components.sdk import EPOCH_KEY, Component, Parameter, RunSettings, Variable
from components.signals import BODY as BODY_OUTPUTS
from components.signals import ORBIT as ORBIT_INPUTS
from components.signals import body_signals, orbit_signals, torque_signal
from components.space.eclipse import MODELS as ECLIPSE_MODELS
from components.space.ephemeris import moon_position_eci, sun_position_eci
from components.space.geomagnetic import BASILISK_DIPOLE
from components.space.geomagnetic import MODELS as MAGNETIC_MODELS
from components.space.parameters import ATMOSPHERE, check_atmosphere
from components.space.srp import SOLAR_FLUX
from components.units import DEG

ORBIT_VALUES = itemgetter(*ORBIT_INPUTS)  # inputs -> the orbit inputs' values, in set_orbit's order

NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
LINK_OUTPUTS = (
    "gg_torque",
    "tidal_force",
    "drag_force",
    "srp_force",
    "srp_torque",
    "link_position",
    "link_orientation",
    "third_body_force",
)
LAST = "last_output."  # state keys of the last output quaternions
MAGNETIC = "magnetic."  # state keys of the magnetic field and magnetorquers (components/dynamics/magnetic.py)

PER_LINK = "one number for the base link, or link name -> number"
# preflight: the rotation per (sub)step above which a step is too coarse (rk4's error in the
# attitude grows as its fifth power: 60 s at the orbit's rate, 0.07 rad, is right to 1e-6 deg;
# 1 h, 4 rad, ends 174 deg off), and the mean motion of the lowest orbit (at Earth's radius)
MAX_ROTATION_PER_STEP = 0.1
# plausible (a warning beyond): tumbling debris turns at up to a few tens of deg/s; a base's offset
# and velocity relative to the orbit point are those of proximity operations
TUMBLE = (0.0, 60 * DEG)
RATE = (-60 * DEG, 60 * DEG)
SPEED = (-100.0, 100.0)
OFFSET = (-1e5, 1e5)
ORBIT_RATE_MAX = float(np.sqrt(MU_EARTH / 6378137.0**3))
SPIN = Record(
    "Spin",
    (
        Parameter("rate", Float("rad/s", minimum=0.0, plausible=TUMBLE), description="angular rate about the axis"),
        Parameter("axis", Vector(3), description="the axis (any length but zero; normalized)"),
        Parameter(
            "axes",
            Str(("body", "frame")),
            description="axes of the axis: the body's own (turned by orientation) or the frame's",
        ),
        Parameter(
            "linear",
            Vector(3, "m/s", plausible=SPEED),
            default=[0.0, 0.0, 0.0],
            description="base origin linear velocity",
        ),
    ),
    description="a twist from parts: rate times axis, and a linear velocity",
)
FACET = Record(
    "Facet",
    (
        Parameter("area", Float("m^2", minimum=0.0, plausible=(0.0, 1e3)), description="the facet's area"),
        Parameter(
            "normal", Vector(3), description="its outward normal in the link frame (any length but zero; normalized)"
        ),
        Parameter(
            "centre", Vector(3, "m", plausible=(-100.0, 100.0)), description="its centre of pressure in the link frame"
        ),
        Parameter("specular", Float(minimum=0.0, maximum=1.0), description="specular reflectivity rho_s"),
        Parameter(
            "diffuse",
            Float(minimum=0.0, maximum=1.0),
            description="diffuse reflectivity rho_d (specular + diffuse <= 1; the rest is absorbed)",
        ),
    ),
    description="one flat facet for SRP (Basilisk facetSRPDynamicEffector's)",
)
BODY = Record(
    "Body",
    (
        Parameter(
            "urdf",
            Str(hint="a URDF file path"),
            description="URDF file, relative to the config file (else to the project root); its root link is the free base",
        ),
        Parameter(
            "frame",
            Str(("world", "lvlh")),
            default="world",
            description="frame of position, orientation and twist (lvlh: LVLH at t0, its rotation included)",
        ),
        Parameter(
            "position", Vector(3, "m", plausible=OFFSET), default=[0.0, 0.0, 0.0], description="base link origin"
        ),
        Parameter("orientation", Vector(4), default=[0.0, 0.0, 0.0, 1.0], description="base attitude [x, y, z, w]"),
        Parameter(
            "twist",
            OneOf((Vector(6, units=("m/s",) * 3 + ("rad/s",) * 3, plausible=(SPEED,) * 3 + (RATE,) * 3), SPIN)),
            default=[0.0] * 6,
            description="base origin linear velocity (m/s), then angular velocity (rad/s); or built from parts: "
            "{rate, axis, axes, linear} (a tumble rate about an axis, each sweepable)",
        ),
        Parameter(
            "q",
            MapOf(JOINT_VALUE, "joint"),
            default={},
            description="initial joint positions (rad, m for prismatic); joints not named start at 0",
        ),
        Parameter(
            "qd",
            MapOf(JOINT_RATE, "joint"),
            default={},
            description="initial joint rates (rad/s, m/s for prismatic); joints not named start at 0",
        ),
        Parameter(
            "locked_joints", ListOf(Str(), unique=True), default=[], description="joints welded at their initial q"
        ),
        Parameter(
            "drag_area",
            OneOf(
                (
                    Float("m^2", minimum=0.0, plausible=(0.0, 1e4)),
                    MapOf(Float("m^2", minimum=0.0, plausible=(0.0, 1e4)), "link"),
                )
            ),
            default={},
            description=f"area facing the flow: {PER_LINK}",
        ),
        Parameter(
            "drag_cd",
            OneOf(
                (Float(minimum=0.0, plausible=(0.0, 10.0)), MapOf(Float(minimum=0.0, plausible=(0.0, 10.0)), "link"))
            ),
            default=2.2,
            description=f"drag coefficient: {PER_LINK}",
        ),
        Parameter(
            "srp_area",
            OneOf(
                (
                    Float("m^2", minimum=0.0, plausible=(0.0, 1e4)),
                    MapOf(Float("m^2", minimum=0.0, plausible=(0.0, 1e4)), "link"),
                )
            ),
            default={},
            description=f"cannonball SRP: area facing the Sun, {PER_LINK}",
        ),
        Parameter(
            "srp_cr",
            OneOf((Float(minimum=0.0, plausible=(0.0, 2.0)), MapOf(Float(minimum=0.0, plausible=(0.0, 2.0)), "link"))),
            default=1.0,
            description=f"cannonball SRP: radiation pressure coefficient Cr (1: black, 1 + specular), {PER_LINK}",
        ),
        Parameter(
            "srp_facets",
            MapOf(ListOf(FACET), "link"),
            default={},
            description="faceted SRP: link name -> its flat facets (instead of or with a cannonball)",
        ),
    ),
    description="one free-floating URDF multibody (``bodies.<name>``)",
)


MAGNETIC_FIELD = Record(
    "MagneticField",
    (
        Parameter(
            "model",
            Str(MAGNETIC_MODELS),
            description="wmm: the World Magnetic Model 2025 (degree 12, 2025.0-2030.0); dipole: a centered tilted dipole",
        ),
        Parameter(
            "g10",
            Float("T", plausible=(-1e-4, 1e-4)),
            default=BASILISK_DIPOLE["g10"],
            description="dipole coefficient g10 (model: dipole; default Basilisk's Earth, -30926 nT)",
        ),
        Parameter(
            "g11",
            Float("T", plausible=(-1e-4, 1e-4)),
            default=BASILISK_DIPOLE["g11"],
            description="dipole coefficient g11 (model: dipole; default Basilisk's Earth, -2318 nT)",
        ),
        Parameter(
            "h11",
            Float("T", plausible=(-1e-4, 1e-4)),
            default=BASILISK_DIPOLE["h11"],
            description="dipole coefficient h11 (model: dipole; default Basilisk's Earth, 5817 nT)",
        ),
        Parameter(
            "radius",
            Float("m", positive=True, plausible=(6e6, 7e6)),
            default=BASILISK_DIPOLE["radius"],
            description="the dipole's reference radius (model: dipole; default 6371.2 km)",
        ),
    ),
    description="the Earth's magnetic field at each body (components/space/geomagnetic.py)",
)
MAGNETORQUERS = Record(
    "Magnetorquers",
    (
        Parameter(
            "max_dipole",
            OneOf(
                (
                    Float("A*m^2", positive=True, plausible=(1e-3, 1e3)),
                    Vector(3, "A*m^2", minimum=0.0, plausible=(0.0, 1e3)),
                )
            ),
            description="saturation of the commanded dipole per base axis: one for every axis or one per axis",
        ),
    ),
    description="three magnetorquers along a body's base axes (``magnetorquers.<body>``)",
)


TOLERANCE = Record(
    "Tolerance",
    (
        Parameter(
            "position",
            Float("m", minimum=0.0, plausible=(0.0, 1.0)),
            description="distance between the end effector's and the grasp frame's origins",
        ),
        Parameter(
            "orientation",
            Float("rad", minimum=0.0, plausible=(0.0, 45 * DEG)),
            description="angle between their attitudes",
        ),
        Parameter(
            "linear_velocity",
            Float("m/s", minimum=0.0, plausible=(0.0, 1.0)),
            description="target's velocity relative to the chaser at the end effector",
        ),
        Parameter(
            "angular_velocity",
            Float("rad/s", minimum=0.0, plausible=TUMBLE),
            description="target's angular velocity relative to the chaser",
        ),
    ),
    description="the grasp closes only within all four",
)
GRASP = Record(
    "Grasp",
    (
        Parameter("chaser", Str(), description="the body whose end effector grasps (the paper's chaser, F_c)"),
        Parameter("end_effector", Str(), description="link of the chaser: the end-effector frame E"),
        Parameter("target", Str(), description="the body grasped (the paper's target, F_t)"),
        Parameter("grasp_frame", Str(), description="link of the target: the grasp frame G that E must meet"),
        Parameter("tolerance", TOLERANCE, description="pose and velocity errors within which the grasp closes"),
        Parameter(
            "force_limit",
            Float("N", positive=True, plausible=(0.1, 1e6)),
            description="the largest force the fixture carries (the weld's force at the grasp point)",
        ),
        Parameter(
            "torque_limit",
            Float("N*m", positive=True, plausible=(0.01, 1e6)),
            description="the largest torque the fixture carries (about the grasp point)",
        ),
        Parameter(
            "on_overload",
            Str(OVERLOAD_ACTIONS),
            default="release",
            description="beyond a limit: release (the weld opens, momentum kept) or hold (stays closed); "
            "either way a grasp_overload event",
        ),
    ),
    description="a capture: E welds to G when grasp.close is set and the errors are within tolerance",
)
GRASP_OUTPUTS = ("p_ee_grasp", "q_ee_grasp", "twist_ee_grasp", "closed", "wrench", "p_c_t", "q_c_t", "v_c_t", "w_c_t")
FRAME_OUTPUTS = ("p_lvlh_com", "q_lvlh_body", "v_lvlh_com", "w_lvlh_body")
IMU_OUTPUTS = ("imu_rate", "specific_force")


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


def load_models(params: Mapping[str, Any], run: RunSettings) -> dict[str, UrdfModel]:
    """Parsed URDF of every body (xml.etree only); ConfigError naming ``bodies.<name>.urdf``."""
    return {
        name: read_model(body["urdf"], run.config_dir, f"bodies.{name}.urdf", run.packages)
        for name, body in body_items(params["bodies"])
    }


def initial_twist(body: Mapping[str, Any]) -> list[float]:
    """A body's ``twist`` as the 6-vector (linear, angular) in its ``frame``: given so, or from its
    parts ``{rate, axis, axes, linear}`` (the axis normalized, in the body's own axes turned into
    the frame by ``orientation`` for ``axes: body``)."""
    twist = body["twist"]
    if not isinstance(twist, Mapping):
        return list(twist)
    axis = np.asarray(twist["axis"], dtype=float)
    norm = float(np.linalg.norm(axis))
    if not norm > 0.0:
        raise ConfigError("twist.axis", f"expected a direction (a vector that is not zero), got {list(twist['axis'])}")
    axis = axis / norm
    if twist["axes"] == "body":
        from components.rotations import quat_to_matrix

        axis = quat_to_matrix(np.asarray(body["orientation"], dtype=float)) @ axis
    return [float(x) for x in twist["linear"]] + [float(x) for x in twist["rate"] * axis]


def _twist(name: str, body: Mapping[str, Any]) -> list[float]:
    try:
        return initial_twist(body)
    except ConfigError as e:
        raise ConfigError(f"bodies.{name}.{e.key}", e.message) from None


def body_specs(params: Mapping[str, Any], models: Mapping[str, UrdfModel]):
    """BodySpec of every body, values in SI; ConfigError naming the key."""
    from components.dynamics.world import BodySpec, ModelError, check_spec

    specs = []
    for name, body in body_items(params["bodies"]):
        model = models[name]
        area, cd, srp_area = body["drag_area"], body["drag_cd"], body["srp_area"]
        spec = BodySpec(
            name=name,
            urdf=model.path,
            frame=body["frame"],
            position=body["position"],
            orientation=body["orientation"],
            twist=_twist(name, body),
            q=dict(body["q"]),
            qd=dict(body["qd"]),
            locked_joints=tuple(body["locked_joints"]),
            drag_area=area if isinstance(area, Mapping) else {model.root: area},
            drag_cd=cd,
            srp_area=srp_area if isinstance(srp_area, Mapping) else {model.root: srp_area},
            srp_cr=body["srp_cr"],
            srp_facets={link: list(facets) for link, facets in body["srp_facets"].items()},
        )
        try:
            check_spec(spec, model)
        except ModelError as e:
            raise ConfigError(f"bodies.{e.key}", e.message) from None
        specs.append(spec)
    return specs


def _atmosphere(atmosphere: Mapping | None, epoch):
    """The world's atmosphere: None (the table), one exponential layer, or NRLMSISE-00 as a local exponential."""
    from components.space.atmosphere import ExponentialAtmosphere, LocalExponential, Nrlmsise00

    if atmosphere is None or (atmosphere["model"] == "exponential" and atmosphere["altitude"] is None):
        return None
    if atmosphere["model"] == "exponential":
        return ExponentialAtmosphere(single=(atmosphere["altitude"], atmosphere["density"], atmosphere["scale_height"]))
    return LocalExponential(
        Nrlmsise00(atmosphere["f107"], atmosphere["f107a"], atmosphere["ap"], model=atmosphere["model"]), epoch
    )


class OrbitalDynamics(Component):
    """What both dynamics types share: everything but the engine (``engine``)."""

    engine = ""
    state_form = "dynamics"
    plots = (dynamics_plots.BODIES, dynamics_plots.CAPTURE, dynamics_plots.MAGNETIC)
    view = DynamicsView
    rosbag = dynamics_ros.ROS_EXPORT
    parameters = (
        Parameter(
            "bodies",
            MapOf(BODY, "body name", key_pattern=NAME.pattern[1:-1], min_items=1),
            description="the bodies by name",
        ),
        Parameter(
            "integrator",
            "str",
            default="rk4",
            choices=("rk4", "dart"),
            description="rk4: manifold RK4 on the engine's forward dynamics (no contacts); "
            "dart: DART's step with contacts (dynamics.dart only)",
        ),
        Parameter("substeps", Int(minimum=1), default=1, description="internal steps per communication step"),
        Parameter("tidal_force", "bool", default=True, description="tidal (differential gravity) force per link"),
        Parameter("gravity_gradient", "bool", default=True, description="gravity-gradient torque per link"),
        Parameter("drag", "bool", default=False, description="atmospheric drag on links with a drag_area"),
        Parameter(
            "atmosphere",
            ATMOSPHERE,
            default=None,
            description="the drag's atmosphere (model: exponential, nrlmsise00, msis21); null (default): the "
            "piecewise exponential table 0-1000 km",
        ),
        Parameter(
            "srp",
            "bool",
            default=False,
            description="solar radiation pressure on links with an srp_area or srp_facets (needs run.epoch)",
        ),
        Parameter(
            "eclipse",
            Str(tuple(ECLIPSE_MODELS)),
            default="conical",
            description="the shadow for SRP and sun_sensor: conical (Earth and Moon, penumbra), cylindrical "
            "(the Earth's), none",
        ),
        Parameter(
            "solar_flux",
            Float("kg/s^3", positive=True, plausible=(1300.0, 1420.0)),
            default=SOLAR_FLUX,
            description="solar flux at 1 AU, W/m^2 (= kg/s^3; 1361: IAU 2015 nominal total solar irradiance)",
        ),
        Parameter(
            "third_bodies",
            ListOf(Str(tuple(THIRD_BODIES)), unique=True),
            default=[],
            description="bodies whose tidal force acts on every link: sun, moon (their pull at the link less "
            "at the orbit point; JPL DE440 GMs; positions by ERFA at each step's start; needs run.epoch)",
        ),
        Parameter(
            "sun_sensor",
            ListOf(Str(), unique=True),
            default=[],
            description="bodies whose base carries a sun sensor: their sun_body and sunlit outputs (true values; "
            "needs run.epoch)",
        ),
        Parameter(
            "mu",
            Float("m^3/s^2", positive=True, plausible=(1e9, 1e21)),
            default=MU_EARTH,
            description="Earth's gravitational parameter",
        ),
        Parameter("joint_limits", "bool", default=True, description="enforce the URDF joint position limits"),
        Parameter(
            "link_outputs",
            "bool",
            default=False,
            description="publish the per-link outputs (poses, environment wrenches)",
        ),
        Parameter(
            "frame_outputs",
            "bool",
            default=False,
            description="publish each body's CoM frame relative to LVLH (p_lvlh_com, q_lvlh_body, v_lvlh_com, w_lvlh_body)",
        ),
        Parameter(
            "imu",
            ListOf(Str(), unique=True),
            default=[],
            description="bodies whose base carries an IMU: their imu_rate and specific_force outputs (true values)",
        ),
        Parameter("grasp", GRASP, default=None, description="a capture between two bodies; null: none"),
        Parameter(
            "magnetic_field",
            MAGNETIC_FIELD,
            default=None,
            description="the Earth's magnetic field at each body's base: its <body>.b_body outputs, and what "
            "magnetorquers act on; null (default): none",
        ),
        Parameter(
            "magnetorquers",
            MapOf(MAGNETORQUERS, "body"),
            default={},
            description="bodies with magnetorquers: their <body>.dipole input, torque m x B on the base "
            "(needs magnetic_field)",
        ),
    )

    @classmethod
    def declare(cls, params, run):
        lvlh = "used at initialize for frame: lvlh bodies"
        variables = orbit_signals(
            "input",
            notes={"r_eci": "the origin of W; all zero: no orbit, no environment", "q_eci_lvlh": lvlh, "w_lvlh": lvlh},
        )
        links = params.get("link_outputs", False)
        for name, model in load_models(params, run).items():
            m = len(model.links)
            link_names = ", ".join(model.link_names)
            variables += [torque_signal("input", model, name)] + body_signals("output", model, name)
            if not links:
                continue
            variables += [
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
            if params.get("third_bodies"):
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
        for name, model in load_models(params, run).items():
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

    @classmethod
    def validate(cls, params, run):
        models = load_models(params, run)
        body_specs(params, models)
        check_atmosphere(params["atmosphere"], run.epoch)
        for key in ("imu", "sun_sensor"):
            for i, name in enumerate(params[key]):
                if name not in models:
                    raise ConfigError(f"{key}[{i}]", f"expected a body name ({', '.join(models)}), got {name!r}")
        if (params["srp"] or params["sun_sensor"]) and not run.epoch:
            raise ConfigError(EPOCH_KEY, "SRP and a sun sensor need the run's epoch (run.epoch) for the Sun")
        if params["third_bodies"] and not run.epoch:
            raise ConfigError(
                EPOCH_KEY,
                f"third_bodies ({', '.join(params['third_bodies'])}) need the run's epoch "
                f"(run.epoch) for their positions, got none",
            )
        for name in params["magnetorquers"]:
            if name not in models:
                raise ConfigError(f"magnetorquers.{name}", f"expected a body name ({', '.join(models)}), got {name!r}")
            if params["magnetic_field"] is None:
                raise ConfigError(
                    f"magnetorquers.{name}",
                    "magnetorquers act on the Earth's magnetic field: expected "
                    "magnetic_field (model: wmm or dipole), got none",
                )
        grasp = params["grasp"]
        if grasp is not None:
            if params["integrator"] != "rk4":
                raise ConfigError(
                    "grasp",
                    f"a capture needs integrator: rk4 (its weld is solved at every "
                    f"integrator stage), got {params['integrator']!r}",
                )
            for key, link_key in (("chaser", "end_effector"), ("target", "grasp_frame")):
                model = models.get(grasp[key])
                if model is None:
                    raise ConfigError(f"grasp.{key}", f"expected a body name ({', '.join(models)}), got {grasp[key]!r}")
                if grasp[link_key] not in model.link_names:
                    raise ConfigError(
                        f"grasp.{link_key}",
                        f"expected a link of {grasp[key]} ({', '.join(model.link_names)}), got {grasp[link_key]!r}",
                    )
            if grasp["chaser"] == grasp["target"]:
                raise ConfigError("grasp.target", f"expected another body than the chaser, got {grasp['target']!r}")
        return params

    @classmethod
    def preflight(cls, params, run, step_s, full=False):
        """Zero-mass links a joint moves; a step too coarse for the rotation the bodies see (the
        largest of: a body's initial angular rate, its joints' rates, and the orbit's mean motion
        when the body co-rotates with LVLH or the environment is on, taken at the lowest orbit,
        ORBIT_RATE_MAX) against MAX_ROTATION_PER_STEP. ``full``: DART loads every body."""
        models = load_models(params, run)
        notes = [f"bodies.{name}: {note}" for name, model in models.items() for note in model.notes()]
        h = step_s / params["substeps"]
        environment = params["tidal_force"] or params["gravity_gradient"] or params["third_bodies"]
        for name, body in body_items(params["bodies"]):
            model = models[name]
            figures = [
                (float(np.linalg.norm(np.asarray(_twist(name, body), dtype=float)[3:])), "its initial angular rate")
            ]
            revolute = [abs(float(v)) for j, v in body["qd"].items() if model.joint(j).type != "prismatic"]
            if revolute:
                figures.append((max(revolute), "its fastest joint's initial rate"))
            if body["frame"] == "lvlh" or environment:
                figures.append((ORBIT_RATE_MAX, "the orbit's rate (mean motion at the lowest orbit)"))
            rate, what = max(figures)
            if rate * h > MAX_ROTATION_PER_STEP:
                notes.append(
                    f"bodies.{name}: the step is too coarse for the dynamics: {what}, {rate:.3g} rad/s, turns it "
                    f"{rate * h:.3g} rad ({np.degrees(rate * h):.3g} deg) per step of {h:g} s; above "
                    f"{MAX_ROTATION_PER_STEP:g} rad ({np.degrees(MAX_ROTATION_PER_STEP):.2g} deg) per step the "
                    f"integration is wrong by whole degrees: use a step of at most {MAX_ROTATION_PER_STEP / rate:.3g} s "
                    f"(or substeps)"
                )
        if full:  # the engine loads every body: what it refuses is an error now, not at the start
            world = cls(params, run, compile_kernels=False).world  # (the kernels compile at the run's instantiate)
            notes += [
                f"bodies.{name}: {note}"
                for name, body in world.bodies.items()
                for note in getattr(body, "engine_notes", ())
            ]
            notes += [
                f"bodies.{a} and bodies.{b} overlap at the start: {a}'s link {la!r} and {b}'s link {lb!r} "
                f"by {depth * 1e3:.3g} mm (their collision geometry); the rk4 integrator has no contacts: "
                f"they pass through each other"
                for a, la, b, lb, depth in world.overlaps()
            ]
        return notes

    def __init__(self, params, run, *, compile_kernels: bool = True):
        super().__init__(params, run)
        from components.dynamics.capture import GraspSpec, Tolerance
        from components.dynamics.world import ModelError, OrbitalWorld

        models = load_models(params, run)
        specs = body_specs(params, models)
        grasp = params["grasp"]
        self.grasp = grasp is not None and GraspSpec(
            chaser=grasp["chaser"],
            end_effector=grasp["end_effector"],
            target=grasp["target"],
            grasp_frame=grasp["grasp_frame"],
            tolerance=Tolerance(**grasp["tolerance"]),
            force_limit=grasp["force_limit"],
            torque_limit=grasp["torque_limit"],
            on_overload=grasp["on_overload"],
        )
        try:
            self.world = OrbitalWorld(
                specs,
                engine=self.engine,
                integrator=params["integrator"],
                substeps=params["substeps"],
                tidal_force=params["tidal_force"],
                gravity_gradient=params["gravity_gradient"],
                drag=params["drag"],
                mu=params["mu"],
                atmosphere=_atmosphere(params["atmosphere"], run.epoch),
                joint_limits=params["joint_limits"],
                models=models,
                grasp=self.grasp or None,
                compile_kernels=compile_kernels,
                srp=params["srp"],
                eclipse=params["eclipse"],
                solar_flux=params["solar_flux"],
                third_bodies=tuple(params["third_bodies"]),
            )
        except ModelError as e:
            raise ConfigError(f"bodies.{e.key}", e.message) from None
        self.names = [spec.name for spec in specs]
        self.links = params["link_outputs"]
        self.torque_inputs = [(name, f"{name}.tau") for name in self.names]
        self.output_names = {name: {key: f"{name}.{key}" for key in BODY_OUTPUTS + LINK_OUTPUTS} for name in self.names}
        self.frames = params["frame_outputs"]
        self.imu = list(params["imu"])
        self.sun_sensors = list(params["sun_sensor"])
        self.ephemeris = None
        if params["srp"] or self.sun_sensors or params["third_bodies"]:  # the Sun and Moon at each step's start
            from components.space.ephemeris import Ephemeris

            self.ephemeris = Ephemeris(run.epoch)
        self.quaternion_outputs = [
            f"{name}.{key}"
            for name in self.names
            for key in ("orientation", "link_orientation")[: 2 if self.links else 1]
        ]
        self.quaternion_outputs += [f"{name}.q_lvlh_body" for name in self.names if self.frames]
        self.quaternion_outputs += ["grasp.q_ee_grasp", "grasp.q_c_t"] if self.grasp else []
        self.magnetics = None  # the field and magnetorquers (magnetic_field), else nothing per step
        field = params["magnetic_field"]
        if field is not None:
            from components.dynamics.magnetic import Magnetics
            from components.space.geomagnetic import GeomagneticField

            if not run.epoch:
                raise ConfigError(EPOCH_KEY, "the magnetic field needs the run's epoch (run.epoch)")
            dipole = {key: field[key] for key in ("g10", "g11", "h11", "radius")}
            self.magnetics = Magnetics(
                self.world,
                GeomagneticField(field["model"], run.epoch, dipole),
                {
                    name: np.broadcast_to(np.asarray(m["max_dipole"], dtype=float), (3,))
                    for name, m in params["magnetorquers"].items()
                },
            )
        self.capture_report = None  # the last step's capture, for the event
        self.last_quaternions: dict[str, np.ndarray] = {}

    def _inputs(self, inputs: Mapping[str, np.ndarray], torques: bool, t_ns: int) -> None:
        age = (t_ns - self.input_times_ns.get("r_eci", t_ns)) / NS_PER_S  # < 0 under Gauss-Seidel
        if self.ephemeris is not None:
            tt = self.ephemeris.tt(t_ns)
            self.world.set_sun(sun_position_eci(tt), moon_position_eci(tt))
        try:
            self.world.set_orbit(*ORBIT_VALUES(inputs), age=age)
            if self.world.atmosphere_varies:  # NRLMSISE-00 needs the time the orbit point is at
                self.world.orbit_time = self.input_times_ns.get("r_eci", t_ns) / NS_PER_S
            if torques:
                for name, key in self.torque_inputs:
                    self.world.set_torques(name, inputs[key])
        except ValueError as e:
            raise ComponentError(str(e)) from None

    def _outputs(self, t_ns: int) -> dict[str, np.ndarray]:
        out = {}
        for name in self.names:
            output_names = self.output_names[name]
            for key, value in self.world.outputs(name, links=self.links).items():
                out[output_names[key]] = value
            if self.frames:
                out.update({f"{name}.{k}": v for k, v in self.world.frame_outputs(name).items()})
        for name in self.sun_sensors:
            out.update({f"{name}.{k}": v for k, v in self.world.sun_outputs(name).items()})
        grasp = self.world.grasp
        if self.imu or (grasp is not None and grasp.closed):
            accelerations = self.world.accelerations()  # also the weld's wrench, for grasp.wrench
            for name in self.imu:
                out.update({f"{name}.{k}": v for k, v in self.world.imu_outputs(name, accelerations[name]).items()})
        if grasp is not None:
            out.update({f"grasp.{k}": v for k, v in grasp.relative().items()})
            out.update(
                {f"grasp.{k}": v for k, v in self.world.relative_frames(self.grasp.chaser, self.grasp.target).items()}
            )
            out["grasp.closed"] = np.float64(grasp.closed)
            out["grasp.wrench"] = grasp.wrench_on_target() if grasp.closed else np.zeros(6)
        if self.magnetics is not None:
            try:
                out.update(self.magnetics.outputs(t_ns))
            except ValueError as e:  # the WMM outside its years
                raise ComponentError(f"magnetic_field: {e}") from None
        for key in self.quaternion_outputs:
            out[key] = self.last_quaternions[key] = continuous(out[key], self.last_quaternions.get(key))
        return out

    def initialize(self, t0_ns, inputs):
        self._inputs(inputs, torques=False, t_ns=t0_ns)
        self.world.reset_bodies()
        if self.world.atmosphere_varies and self.world.environment_on:  # (the steps update it at their midpoints)
            self.world.update_atmosphere(self.world.elapsed)
        self.last_quaternions = {}
        return self._outputs(t0_ns)

    def do_step(self, t_ns, h_ns, inputs):
        self._inputs(inputs, torques=True, t_ns=t_ns)
        if self.magnetics is not None:
            self.magnetics.apply(inputs)
        self.world.step(h_ns / NS_PER_S)
        grasp = self.world.grasp
        if grasp is not None:
            overload = grasp.check_overload()
            if overload is not None:
                self.emit("grasp_overload", time=(t_ns + h_ns) / NS_PER_S, **overload)
            grasp.rearm(inputs["grasp.close"] >= 0.5)
        if self.grasp and inputs["grasp.close"] >= 0.5:
            report = self.world.capture()
            if report is not None:
                self.capture_report = report
                self.emit(
                    "capture",
                    time=(t_ns + h_ns) / NS_PER_S,
                    relative_twist=report.relative_twist.tolist(),
                    impulse=report.impulse.tolist(),
                    errors=report.errors,
                )
        return self._outputs(t_ns + h_ns)

    def get_state(self):
        magnetic = self.magnetics.get_state() if self.magnetics is not None else {}
        return {**self.world.get_state(), **{LAST + k: v.copy() for k, v in self.last_quaternions.items()}, **magnetic}

    def set_state(self, state):
        try:
            self.world.set_state({k: v for k, v in state.items() if not k.startswith((LAST, MAGNETIC))})
            if self.magnetics is not None:
                self.magnetics.set_state(state)
        except ValueError as e:
            raise ComponentError(str(e)) from None
        except KeyError as e:
            raise ComponentError(f"state: missing {e.args[0]!r}") from None
        self.last_quaternions = {
            k[len(LAST) :]: np.array(v, dtype=np.float64) for k, v in state.items() if k.startswith(LAST)
        }


class DartDynamics(OrbitalDynamics):
    """Free-floating URDF multibodies in orbit, their dynamics by DART.

    Zero gravity in the free-falling, non-rotating world frame W (origin at the reference orbit
    point r_eci(t), axes parallel to ECI), plus per link and each switchable: tidal force,
    gravity-gradient torque, atmospheric drag, solar radiation pressure (docs/environment/sun.md),
    the Sun's and the Moon's tidal force (``third_bodies``, docs/environment/gravity.md). ``integrator: rk4`` (default) is fourth-order
    Runge-Kutta on the configuration manifold over DART's forward dynamics (no contacts);
    ``integrator: dart`` is DART's own step with its constraint solver (contacts between bodies).
    Quaternions [x, y, z, w]. Takes the state of ``dynamics.pinocchio`` (a swap hands it over).
    """

    type_name = "dynamics.dart"
    engine = "dart"


class PinocchioDynamics(OrbitalDynamics):
    """Free-floating URDF multibodies in orbit, their dynamics by Pinocchio (ABA).

    The same world, environment, integrator, joint stops, mimic joints, grasp, outputs and state as
    ``dynamics.dart`` (components/dynamics/world.py); Pinocchio computes the forward dynamics
    (components/dynamics/pinocchio_body.py). No contacts: ``integrator`` must be rk4. Takes the
    state of ``dynamics.dart`` (a swap hands it over). Quaternions [x, y, z, w].
    """

    type_name = "dynamics.pinocchio"
    engine = "pinocchio"

    @classmethod
    def validate(cls, params, run):
        if params["integrator"] != "rk4":
            raise ConfigError(
                "integrator",
                f"dynamics.pinocchio has no contact solver: expected rk4 (DART's own "
                f"step with contacts is dynamics.dart's), got {params['integrator']!r}",
            )
        return super().validate(params, run)
