"""The ``controller.joint_pd`` component type: a thin wrapper around
:mod:`components.controller.joint_pd` (the law), on one body of the dynamics
(:mod:`components.controller.body_loop`: its connections).

Time: ``do_step(t, h)`` reads the state measured at t (in a Jacobi run, the dynamics' output of
the previous step) and returns the torque to apply from t + h on: the loop has one step of delay,
as a sampled controller. ``q_desired`` is the reference at t.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from components.constants import NS_PER_S
from components.controller import plots as controller_plots
from components.controller.body_loop import check_names, loop_signals, read_body_urdf
from components.controller.view import ControllerView
from components.errors import ConfigError
from components.robots.model import JOINT_VALUE, joint_units
from components.schema import Float, ListOf, MapOf, Record
from components.sdk import Component, Parameter, Variable

if TYPE_CHECKING:
    from components.controller.trajectory import JointWaypoints

PID_GAINS = Record(
    "PID gains",
    (
        Parameter(
            "p",
            Float("N*m/rad", minimum=0.0, plausible=(0.0, 1e6)),
            description="proportional gain (N/m for prismatic)",
        ),
        Parameter("i", Float("N*m/rad/s", minimum=0.0, plausible=(0.0, 1e6)), default=0.0, description="integral gain"),
        Parameter(
            "d", Float("N*m*s/rad", minimum=0.0, plausible=(0.0, 1e5)), default=0.0, description="derivative gain"
        ),
        Parameter(
            "i_clamp",
            Float("N*m", minimum=0.0, plausible=(0.0, 1e5)),
            default=None,
            description="bound of the integral term's torque (default: the URDF effort)",
        ),
    ),
    description="one joint's gains (``gains.<joint>``, ros_control pid style)",
)
JOINT_TRAJECTORY = Record(
    "Joint trajectory",
    (
        Parameter("start", Float("s", minimum=0.0), default=0.0, description="time the first segment starts"),
        Parameter(
            "waypoints",
            ListOf(
                Record(
                    "Joint waypoint",
                    (
                        Parameter(
                            "time",
                            Float("s"),
                            description="the run time (s from t = 0, not from the previous waypoint) at which it is reached; later than the previous one (or start)",
                        ),
                        Parameter(
                            "q",
                            MapOf(JOINT_VALUE, "joint"),
                            default={},
                            description="positions of driven joints; joints not named keep their previous value",
                        ),
                    ),
                    description="one waypoint of a joint trajectory",
                ),
                min_items=1,
            ),
            description="reached one after the other",
        ),
    ),
    description="rest-to-rest quintic segments from the initial positions through waypoints",
)


@dataclass(frozen=True)
class JointSetup:
    """The joint PID parameters checked against the URDF: the driven joints in URDF order, the
    gains per joint (arrays by p, i, d, i_clamp), the targets and trajectory in SI; ``checked``:
    the parameters they come from."""

    checked: Mapping[str, Any]
    model: Any
    joints: list[str]
    targets: dict[str, float]
    trajectory: dict | None
    gains: dict[str, np.ndarray]
    effort: np.ndarray


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

    Outputs: ``tau`` (zero on joints not driven) and ``q_desired`` (the reference of the driven
    joints, the measured q elsewhere).

    State (``get_state``): the integral terms and the start positions of the reference (the q
    measured at ``initialize``, targets applied); ``set_state`` rebuilds the reference from them,
    on a fresh instance too (no ``initialize``).
    """

    type_name = "controller.joint_pd"
    plots = (controller_plots.TORQUES, controller_plots.JOINTS)
    view = ControllerView
    parameters = (
        Parameter("urdf", "str", description="the body's URDF, relative to the config file"),
        Parameter("gains", MapOf(PID_GAINS, "joint", min_items=1), description="the driven joints and their gains"),
        Parameter(
            "targets",
            MapOf(JOINT_VALUE, "joint"),
            default={},
            description="fixed target positions (rad, m for prismatic); a joint not named holds its initial q",
        ),
        Parameter(
            "trajectory", JOINT_TRAJECTORY, default=None, description="joint-space waypoints (instead of targets)"
        ),
    )

    @classmethod
    def validate(cls, params, run) -> JointSetup:
        """What the parameters mean for this URDF, checked."""
        model = read_body_urdf(params, run)
        movable = model.movable_joints
        gains = params["gains"]
        for name in gains:
            check_names([name], f"gains.{name}", movable, "movable joint")
        joints = [j for j in movable if j in gains]  # URDF order
        table = {
            k: np.array([gains[j][k] if gains[j][k] is not None else model.joint(j).effort for j in joints])
            for k in ("p", "i", "d", "i_clamp")
        }

        def positions(mapping: Mapping[str, float], key: str) -> dict[str, float]:
            for name, x in mapping.items():
                if name not in joints:
                    raise ConfigError(
                        f"{key}.{name}", f"{name!r} is not a driven joint (the joints in gains: {', '.join(joints)})"
                    )
                j = model.joint(name)
                if not (j.lower - 1e-9 <= x <= j.upper + 1e-9):
                    raise ConfigError(
                        f"{key}.{name}", f"expected within the URDF limits [{j.lower}, {j.upper}], got {x}"
                    )
            return dict(mapping)

        targets = positions(params["targets"], "targets")
        trajectory = params["trajectory"]
        if trajectory is not None:
            previous = trajectory["start"]
            for i, point in enumerate(trajectory["waypoints"]):
                key = f"trajectory.waypoints[{i}]"
                if not point["time"] > previous:
                    raise ConfigError(f"{key}.time", f"expected a time after {previous:g} s, got {point['time']:g} s")
                previous = point["time"]
                positions(point["q"], f"{key}.q")
        return JointSetup(
            checked=params,
            model=model,
            joints=joints,
            targets=targets,
            trajectory=trajectory,
            gains=table,
            effort=np.array([model.joint(j).effort for j in joints]),
        )

    @classmethod
    def declare(cls, params, run):
        model = params.model
        n = len(model.movable_joints)
        return loop_signals(model) + [
            Variable(
                "q_desired",
                "output",
                (n,),
                joint_units(model)[0],
                [0.0] * n,
                "reference of the driven joints; the measured q elsewhere",
            ),
        ]

    def __init__(self, params, run):
        from components.controller.joint_pd import JointPID, PidGains

        super().__init__(params.checked, run)
        c = self.joints = params
        body = c.model.movable_joints
        self.index = np.array([body.index(j) for j in c.joints])
        self.n = len(body)
        g = c.gains
        self.pid = JointPID(PidGains(g["p"], g["i"], g["d"], g["i_clamp"]), c.effort)
        self.q_start = np.zeros(len(c.joints))
        self.reference: JointWaypoints | None = None

    def _build_reference(self) -> JointWaypoints:
        from components.controller.trajectory import JointWaypoints

        spec = self.joints.trajectory
        if spec is None:
            return JointWaypoints(self.q_start, 0.0, [], [])
        targets, current = [], self.q_start.copy()
        for point in spec["waypoints"]:
            for name, value in point["q"].items():
                current[self.joints.joints.index(name)] = value
            targets.append(current.copy())
        return JointWaypoints(self.q_start, spec["start"], [p["time"] for p in spec["waypoints"]], targets)

    def _outputs(self, t: float, dt: float, inputs) -> dict[str, np.ndarray]:
        q, qd = np.asarray(inputs["q"], dtype=float), np.asarray(inputs["qd"], dtype=float)
        assert self.reference is not None, "initialize or set_state comes first"
        q_d, qd_d, _ = self.reference.sample(t)
        tau = np.zeros(self.n)
        tau[self.index] = self.pid.torque(q_d, qd_d, q[self.index], qd[self.index], dt)
        q_desired = q.copy()
        q_desired[self.index] = q_d
        return {"tau": tau, "q_desired": q_desired}

    def initialize(self, t0_ns, inputs):
        c = self.joints
        self.q_start = np.asarray(inputs["q"], dtype=float)[self.index].copy()
        for name, value in c.targets.items():
            self.q_start[c.joints.index(name)] = value
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
