"""Free-floating URDF multibodies in orbit, simulated with DART (type ``dynamics.dart``; a thin
wrapper of :class:`components.dynamics.world.OrbitalWorld`).

Zero gravity in the free-falling, non-rotating world frame W (origin at the reference orbit point
r_eci(t), axes parallel to ECI), plus per link and each switchable: tidal force, gravity-gradient
torque, atmospheric drag. ``integrator: rk4`` (default) is fourth-order Runge-Kutta on the
configuration manifold over DART's forward dynamics (no contacts); ``integrator: dart`` is DART's
own step with its constraint solver (contacts between bodies). Quaternions [x, y, z, w].

``declare`` reads the URDFs with xml.etree only (joint and link counts); DART loads at instantiate.
State (``get_state``): the DART positions and velocities of every body, torques, orbit inputs,
and the last output quaternions (their signs continue).
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from components.constants import MU_EARTH, NS_PER_S
from components.dynamics.urdf import UrdfError, UrdfModel, read_urdf
from components.errors import ComponentError, ConfigError
from components.rotations import continuous
from components.schema import Float, Int, ListOf, MapOf, OneOf, Record, Str, Vector
from components.sdk import Component, Parameter, Variable

PROJECT_ROOT = Path(__file__).resolve().parents[2]
NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
ORBIT_INPUTS = ("r_eci", "v_eci", "q_eci_lvlh", "w_lvlh")
BODY_OUTPUTS = ("position", "orientation", "twist", "q", "qd", "com", "momentum")
LINK_OUTPUTS = ("gg_torque", "tidal_force", "drag_force", "link_position", "link_orientation")
LAST = "last_output."   # state keys of the last output quaternions


def resolve_urdf(value: Any, config_dir: str | None, key: str) -> Path:
    """A URDF path: absolute, else relative to the config file, else to the project root."""
    if not isinstance(value, str) or not value:
        raise ConfigError(key, f"expected a URDF file path, got {value!r}")
    path = Path(value)
    if path.is_absolute():
        candidates = [path]
    else:
        candidates = [Path(config_dir or ".") / path, PROJECT_ROOT / path]
    for candidate in candidates:
        if candidate.is_file():
            return candidate.resolve()
    raise ConfigError(key, f"URDF file {value!r} not found (looked in: {', '.join(str(c) for c in candidates)})")


JOINT_VALUE = OneOf((Float("rad"), Float("m")))       # revolute (rad) or prismatic (m)
JOINT_RATE = OneOf((Float("rad/s"), Float("m/s")))
PER_LINK = "one number for the base link, or link name -> number"
BODY = Record("Body", (
    Parameter("urdf", Str(hint="a URDF file path"),
              description="URDF file, relative to the config file (else to the project root); its root link is the free base"),
    Parameter("frame", Str(("world", "lvlh")), default="world",
              description="frame of position, orientation and twist (lvlh: LVLH at t0, its rotation included)"),
    Parameter("position", Vector(3, "m"), default=[0.0, 0.0, 0.0], description="base link origin"),
    Parameter("orientation", Vector(4), default=[0.0, 0.0, 0.0, 1.0], description="base attitude [x, y, z, w]"),
    Parameter("twist", Vector(6, units=("m/s",) * 3 + ("rad/s",) * 3), default=[0.0] * 6,
              description="base origin linear velocity (m/s), then angular velocity (rad/s)"),
    Parameter("q", MapOf(JOINT_VALUE, "joint"), default={},
              description="initial joint positions (rad, m for prismatic); joints not named start at 0"),
    Parameter("qd", MapOf(JOINT_RATE, "joint"), default={},
              description="initial joint rates (rad/s, m/s for prismatic); joints not named start at 0"),
    Parameter("locked_joints", ListOf(Str(), unique=True), default=[], description="joints welded at their initial q"),
    Parameter("drag_area", OneOf((Float("m^2", minimum=0.0), MapOf(Float("m^2", minimum=0.0), "link"))),
              default={}, description=f"area facing the flow: {PER_LINK}"),
    Parameter("drag_cd", OneOf((Float(minimum=0.0), MapOf(Float(minimum=0.0), "link"))), default=2.2,
              description=f"drag coefficient: {PER_LINK}"),
), description="one free-floating URDF multibody (``bodies.<name>``)")
ATMOSPHERE = Record("Atmosphere", (
    Parameter("altitude", Float("m"), description="reference altitude above the WGS 84 ellipsoid"),
    Parameter("density", Float("kg/m^3", minimum=0.0), description="density at that altitude"),
    Parameter("scale_height", Float("m", positive=True), description="height over which the density falls by e"),
), description="one exponential layer instead of the 0-1000 km table")


def body_items(raw: Any) -> list[tuple[str, Mapping]]:
    """``bodies`` as (name, body) pairs; ConfigError unless a mapping name -> {urdf, ...}."""
    if not isinstance(raw, Mapping) or not raw:
        raise ConfigError("bodies", f"expected a mapping body name -> body, got {raw!r}")
    for name, body in raw.items():
        if not isinstance(body, Mapping) or "urdf" not in body:
            raise ConfigError(f"bodies.{name}", f"expected a mapping with at least urdf, got {body!r}")
    return list(raw.items())


def load_models(params: Mapping[str, Any]) -> dict[str, UrdfModel]:
    """Parsed URDF of every body (xml.etree only); ConfigError naming ``bodies.<name>.urdf``."""
    models = {}
    for name, body in body_items(params["bodies"]):
        key = f"bodies.{name}.urdf"
        path = resolve_urdf(body["urdf"], params.get("_config_dir"), key)
        try:
            models[name] = read_urdf(path)
        except UrdfError as e:
            raise ConfigError(key, str(e)) from None
    return models


def body_specs(params: Mapping[str, Any], models: Mapping[str, UrdfModel]):
    """BodySpec of every body, values in SI; ConfigError naming the key."""
    from components.dynamics.world import BodySpec, ModelError, check_spec

    specs = []
    for name, body in body_items(params["bodies"]):
        model = models[name]
        area, cd = body["drag_area"], body["drag_cd"]
        spec = BodySpec(
            name=name, urdf=model.path, frame=body["frame"], position=body["position"],
            orientation=body["orientation"], twist=body["twist"], q=dict(body["q"]), qd=dict(body["qd"]),
            locked_joints=tuple(body["locked_joints"]), drag_area=area if isinstance(area, Mapping) else {model.root: area},
            drag_cd=cd)
        try:
            check_spec(spec, model)
        except ModelError as e:
            raise ConfigError(f"bodies.{e.key}", e.message) from None
        specs.append(spec)
    return specs


def _atmosphere(layer: Mapping | None):
    from components.dynamics.environment import ExponentialAtmosphere

    if layer is None:
        return None
    return ExponentialAtmosphere(single=(layer["altitude"], layer["density"], layer["scale_height"]))


class DartDynamics(Component):
    __doc__ = __doc__
    type_name = "dynamics.dart"
    parameters = (
        Parameter("bodies", MapOf(BODY, "body name", key_pattern=NAME.pattern[1:-1], min_items=1),
                  description="the bodies by name"),
        Parameter("integrator", "str", default="rk4", choices=("rk4", "dart"),
                  description="rk4: manifold RK4 on DART forward dynamics (no contacts); dart: DART step with contacts"),
        Parameter("substeps", Int(minimum=1), default=1, description="internal steps per communication step"),
        Parameter("tidal_force", "bool", default=True, description="tidal (differential gravity) force per link"),
        Parameter("gravity_gradient", "bool", default=True, description="gravity-gradient torque per link"),
        Parameter("drag", "bool", default=False, description="atmospheric drag on links with a drag_area"),
        Parameter("atmosphere", ATMOSPHERE, default=None,
                  description="one exponential layer; null (default): the piecewise exponential table 0-1000 km"),
        Parameter("mu", Float("m^3/s^2", positive=True), default=MU_EARTH, description="Earth's gravitational parameter"),
        Parameter("joint_limits", "bool", default=True, description="enforce the URDF joint position limits"),
        Parameter("link_outputs", "bool", default=False,
                  description="publish the per-link outputs (poses, environment wrenches)"),
    )

    @classmethod
    def declare(cls, params):
        variables = [
            Variable("r_eci", "input", (3,), "m", [0.0, 0.0, 0.0],
                     "reference orbit point (origin of W), ECI; all zero: no orbit, no environment"),
            Variable("v_eci", "input", (3,), "m/s", [0.0, 0.0, 0.0], "velocity of the reference point, ECI"),
            Variable("q_eci_lvlh", "input", (4,), "1", [0.0, 0.0, 0.0, 1.0],
                     "LVLH attitude [x, y, z, w] (LVLH -> ECI); used at initialize for frame: lvlh bodies"),
            Variable("w_lvlh", "input", (3,), "rad/s", [0.0, 0.0, 0.0],
                     "LVLH angular velocity, ECI axes; used at initialize for frame: lvlh bodies"),
        ]
        links = params.get("link_outputs", False)
        for name, model in load_models(params).items():
            n, m = len(model.movable_joints), len(model.links)
            joints = ", ".join(model.movable_joints)
            link_names = ", ".join(model.link_names)
            variables += [
                Variable(f"{name}.tau", "input", (n,), "N*m", 0.0,
                         f"joint torques (N m, N for prismatic), URDF order: {joints}"),
                Variable(f"{name}.position", "output", (3,), "m", 0.0, "base link origin in W"),
                Variable(f"{name}.orientation", "output", (4,), "1", [0.0, 0.0, 0.0, 1.0],
                         "q_W_base [x, y, z, w], sign continuous from step to step"),
                Variable(f"{name}.twist", "output", (6,), "m/s, rad/s", 0.0,
                         "base origin linear velocity then angular velocity, W axes"),
                Variable(f"{name}.q", "output", (n,), "rad", 0.0, f"joint positions, URDF order: {joints}"),
                Variable(f"{name}.qd", "output", (n,), "rad/s", 0.0, "joint rates, URDF order"),
                Variable(f"{name}.com", "output", (3,), "m", 0.0, "body CoM in W"),
                Variable(f"{name}.momentum", "output", (6,), "kg*m/s, kg*m^2/s", 0.0,
                         "linear momentum, then angular momentum about the body CoM, W axes"),
            ]
            if not links:
                continue
            variables += [
                Variable(f"{name}.gg_torque", "output", (3 * m,), "N*m", 0.0,
                         f"gravity-gradient torque per link about its CoM, W axes, links: {link_names} "
                         "(this and the next four only with link_outputs: true)"),
                Variable(f"{name}.tidal_force", "output", (3 * m,), "N", 0.0, "tidal force per link, W axes"),
                Variable(f"{name}.drag_force", "output", (3 * m,), "N", 0.0, "drag force per link, W axes"),
                Variable(f"{name}.link_position", "output", (3 * m,), "m", 0.0, "link frame origins in W"),
                Variable(f"{name}.link_orientation", "output", (4 * m,), "1", np.tile([0.0, 0.0, 0.0, 1.0], m),
                         "q_W_link per link [x, y, z, w]"),
            ]
        return variables

    @classmethod
    def validate(cls, params):
        body_specs(params, load_models(params))

    def __init__(self, params):
        super().__init__(params)
        from components.dynamics.world import ModelError, OrbitalWorld

        models = load_models(params)
        specs = body_specs(params, models)
        try:
            self.world = OrbitalWorld(
                specs, integrator=params["integrator"], substeps=params["substeps"],
                tidal_force=params["tidal_force"], gravity_gradient=params["gravity_gradient"],
                drag=params["drag"], mu=params["mu"], atmosphere=_atmosphere(params["atmosphere"]),
                joint_limits=params["joint_limits"], models=models)
        except ModelError as e:
            raise ConfigError(f"bodies.{e.key}", e.message) from None
        self.names = [spec.name for spec in specs]
        self.links = params["link_outputs"]
        self.torque_inputs = [(name, f"{name}.tau") for name in self.names]
        self.output_names = {name: {key: f"{name}.{key}" for key in BODY_OUTPUTS + LINK_OUTPUTS} for name in self.names}
        self.quaternion_outputs = [f"{name}.{key}" for name in self.names
                                   for key in ("orientation", "link_orientation")[:2 if self.links else 1]]
        self.last_quaternions: dict[str, np.ndarray] = {}

    def _inputs(self, inputs: Mapping[str, np.ndarray], torques: bool, t_ns: int) -> None:
        age = (t_ns - self.input_times_ns.get("r_eci", t_ns)) / NS_PER_S   # < 0 under Gauss-Seidel
        try:
            self.world.set_orbit(*(inputs[k] for k in ORBIT_INPUTS), age=age)
            if torques:
                for name, key in self.torque_inputs:
                    self.world.set_torques(name, inputs[key])
        except ValueError as e:
            raise ComponentError(str(e)) from None

    def _outputs(self) -> dict[str, np.ndarray]:
        out = {}
        for name in self.names:
            output_names = self.output_names[name]
            for key, value in self.world.outputs(name, links=self.links).items():
                out[output_names[key]] = value
        for key in self.quaternion_outputs:
            out[key] = self.last_quaternions[key] = continuous(out[key], self.last_quaternions.get(key))
        return out

    def initialize(self, t0_ns, inputs):
        self._inputs(inputs, torques=False, t_ns=t0_ns)
        self.world.reset_bodies()
        self.last_quaternions = {}
        return self._outputs()

    def do_step(self, t_ns, h_ns, inputs):
        self._inputs(inputs, torques=True, t_ns=t_ns)
        self.world.step(h_ns / NS_PER_S)
        return self._outputs()

    def get_state(self):
        return {**self.world.get_state(), **{LAST + k: v.copy() for k, v in self.last_quaternions.items()}}

    def set_state(self, state):
        try:
            self.world.set_state({k: v for k, v in state.items() if not k.startswith(LAST)})
        except ValueError as e:
            raise ComponentError(str(e)) from None
        self.last_quaternions = {k[len(LAST):]: np.array(v, dtype=np.float64) for k, v in state.items()
                                 if k.startswith(LAST)}
