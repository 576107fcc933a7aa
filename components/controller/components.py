"""Controller component types: thin wrappers around :mod:`components.controller.computed_torque`
and :mod:`components.controller.joint_pd`.

Both types read one body of the dynamics (``dynamics.dart``) and drive some of its joints:

| input | shape | unit | description |
|---|---|---|---|
| position | (3,) | m | base link origin, W |
| orientation | (4,) | 1 | q_W_base [x, y, z, w] |
| twist | (6,) | m/s, rad/s | base origin's linear velocity, then angular velocity, W axes |
| q | (n,) | rad or m | every non-fixed joint of the URDF, file order (locked ones included) |
| qd | (n,) | rad/s or m/s | their rates |

Connect them as ``controller.q: dynamics.<body>.q`` etc. and ``dynamics.<body>.tau: controller.tau``.
``tau`` covers the same n joints; joints the controller does not drive get zero.

Time: ``do_step(t, h)`` reads the state measured at t (in a Jacobi run, the dynamics' output of
the previous step) and returns the torque to apply from t + h on: the loop has one step of delay,
as a sampled controller. The diagnostic outputs (``ee_*``, ``sigma_min``, ``q_desired``) describe
that measured state at t and the reference at t.
"""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from components.constants import NS_PER_S
from components.errors import ConfigError
from components.rotations import continuous
from components.sdk import Component, Parameter, Variable


# --------------------------------------------------------------------------- shared helpers

def _urdf(params: Mapping[str, Any]):
    """The parsed URDF of ``params['urdf']``: absolute, else relative to the config file, else to
    the project root (as ``dynamics.dart`` resolves it); ConfigError naming ``urdf``."""
    from components.dynamics.component import resolve_urdf
    from components.dynamics.urdf import UrdfError, read_urdf

    path = resolve_urdf(params["urdf"], params.get("_config_dir"), "urdf")
    try:
        return read_urdf(path)
    except UrdfError as e:
        raise ConfigError("urdf", str(e)) from None


def _names(value: Any, key: str, allowed: list[str], what: str) -> list[str]:
    """A list of distinct names, each in ``allowed``; ConfigError naming the key otherwise."""
    if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
        raise ConfigError(key, f"expected a list of {what} names, got {value!r}")
    for name in value:
        if name not in allowed:
            raise ConfigError(key, f"{name!r} is not a {what} of the URDF (expected one of: {', '.join(allowed)})")
    duplicates = sorted({v for v in value if list(value).count(v) > 1})
    if duplicates:
        raise ConfigError(key, f"{duplicates[0]!r} listed twice")
    return list(value)


def _gains(value: Any, n: int, key: str, unit: str, each: str = "one per joint") -> np.ndarray:
    """One number (the same for all n), or a list of n numbers (``each`` says what they are); all >= 0."""
    from components.units import to_si

    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        if len(value) != n:
            raise ConfigError(key, f"expected one number or {n} numbers ({each}), got {len(value)}")
        array = np.array([to_si(v, unit, f"{key}[{i}]") for i, v in enumerate(value)])
    else:
        array = np.full(n, to_si(value, unit, key))
    if not np.all(np.isfinite(array)) or np.any(array < 0.0):
        raise ConfigError(key, f"expected finite numbers >= 0, got {array.tolist()}")
    return array


def _state_inputs(n: int) -> list[Variable]:
    return [
        Variable("position", "input", (3,), "m", [0.0, 0.0, 0.0], "base link origin, W"),
        Variable("orientation", "input", (4,), "1", [0.0, 0.0, 0.0, 1.0], "q_W_base [x, y, z, w]"),
        Variable("twist", "input", (6,), "m/s, rad/s", [0.0] * 6,
                 "base origin linear velocity, then angular velocity, W axes"),
        Variable("q", "input", (n,), "rad", [0.0] * n, "joint positions, every non-fixed URDF joint, file order"),
        Variable("qd", "input", (n,), "rad/s", [0.0] * n, "joint rates, same layout as q"),
    ]


def _kinematic_chain(model, end_effector: str) -> list:
    """URDF joints from the root link down to ``end_effector`` (root first)."""
    by_child = {j.child: j for j in model.joints}
    chain, link = [], end_effector
    while link in by_child:
        joint = by_child[link]
        chain.append(joint)
        link = joint.parent
    return chain[::-1]


# --------------------------------------------------------------------------- computed torque

