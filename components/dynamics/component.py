"""Free-floating URDF multibodies in orbit, simulated with DART (type ``dynamics.dart``; a thin
wrapper of :class:`components.dynamics.world.OrbitalWorld`).

Zero gravity in the free-falling, non-rotating world frame W (origin at the reference orbit point
r_eci(t), axes parallel to ECI), plus per link and each switchable: tidal force, gravity-gradient
torque, atmospheric drag. ``integrator: rk4`` (default) is fourth-order Runge-Kutta on the
configuration manifold over DART's forward dynamics (no contacts); ``integrator: dart`` is DART's
own step with its constraint solver (contacts between bodies). Quaternions [x, y, z, w].

| parameter | kind | unit | default | description |
|---|---|---|---|---|
| bodies | any | - | required | name -> body (table below); a list of bodies with ``name`` also works |
| integrator | str | - | rk4 | rk4 (manifold RK4, no contacts) or dart (DART step, contacts) |
| substeps | int | - | 1 | internal steps per communication step |
| tidal_force | bool | - | true | F_i = m_i (g(R + d_i) - g(R)) on each link CoM |
| gravity_gradient | bool | - | true | tau_i = 3 mu / abs(rho_i)^5 (rho_i x I_i rho_i) on each link |
| drag | bool | - | false | -1/2 rho Cd A abs(v_rel) v_rel on links with a drag_area |
| atmosphere | any | - | null | null: piecewise exponential table 0-1000 km; or {altitude, density, scale_height} |
| mu | float | m^3/s^2 | 3.986004418e14 | Earth's gravitational parameter |
| joint_limits | bool | - | true | URDF position limits (rk4: inelastic stops; dart: constraints) |
| link_outputs | bool | - | false | publish the per-link outputs (last five rows below); each step then costs a transform per link and one more environment evaluation |

Body (``bodies.<name>``):

| key | unit | default | description |
|---|---|---|---|
| urdf | - | required | URDF file, relative to the config file (or to the project root); its root link is the free base |
| frame | - | world | world (W) or lvlh: the frame of position, orientation and twist (lvlh includes its rotation) |
| position | m | [0, 0, 0] | base link origin |
| orientation | - | [0, 0, 0, 1] | base attitude [x, y, z, w] |
| twist | m/s, rad/s | zeros | base origin linear velocity, then angular velocity |
| q, qd | rad (m), rad/s (m/s) | {} | initial joint positions / rates by joint name; others 0 |
| locked_joints | - | [] | joints welded at their initial q |
| drag_area | m^2 | {} | link name -> area, or one number for the base link |
| drag_cd | - | 2.2 | drag coefficient, one number or link name -> Cd |

| variable | causality | shape | unit | description |
|---|---|---|---|---|
| r_eci | input | (3,) | m | reference orbit point (origin of W), ECI; all zero = no orbit, no environment |
| v_eci | input | (3,) | m/s | its velocity, ECI |
| q_eci_lvlh | input | (4,) | 1 | LVLH attitude [x, y, z, w], LVLH -> ECI (used at initialize for frame: lvlh) |
| w_lvlh | input | (3,) | rad/s | LVLH angular velocity, ECI axes (used at initialize) |
| <body>.tau | input | (n_joints,) | N m (N) | joint torques, every non-fixed URDF joint in file order; clipped to the URDF effort; ignored on locked joints |
| <body>.position | output | (3,) | m | base link origin in W |
| <body>.orientation | output | (4,) | 1 | q_W_base [x, y, z, w], sign continuous from step to step (w >= 0 at initialize) |
| <body>.twist | output | (6,) | m/s, rad/s | base origin linear velocity, then angular velocity, W axes |
| <body>.q | output | (n_joints,) | rad (m) | joint positions |
| <body>.qd | output | (n_joints,) | rad/s (m/s) | joint rates |
| <body>.com | output | (3,) | m | body CoM in W |
| <body>.momentum | output | (6,) | kg m/s, kg m^2/s | linear, then angular about the body CoM, W axes |
| <body>.gg_torque | output | (n_links*3,) | N m | gravity-gradient torque per URDF link (file order), W axes; this and the next four only with link_outputs: true |
| <body>.tidal_force | output | (n_links*3,) | N | tidal force per link, W axes |
| <body>.drag_force | output | (n_links*3,) | N | drag force per link, W axes |
| <body>.link_position | output | (n_links*3,) | m | link frame origins in W |
| <body>.link_orientation | output | (n_links*4,) | 1 | q_W_link per link [x, y, z, w], sign continuous |

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
from components.sdk import Component, Parameter, Variable
from components.units import to_si

PROJECT_ROOT = Path(__file__).resolve().parents[2]
NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
BODY_KEYS = ("urdf", "frame", "position", "orientation", "twist", "q", "qd", "locked_joints",
             "drag_area", "drag_cd")
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


def _vector(value: Any, size: int, units: list[str], key: str) -> np.ndarray:
    if not isinstance(value, (list, tuple)) or len(value) != size:
        raise ConfigError(key, f"expected a list of {size} numbers, got {value!r}")
    return np.array([to_si(v, u, f"{key}[{i}]") for i, (v, u) in enumerate(zip(value, units))])


def _mapping(value: Any, key: str) -> Mapping:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise ConfigError(key, f"expected a mapping name: value, got {value!r}")
    return value


def body_items(raw: Any) -> list[tuple[str, Mapping]]:
    """``bodies`` as (name, body) pairs: a mapping, or a list of mappings with ``name``."""
    if isinstance(raw, Mapping):
        items = list(raw.items())
    elif isinstance(raw, list):
        items = []
        for i, body in enumerate(raw):
            if not isinstance(body, Mapping) or "name" not in body:
                raise ConfigError(f"bodies[{i}]", f"expected a mapping with a name, got {body!r}")
            items.append((body["name"], {k: v for k, v in body.items() if k != "name"}))
    else:
        raise ConfigError("bodies", f"expected a mapping body name -> body, got {raw!r}")
    if not items:
        raise ConfigError("bodies", "expected at least one body")
    seen = set()
    for name, body in items:
        if not isinstance(name, str) or not NAME.match(name):
            raise ConfigError(f"bodies.{name}", "a body name must be an identifier (letters, digits, _)")
        if name in seen:
            raise ConfigError(f"bodies.{name}", "duplicate body name")
        seen.add(name)
        if not isinstance(body, Mapping):
            raise ConfigError(f"bodies.{name}", f"expected a mapping with at least urdf, got {body!r}")
        unknown = [k for k in body if k not in BODY_KEYS]
        if unknown:
            raise ConfigError(f"bodies.{name}.{unknown[0]}", f"unknown key (known: {', '.join(BODY_KEYS)})")
        if "urdf" not in body:
            raise ConfigError(f"bodies.{name}.urdf", "missing required key: the body's URDF file")
    return items


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
        k = f"bodies.{name}"
        frame = body.get("frame", "world")
        if frame not in ("world", "lvlh"):
            raise ConfigError(f"{k}.frame", f"expected world or lvlh, got {frame!r}")
        joint_units = {j.name: ("m" if j.type == "prismatic" else "rad") for j in model.joints}
        q = {j: to_si(v, joint_units.get(j, "rad"), f"{k}.q.{j}") for j, v in _mapping(body.get("q"), f"{k}.q").items()}
        qd = {j: to_si(v, joint_units.get(j, "rad") + "/s", f"{k}.qd.{j}")
              for j, v in _mapping(body.get("qd"), f"{k}.qd").items()}
        locked = body.get("locked_joints") or []
        if not isinstance(locked, list) or not all(isinstance(j, str) for j in locked):
            raise ConfigError(f"{k}.locked_joints", f"expected a list of joint names, got {locked!r}")
        area = body.get("drag_area", {})
        if isinstance(area, Mapping):
            area = {link: to_si(v, "m^2", f"{k}.drag_area.{link}") for link, v in area.items()}
        else:
            area = {model.root: to_si(area, "m^2", f"{k}.drag_area")}
        cd = body.get("drag_cd", 2.2)
        if isinstance(cd, Mapping):
            cd = {link: to_si(v, "1", f"{k}.drag_cd.{link}") for link, v in cd.items()}
        else:
            cd = to_si(cd, "1", f"{k}.drag_cd")
        spec = BodySpec(
            name=name, urdf=model.path, frame=frame,
            position=_vector(body.get("position", [0, 0, 0]), 3, ["m"] * 3, f"{k}.position"),
            orientation=_vector(body.get("orientation", [0, 0, 0, 1]), 4, ["1"] * 4, f"{k}.orientation"),
            twist=_vector(body.get("twist", [0] * 6), 6, ["m/s"] * 3 + ["rad/s"] * 3, f"{k}.twist"),
            q=q, qd=qd, locked_joints=tuple(locked), drag_area=area, drag_cd=cd)
        try:
            check_spec(spec, model)
        except ModelError as e:
            raise ConfigError(f"bodies.{e.key}", e.message) from None
        specs.append(spec)
    return specs


def _atmosphere(value: Any):
    from components.dynamics.environment import ExponentialAtmosphere

    if value is None:
        return None
    if not isinstance(value, Mapping) or set(value) != {"altitude", "density", "scale_height"}:
        raise ConfigError("atmosphere", "expected null (the 0-1000 km exponential table) or "
                                        f"{{altitude, density, scale_height}}, got {value!r}")
    altitude = to_si(value["altitude"], "m", "atmosphere.altitude")
    density = to_si(value["density"], "kg/m^3", "atmosphere.density")
    scale = to_si(value["scale_height"], "m", "atmosphere.scale_height")
    if density < 0 or scale <= 0:
        raise ConfigError("atmosphere", f"expected density >= 0 and scale_height > 0, got {density}, {scale}")
    return ExponentialAtmosphere(single=(altitude, density, scale))


class DartDynamics(Component):
    __doc__ = __doc__
    type_name = "dynamics.dart"
    parameters = (
        Parameter("bodies", "any", description="name -> {urdf, frame, position, orientation, twist, q, qd, "
                                               "locked_joints, drag_area, drag_cd}"),
        Parameter("integrator", "str", default="rk4", choices=("rk4", "dart"),
                  description="rk4: manifold RK4 on DART forward dynamics (no contacts); dart: DART step with contacts"),
        Parameter("substeps", "int", default=1, description="internal steps per communication step"),
        Parameter("tidal_force", "bool", default=True, description="tidal (differential gravity) force per link"),
        Parameter("gravity_gradient", "bool", default=True, description="gravity-gradient torque per link"),
        Parameter("drag", "bool", default=False, description="atmospheric drag on links with a drag_area"),
        Parameter("atmosphere", "any", default=None,
                  description="null: exponential table 0-1000 km; or {altitude, density, scale_height}"),
        Parameter("mu", "float", unit="m^3/s^2", default=MU_EARTH, description="Earth's gravitational parameter"),
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
                         f"gravity-gradient torque per link about its CoM, W axes, links: {link_names}"),
                Variable(f"{name}.tidal_force", "output", (3 * m,), "N", 0.0, "tidal force per link, W axes"),
                Variable(f"{name}.drag_force", "output", (3 * m,), "N", 0.0, "drag force per link, W axes"),
                Variable(f"{name}.link_position", "output", (3 * m,), "m", 0.0, "link frame origins in W"),
                Variable(f"{name}.link_orientation", "output", (4 * m,), "1", np.tile([0.0, 0.0, 0.0, 1.0], m),
                         "q_W_link per link [x, y, z, w]"),
            ]
        return variables

    @classmethod
    def validate(cls, params):
        if params["substeps"] < 1:
            raise ConfigError("substeps", f"expected an integer >= 1, got {params['substeps']}")
        if not params["mu"] > 0:
            raise ConfigError("mu", f"expected a positive gravitational parameter, got {params['mu']}")
        _atmosphere(params["atmosphere"])
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
