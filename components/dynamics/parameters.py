"""The parameters of the dynamics types (``dynamics.dart``, ``dynamics.pinocchio``), declared once:
a body (its initial state, drag and SRP), the environment's switches, the magnetic field and
magnetorquers, the grasp of a capture."""

from __future__ import annotations

import re

from components.constants import MU_EARTH
from components.dynamics.bodies import THIRD_BODIES
from components.dynamics.capture import OVERLOAD_ACTIONS
from components.robots.model import JOINT_RATE, JOINT_VALUE
from components.schema import Float, Int, ListOf, MapOf, OneOf, Record, Str, Vector
from components.sdk import Parameter
from components.space.eclipse import MODELS as ECLIPSE_MODELS
from components.space.geomagnetic import BASILISK_DIPOLE
from components.space.geomagnetic import MODELS as MAGNETIC_MODELS
from components.space.parameters import ATMOSPHERE
from components.space.srp import SOLAR_FLUX
from components.units import DEG

NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
PER_LINK = "one number for the base link, or link name -> number"
# plausible (a warning beyond): tumbling debris turns at up to a few tens of deg/s; a base's offset
# and velocity relative to the orbit point are those of proximity operations
TUMBLE = (0.0, 60 * DEG)
RATE = (-60 * DEG, 60 * DEG)
SPEED = (-100.0, 100.0)
OFFSET = (-1e5, 1e5)
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

PARAMETERS = (
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