TASK_AXES = "x, y, z, rotation about x, y, z"
QUATERNION_OUTPUTS = ("ee_orientation", "ee_orientation_desired")

class ComputedTorqueComponent(Component):
    """Computed-torque control of one arm of a free-floating body with the Generalized Jacobian
    (type ``controller.computed_torque``; paper eqs. 1-8, see
    :mod:`components.controller.computed_torque` for the derivation).

    The end effector follows a Cartesian trajectory anchored at its pose measured at
    ``initialize`` (see :mod:`components.controller.trajectory`): ``{type: hold}`` (default),
    ``{type: parabola, start, duration, displacement, height}`` (the paper's move) or
    ``{type: waypoints, waypoints: [{time, position, rotation}, ...]}``. Its model is the URDF on
    a free flyer (Pinocchio); list the dynamics' ``locked_joints`` of the body here too (they are
    welded at the position measured at ``initialize``). Joints neither driven nor locked are
    modelled as passive (zero torque).

    | parameter | kind | unit | default | description |
    |---|---|---|---|---|
    | urdf | str | - | required | the body's URDF (relative to the config file, else to the project root) |
    | joints | any | - | required | names of the driven joints (the arm) |
    | end_effector | str | - | required | link (frame) name of the end effector |
    | locked_joints | any | - | [] | joints welded in the dynamics (same list as there) |
    | kp | any | 1/s^2 | 100 | K_p: one number for all six axes, or one per axis: x, y, z, then rotation about x, y, z (W) |
    | kd | any | 1/s | 20 | K_d: one number for all six axes, or one per axis |
    | null_kp | any | 1/s^2 | 4 | null-space posture stiffness, one number or one per joint |
    | null_kd | any | 1/s | 4 | null-space joint damping, one number or one per joint |
    | dls_threshold | float | - | 0.02 | sigma_min(J_g) below which J_g^+ is damped |
    | dls_damping | float | - | 0.05 | damping lambda at sigma_min = 0 |
    | base_model | str | - | free_floating | free_floating (paper) or fixed (ignores the base reaction) |
    | trajectory | any | - | {type: hold} | end-effector trajectory (see above) |

    | variable | causality | shape | unit | description |
    |---|---|---|---|---|
    | position, orientation, twist, q, qd | input | | | the body's state (module table) |
    | tau | output | (n,) | N m | joint torques, zero on joints not driven, clipped to URDF efforts |
    | ee_position | output | (3,) | m | end-effector frame origin, W |
    | ee_position_desired | output | (3,) | m | its reference, W |
    | ee_error | output | (6,) | m, rad | (p_d - p, log(R_d R^T)): position then orientation error, W |
    | ee_orientation | output | (4,) | 1 | q_W_ee [x, y, z, w], sign continuous from step to step |
    | ee_orientation_desired | output | (4,) | 1 | its reference |
    | ee_twist | output | (6,) | m/s, rad/s | end-effector linear and angular velocity, W |
    | sigma_min | output | () | - | smallest singular value of J_g (of J_m for base_model fixed) |

    The anchor is the state seen at ``initialize``; should the first step see another state (the
    controller was initialized before the dynamics it reads, e.g. listed first in a cycle), the
    controller re-anchors there. After a same-type swap, ``set_state`` hands the anchor over.

    Errors: unknown joint or end-effector names, gains of the wrong length, a trajectory the
    arm cannot reach -> ConfigError naming the key (the reach is checked against the URDF in
    ``orchestrator check`` and against the measured initial pose at ``initialize``). A joint of
    ``locked_joints`` that moves (not locked in the dynamics) stops the run with a message.
    """
    type_name = "controller.computed_torque"
    parameters = (
        Parameter("urdf", "str", description="the body's URDF, relative to the config file"),
        Parameter("joints", "any", description="names of the driven joints (the arm), e.g. [arm_right_1_joint, ...]"),
        Parameter("end_effector", "str", description="link (frame) name of the end effector"),
        Parameter("locked_joints", "any", default=(), description="joints welded in the dynamics (same list)"),
        Parameter("kp", "any", default=100.0,
                  description="K_p (1/s^2), one for all six axes or per axis: x, y, z, rotation x, y, z"),
        Parameter("kd", "any", default=20.0,
                  description="K_d (1/s), one for all six axes or per axis: x, y, z, rotation x, y, z"),
        Parameter("null_kp", "any", default=4.0, description="null-space posture stiffness (1/s^2), one or per joint"),
        Parameter("null_kd", "any", default=4.0, description="null-space joint damping (1/s), one or per joint"),
        Parameter("dls_threshold", "float", unit="1", default=0.02,
                  description="sigma_min(J_g) below which the pseudo-inverse is damped"),
        Parameter("dls_damping", "float", unit="1", default=0.05, description="damping at sigma_min = 0"),
        Parameter("base_model", "str", default="free_floating", choices=("free_floating", "fixed"),
                  description="free_floating (Generalized Jacobian) or fixed (ignores the base reaction)"),
        Parameter("trajectory", "any", default=None, description="end-effector trajectory: hold | parabola | waypoints"),
    )

    @classmethod
    def _checked(cls, params) -> dict:
        """Everything validate establishes, for __init__ too."""
        from components.controller.trajectory import max_offset, parse_cartesian

        model = _urdf(params)
        movable = model.movable_joints
        joints = _names(params["joints"], "joints", movable, "movable joint")
        if not joints:
            raise ConfigError("joints", "expected at least one joint name, got an empty list")
        locked = _names(list(params["locked_joints"] or []), "locked_joints", movable, "movable joint")
        both = [j for j in joints if j in locked]
        if both:
            raise ConfigError("locked_joints", f"{both[0]!r} is also in joints: a driven joint cannot be locked")
        ee = params["end_effector"]
        if ee not in model.link_names:
            raise ConfigError("end_effector", f"{ee!r} is not a link of {model.path.name} "
                                              f"(links: {', '.join(model.link_names)})")
        chain = _kinematic_chain(model, ee)
        if not chain:
            raise ConfigError("end_effector", f"{ee!r} is the base link: expected a link the joints move")
        names = [j.name for j in chain]
        for j in joints:
            if j not in names:
                raise ConfigError("joints", f"{j!r} does not move end_effector {ee!r} (its chain: "
                                            f"{', '.join(n for n in names if n in movable)})")
        first = min(names.index(j) for j in joints)
        reach = float(sum(math.sqrt(sum(x * x for x in j.xyz)) for j in chain[first + 1:]))
        n = len(joints)
        for key in ("dls_threshold", "dls_damping"):
            if not (params[key] >= 0.0 and math.isfinite(params[key])):
                raise ConfigError(key, f"expected a finite number >= 0, got {params[key]}")
        trajectory = parse_cartesian(params["trajectory"])
        key, size = max_offset(trajectory)
        if size > 2.0 * reach:
            raise ConfigError(f"trajectory.{key}", f"out of reach: {size:.3f} m from the initial end-effector "
                                                   f"position, the arm spans at most {2 * reach:.3f} m")
        return {"model": model, "joints": joints, "locked": locked, "trajectory": trajectory,
                "kp": _gains(params["kp"], 6, "kp", "1/s^2", TASK_AXES),
                "kd": _gains(params["kd"], 6, "kd", "1/s", TASK_AXES),
                "null_kp": _gains(params["null_kp"], n, "null_kp", "1/s^2"),
                "null_kd": _gains(params["null_kd"], n, "null_kd", "1/s"),
                "reach": (chain[first].name, reach)}

    @classmethod
    def validate(cls, params):
        cls._checked(params)

    @classmethod
    def declare(cls, params):
        n = len(_urdf(params).movable_joints)
        return _state_inputs(n) + [
            Variable("tau", "output", (n,), "N*m", [0.0] * n, "joint torques, zero on joints not driven"),
            Variable("ee_position", "output", (3,), "m", [0.0] * 3, "end-effector frame origin, W"),
            Variable("ee_position_desired", "output", (3,), "m", [0.0] * 3, "its reference, W"),
            Variable("ee_error", "output", (6,), "m, rad", [0.0] * 6,
                     "position error p_d - p (m), then orientation error log(R_d R^T) (rad), W"),
            Variable("ee_orientation", "output", (4,), "1", [0.0, 0.0, 0.0, 1.0], "q_W_ee [x, y, z, w]"),
            Variable("ee_orientation_desired", "output", (4,), "1", [0.0, 0.0, 0.0, 1.0], "its reference"),
            Variable("ee_twist", "output", (6,), "m/s, rad/s", [0.0] * 6,
                     "end-effector linear then angular velocity, W"),
            Variable("sigma_min", "output", (), "1", 0.0, "smallest singular value of the (generalized) Jacobian"),
        ]

    def __init__(self, params):
        super().__init__(params)
        self.checked = self._checked(params)
        self.controller = None
        self._initial_inputs = None
        self.last_quaternions: dict[str, np.ndarray] = {}

    def _build(self, q: np.ndarray):
        from components.controller.computed_torque import ArmController, ComputedTorqueLaw, FreeFloatingArm

        c, p = self.checked, self.params
        model = c["model"]
        body = model.movable_joints
        locked = {j: float(q[body.index(j)]) for j in c["locked"]}
        arm = FreeFloatingArm(model.path, body, c["joints"], p["end_effector"], locked)
        effort = np.array([model.joint(j).effort for j in c["joints"]])
        law = ComputedTorqueLaw(c["kp"], c["kd"], c["null_kp"], c["null_kd"], effort,
                                dls_threshold=p["dls_threshold"], dls_damping=p["dls_damping"],
                                base_model=p["base_model"])
        return ArmController(arm, law, c["trajectory"], reach=c["reach"])

    def _continuous(self, out: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The output quaternions' signs continued from the last step's."""
        for key in QUATERNION_OUTPUTS:
            out[key] = self.last_quaternions[key] = continuous(out[key], self.last_quaternions.get(key))
        return out

    def initialize(self, t0_ns, inputs):
        self.controller = self._build(np.asarray(inputs["q"], dtype=float))
        self.controller.start(inputs)
        # an unsampled state (the dynamics comes later in config order and holds its start values,
        # or a harness said nothing): re-anchor at the first state stepped from, if it differs
        sampled = "q" in self.input_times_ns
        self._initial_inputs = None if sampled else {k: np.array(v, dtype=float) for k, v in inputs.items()}
        self.last_quaternions = {}
        return self._continuous(self.controller.step(t0_ns / NS_PER_S, inputs))

    def do_step(self, t_ns, h_ns, inputs):
        if self._initial_inputs is not None:
            # initialized before the dynamics it reads (config order): anchor at the first real state
            if any(not np.array_equal(inputs[k], v) for k, v in self._initial_inputs.items()):
                self.controller = self._build(np.asarray(inputs["q"], dtype=float))
                self.controller.start(inputs)
            self._initial_inputs = None
        # the reference at the time the state was sampled (t_(k+1) under Gauss-Seidel): like with like
        t_state = self.input_times_ns.get("q", t_ns)
        return self._continuous(self.controller.step(t_state / NS_PER_S, inputs))

    def get_state(self):
        if self.controller is None:
            raise RuntimeError("get_state before initialize: the trajectory is not anchored yet")
        p0, R0, Rb = self.controller.anchor
        return {"ee_position_0": p0.copy(), "ee_rotation_0": R0.ravel().copy(), "base_rotation_0": Rb.ravel().copy(),
                "q_posture": self.controller.q_posture.copy(),
                **{f"last_{k}": q.copy() for k, q in self.last_quaternions.items()}}

    def set_state(self, state):
        for key, size in (("ee_position_0", 3), ("ee_rotation_0", 9), ("base_rotation_0", 9),
                          ("q_posture", self.controller.arm.n)):
            if key not in state or np.asarray(state[key]).size != size:
                raise ValueError(f"state: {key} expected {size} values, got "
                                 f"{None if key not in state else np.asarray(state[key]).size}")
        self._initial_inputs = None
        self.last_quaternions = {k: np.array(state[f"last_{k}"], dtype=float) for k in QUATERNION_OUTPUTS
                                 if f"last_{k}" in state}
        self.controller.restore(np.asarray(state["ee_position_0"], float),
                                np.asarray(state["ee_rotation_0"], float).reshape(3, 3),
                                np.asarray(state["base_rotation_0"], float).reshape(3, 3),
                                np.asarray(state["q_posture"], float))


# --------------------------------------------------------------------------- joint PID

class JointPDComponent(Component):
    """Per-joint PID on effort, like ros_control's effort_controllers/JointPositionController
    (type ``controller.joint_pd``; law in :mod:`components.controller.joint_pd`).

    Each joint named in ``gains`` is driven towards a fixed position (``targets``; a joint not
    named there holds the position measured at ``initialize``) or along a joint-space
    ``trajectory`` of waypoints, reached one after the other on rest-to-rest quintic segments that
    start from those positions at ``trajectory.start``. Torques saturate at the URDF effort limits.

        gains: {arm_right_4_joint: {p: 20, i: 0.5, d: 2, i_clamp: 1}, ...}
        targets: {arm_right_4_joint: -1.2}
        trajectory: {start: 1 s, waypoints: [{time: 4 s, q: {arm_right_4_joint: -0.8}}, ...]}

    | parameter | kind | unit | default | description |
    |---|---|---|---|---|
    | urdf | str | - | required | the body's URDF (relative to the config file, else to the project root) |
    | gains | any | - | required | joint -> {p (N m/rad), i (N m/(rad s), default 0), d (N m s/rad, default 0), i_clamp (N m, default the URDF effort)} |
    | targets | any | rad (m) | {} | joint -> fixed target position (within the URDF limits) |
    | trajectory | any | - | null | {start (s, default 0), waypoints: [{time (s), q: {joint: position}}, ...]}; joints not named keep their previous value |

    | variable | causality | shape | unit | description |
    |---|---|---|---|---|
    | position, orientation, twist, q, qd | input | | | the body's state (module table; only q, qd are used) |
    | tau | output | (n,) | N m (N) | joint torques, zero on joints not driven |
    | q_desired | output | (n,) | rad (m) | the reference of the driven joints; the measured q elsewhere |
    """
    type_name = "controller.joint_pd"
    parameters = (
        Parameter("urdf", "str", description="the body's URDF, relative to the config file"),
        Parameter("gains", "any", description="joint -> {p, i, d, i_clamp} (ros_control pid style)"),
        Parameter("targets", "any", default=None, description="joint -> fixed target position"),
        Parameter("trajectory", "any", default=None,
                  description="{start, waypoints: [{time, q: {joint: position}}, ...]} joint-space waypoints"),
    )

    @classmethod
    def _checked(cls, params) -> dict:
        from components.units import to_si

        model = _urdf(params)
        movable = model.movable_joints
        gains = params["gains"]
        if not isinstance(gains, Mapping) or not gains:
            raise ConfigError("gains", f"expected a mapping joint -> {{p, i, d, i_clamp}}, got {gains!r}")
        joints = [j for j in movable if j in gains]           # URDF order
        for name, g in gains.items():
            key = f"gains.{name}"
            if name not in movable:
                raise ConfigError(key, f"{name!r} is not a movable joint of {model.path.name} "
                                       f"(expected one of: {', '.join(movable)})")
            if not isinstance(g, Mapping):
                raise ConfigError(key, f"expected a mapping {{p, i, d, i_clamp}}, got {g!r}")
            unknown = sorted(set(g) - {"p", "i", "d", "i_clamp"})
            if unknown:
                raise ConfigError(f"{key}.{unknown[0]}", "unknown gain (known: p, i, d, i_clamp)")
            if "p" not in g:
                raise ConfigError(f"{key}.p", "missing: the proportional gain")
        units = {"p": "N*m/rad", "i": "N*m/rad/s", "d": "N*m*s/rad", "i_clamp": "N*m"}
        table = {k: np.zeros(len(joints)) for k in units}
        for k, name in enumerate(joints):
            effort = model.joint(name).effort
            for gain, unit in units.items():
                key = f"gains.{name}.{gain}"
                default = effort if gain == "i_clamp" else 0.0
                value = to_si(gains[name].get(gain, default), unit, key)
                if not (value >= 0.0) or (gain != "i_clamp" and not np.isfinite(value)):
                    raise ConfigError(key, f"expected a finite number >= 0, got {gains[name].get(gain)!r}")
                table[gain][k] = value

        def positions(mapping, key: str) -> dict[str, float]:
            if mapping is None:
                return {}
            if not isinstance(mapping, Mapping):
                raise ConfigError(key, f"expected a mapping joint -> position, got {mapping!r}")
            out = {}
            for name, value in mapping.items():
                if name not in joints:
                    raise ConfigError(f"{key}.{name}", f"{name!r} is not a driven joint (the joints in gains: "
                                                       f"{', '.join(joints)})")
                j = model.joint(name)
                x = to_si(value, "rad" if j.type != "prismatic" else "m", f"{key}.{name}")
                if not (j.lower - 1e-9 <= x <= j.upper + 1e-9):
                    raise ConfigError(f"{key}.{name}", f"expected within the URDF limits [{j.lower}, {j.upper}], got {x}")
                out[name] = x
            return out

        targets = positions(params["targets"], "targets")
        trajectory = None
        spec = params["trajectory"]
        if spec is not None:
            if not isinstance(spec, Mapping):
                raise ConfigError("trajectory", f"expected a mapping {{start, waypoints}}, got {spec!r}")
            unknown = sorted(set(spec) - {"start", "waypoints"})
            if unknown:
                raise ConfigError(f"trajectory.{unknown[0]}", "unknown key (known: start, waypoints)")
            start = to_si(spec.get("start", 0.0), "s", "trajectory.start")
            if not start >= 0.0:
                raise ConfigError("trajectory.start", f"expected a time >= 0 s, got {start}")
            points = spec.get("waypoints")
            if not isinstance(points, (list, tuple)) or not points:
                raise ConfigError("trajectory.waypoints", f"expected a non-empty list of {{time, q}}, got {points!r}")
            times, qs, previous = [], [], start
            for i, point in enumerate(points):
                key = f"trajectory.waypoints[{i}]"
                if not isinstance(point, Mapping) or set(point) - {"time", "q"} or "time" not in point:
                    raise ConfigError(key, f"expected a mapping {{time, q: {{joint: position}}}}, got {point!r}")
                t = to_si(point["time"], "s", f"{key}.time")
                if not t > previous:
                    raise ConfigError(f"{key}.time", f"expected a time after {previous:g} s, got {t:g} s")
                previous = t
                times.append(t)
                qs.append(positions(point.get("q"), f"{key}.q"))
            trajectory = {"start": start, "times": times, "q": qs}
        return {"model": model, "joints": joints, "targets": targets, "trajectory": trajectory,
                "gains": table, "effort": np.array([model.joint(j).effort for j in joints])}

    @classmethod
    def validate(cls, params):
        cls._checked(params)

    @classmethod
    def declare(cls, params):
        n = len(_urdf(params).movable_joints)
        return _state_inputs(n) + [
            Variable("tau", "output", (n,), "N*m", [0.0] * n, "joint torques, zero on joints not driven"),
            Variable("q_desired", "output", (n,), "rad", [0.0] * n,
                     "reference of the driven joints; the measured q elsewhere"),
        ]

    def __init__(self, params):
        from components.controller.joint_pd import JointPID, PidGains

        super().__init__(params)
        c = self.checked = self._checked(params)
        body = c["model"].movable_joints
        self.index = np.array([body.index(j) for j in c["joints"]])
        self.n = len(body)
        g = c["gains"]
        self.pid = JointPID(PidGains(g["p"], g["i"], g["d"], g["i_clamp"]), c["effort"])
        self.q_start = np.zeros(len(c["joints"]))
        self.reference = None

    def _build_reference(self):
        from components.controller.trajectory import JointWaypoints

        c = self.checked
        spec = c["trajectory"]
        if spec is None:
            return JointWaypoints(self.q_start, 0.0, [], [])
        targets, current = [], self.q_start.copy()
        for mapping in spec["q"]:
            for name, value in mapping.items():
                current[c["joints"].index(name)] = value
            targets.append(current.copy())
        return JointWaypoints(self.q_start, spec["start"], spec["times"], targets)

    def _outputs(self, t: float, dt: float, inputs) -> dict[str, np.ndarray]:
        q, qd = np.asarray(inputs["q"], dtype=float), np.asarray(inputs["qd"], dtype=float)
        q_d, qd_d, _ = self.reference.sample(t)
        tau = np.zeros(self.n)
        tau[self.index] = self.pid.torque(q_d, qd_d, q[self.index], qd[self.index], dt)
        q_desired = q.copy()
        q_desired[self.index] = q_d
        return {"tau": tau, "q_desired": q_desired}

    def initialize(self, t0_ns, inputs):
        c = self.checked
        self.q_start = np.asarray(inputs["q"], dtype=float)[self.index].copy()
        for name, value in c["targets"].items():
            self.q_start[c["joints"].index(name)] = value
        self.reference = self._build_reference()
        return self._outputs(t0_ns / NS_PER_S, 0.0, inputs)

    def do_step(self, t_ns, h_ns, inputs):
        return self._outputs(t_ns / NS_PER_S, h_ns / NS_PER_S, inputs)

    def get_state(self):
        return {"i_term": self.pid.i_term.copy(), "q_start": self.q_start.copy()}

    def set_state(self, state):
        for key in ("i_term", "q_start"):
            if key not in state or np.asarray(state[key]).size != self.index.size:
                raise ValueError(f"state: {key} expected {self.index.size} values")
        self.pid.i_term = np.asarray(state["i_term"], dtype=float).copy()
        self.q_start = np.asarray(state["q_start"], dtype=float).copy()
        self.reference = self._build_reference()
