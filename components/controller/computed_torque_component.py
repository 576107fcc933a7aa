"""The ``controller.computed_torque`` component type: a thin wrapper around
:mod:`components.controller.computed_torque` (the law) and
:mod:`components.controller.free_floating_arm` (the model), on one body of the dynamics
(:mod:`components.controller.body_loop`: its connections).

Time: ``do_step(t, h)`` reads the state measured at t (in a Jacobi run, the dynamics' output of
the previous step) and returns the torque to apply from t + h on: the loop has one step of delay,
as a sampled controller. The diagnostic outputs (``ee_*``, ``sigma_min``) describe that measured
state at t and the reference at t.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from components.constants import NS_PER_S
from components.controller import plots as controller_plots
from components.controller.body_loop import check_names, loop_signals, read_body_urdf
from components.controller.gains import CARTESIAN_GAINS, TASK_AXES, per_item
from components.controller.trajectory import CARTESIAN
from components.controller.view import ControllerView
from components.errors import ConfigError
from components.robots.model import arm_reach
from components.rotations import continuous
from components.schema import ListOf, Str
from components.sdk import Component, Parameter, Variable

if TYPE_CHECKING:
    from components.controller.computed_torque import ArmController


@dataclass(frozen=True)
class ArmSetup:
    """The computed-torque parameters checked against the URDF: the arm's joints in the
    config's order, the gains one per axis (6) or per joint, the trajectory in SI (parse_cartesian)
    and the reach (first moving joint, m) the trajectory was checked against; ``checked``: the
    parameters they come from."""

    checked: Mapping[str, Any]
    model: Any
    joints: list[str]
    locked: list[str]
    trajectory: dict
    kp: np.ndarray
    kd: np.ndarray
    null_kp: np.ndarray
    null_kd: np.ndarray
    reach: tuple[str, float]


QUATERNION_OUTPUTS = ("ee_orientation", "ee_orientation_desired")
INITIAL = "initial."  # state keys of the inputs seen at an unsampled initialize, until the first step


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

    Outputs: ``tau`` (zero on joints not driven, clipped to the URDF efforts), the end effector's
    pose, reference, error and twist (``ee_*``) and ``sigma_min``; ``describe`` lists them.

    The anchor is the state seen at ``initialize``; should the first step see another state (the
    controller was initialized before the dynamics it reads, e.g. listed first in a cycle), the
    controller re-anchors there.

    State (``get_state``): the anchor (end-effector pose and base rotation at the anchoring),
    the null-space posture, the positions the locked joints are welded at, the last output
    quaternions (their signs continue) and, between an unsampled ``initialize`` and the first
    step, the inputs seen there. ``set_state`` on a fresh instance (a swap or a restart: no
    ``initialize``) rebuilds the model and the trajectory from it; it neither re-anchors nor
    re-checks the reach, so the continuation is bit for bit.

    Errors: unknown joint or end-effector names, gains of the wrong length, a trajectory the
    arm cannot reach -> ConfigError naming the key (the reach is checked against the URDF in
    ``orchestrator check`` and against the measured initial pose at ``initialize``). A joint of
    ``locked_joints`` that moves (not locked in the dynamics) stops the run with a message.
    """

    type_name = "controller.computed_torque"
    plots = (controller_plots.PATH, controller_plots.ERROR, controller_plots.TORQUES, controller_plots.BASE)
    view = ControllerView
    parameters = (
        Parameter("urdf", "str", description="the body's URDF, relative to the config file"),
        Parameter(
            "joints",
            ListOf(Str(), min_items=1, unique=True),
            description="names of the driven joints (the arm), e.g. [arm_right_1_joint, ...]",
        ),
        Parameter("end_effector", "str", description="link (frame) name of the end effector"),
        Parameter(
            "locked_joints",
            ListOf(Str(), unique=True),
            default=[],
            description="joints welded in the dynamics (the same list as there)",
        ),
        *CARTESIAN_GAINS,
        Parameter(
            "base_model",
            "str",
            default="free_floating",
            choices=("free_floating", "fixed"),
            description="free_floating (Generalized Jacobian) or fixed (ignores the base reaction)",
        ),
        Parameter(
            "trajectory",
            CARTESIAN,
            default={"type": "hold"},
            description="end-effector trajectory, anchored at the pose measured at initialize",
        ),
    )

    @classmethod
    def validate(cls, params, run) -> ArmSetup:
        """What the parameters mean for this URDF, checked."""
        from components.controller.trajectory import max_offset, parse_cartesian

        model = read_body_urdf(params, run)
        movable = model.movable_joints
        joints = check_names(params["joints"], "joints", movable, "movable joint")
        locked = check_names(params["locked_joints"], "locked_joints", movable, "movable joint")
        both = [j for j in joints if j in locked]
        if both:
            raise ConfigError("locked_joints", f"{both[0]!r} is also in joints: a driven joint cannot be locked")
        shoulder, reach = arm_reach(model, joints, params["end_effector"])
        n = len(joints)
        trajectory = parse_cartesian(params["trajectory"])
        key, size = max_offset(trajectory)
        if size > 2.0 * reach:
            raise ConfigError(
                f"trajectory.{key}",
                f"out of reach: {size:.3f} m from the initial end-effector "
                f"position, the arm spans at most {2 * reach:.3f} m",
            )
        return ArmSetup(
            checked=params,
            model=model,
            joints=joints,
            locked=locked,
            trajectory=trajectory,
            kp=per_item(params["kp"], 6, "kp", TASK_AXES),
            kd=per_item(params["kd"], 6, "kd", TASK_AXES),
            null_kp=per_item(params["null_kp"], n, "null_kp"),
            null_kd=per_item(params["null_kd"], n, "null_kd"),
            reach=(shoulder, reach),
        )

    @classmethod
    def preflight(cls, params, run, step_s, full=False):
        """``full``: Pinocchio builds the model (mimic joints, locked joints at 0) as at initialize."""
        if full:
            try:
                cls(params, run)._build(np.zeros(len(params.locked)))
            except ValueError as e:
                raise ConfigError("urdf", f"Pinocchio cannot build the controller's model: {e}") from None
        return []

    @classmethod
    def declare(cls, params, run):
        return loop_signals(params.model) + [
            Variable("ee_position", "output", (3,), "m", [0.0] * 3, "end-effector frame origin, W"),
            Variable("ee_position_desired", "output", (3,), "m", [0.0] * 3, "its reference, W"),
            Variable(
                "ee_error",
                "output",
                (6,),
                "m, rad",
                [0.0] * 6,
                "position error p_d - p (m), then orientation error log(R_d R^T) (rad), W",
            ),
            Variable("ee_orientation", "output", (4,), "1", [0.0, 0.0, 0.0, 1.0], "q_W_ee [x, y, z, w]"),
            Variable("ee_orientation_desired", "output", (4,), "1", [0.0, 0.0, 0.0, 1.0], "its reference"),
            Variable(
                "ee_twist", "output", (6,), "m/s, rad/s", [0.0] * 6, "end-effector linear then angular velocity, W"
            ),
            Variable("sigma_min", "output", (), "1", 0.0, "smallest singular value of the (generalized) Jacobian"),
        ]

    def __init__(self, params, run):
        super().__init__(params.checked, run)
        self.arm = params
        self.controller: ArmController | None = None
        self._initial_inputs: dict[str, np.ndarray] | None = None
        self.last_quaternions: dict[str, np.ndarray] = {}

    def _locked_at(self, q: np.ndarray) -> np.ndarray:
        """The positions of ``locked_joints`` (config order) in a measured q of the whole body."""
        body = self.arm.model.movable_joints
        return np.array([float(q[body.index(j)]) for j in self.arm.locked], dtype=np.float64)

    def _build(self, locked_q: np.ndarray) -> ArmController:
        """The controller, its model welded at ``locked_q`` (the positions of ``locked_joints``)."""
        from components.controller.computed_torque import ArmController, ComputedTorqueLaw
        from components.controller.free_floating_arm import FreeFloatingArm

        a, p = self.arm, self.params
        body = a.model.movable_joints
        locked = {j: float(x) for j, x in zip(a.locked, locked_q)}
        arm = FreeFloatingArm(a.model, body, a.joints, p["end_effector"], locked)
        effort = np.array([a.model.joint(j).effort for j in a.joints])
        law = ComputedTorqueLaw(
            a.kp,
            a.kd,
            a.null_kp,
            a.null_kd,
            effort,
            dls_threshold=p["dls_threshold"],
            dls_damping=p["dls_damping"],
            base_model=p["base_model"],
        )
        return ArmController(arm, law, a.trajectory, reach=a.reach)

    def _continuous(self, out: dict[str, np.ndarray | np.float64]) -> dict[str, np.ndarray | np.float64]:
        """The output quaternions' signs continued from the last step's."""
        for key in QUATERNION_OUTPUTS:
            out[key] = self.last_quaternions[key] = continuous(out[key], self.last_quaternions.get(key))
        return out

    def initialize(self, t0_ns, inputs):
        self.controller = self._build(self._locked_at(inputs["q"]))
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
                self.controller = self._build(self._locked_at(inputs["q"]))
                self.controller.start(inputs)
            self._initial_inputs = None
        # the reference at the time the state was sampled (t_(k+1) under Gauss-Seidel): like with like
        t_state = self.input_times_ns.get("q", t_ns)
        assert self.controller is not None, "initialize or set_state comes first"
        return self._continuous(self.controller.step(t_state / NS_PER_S, inputs))

    def get_state(self):
        if self.controller is None:
            raise RuntimeError("get_state before initialize: the trajectory is not anchored yet")
        assert self.controller.anchor is not None  # both start and restore anchor it
        p0, R0, Rb = self.controller.anchor
        locked = self.controller.arm.locked
        state = {
            "ee_position_0": p0.copy(),
            "ee_rotation_0": R0.ravel().copy(),
            "base_rotation_0": Rb.ravel().copy(),
            "q_posture": self.controller.q_posture.copy(),
            "locked_q": np.array([locked[j] for j in self.arm.locked], dtype=np.float64),
            **{f"last_{k}": q.copy() for k, q in self.last_quaternions.items()},
        }
        if self._initial_inputs is not None:  # initialized unsampled, not stepped yet
            state.update({INITIAL + k: v.copy() for k, v in self._initial_inputs.items()})
        return state

    def set_state(self, state):
        """Restore on a fresh instance (``initialize`` is not called): the model welded at the
        locked positions and the trajectory anchored as in the state; no re-anchoring and no reach
        check (both happened once, at the run's ``initialize``)."""
        for key, size in (
            ("ee_position_0", 3),
            ("ee_rotation_0", 9),
            ("base_rotation_0", 9),
            ("q_posture", len(self.arm.joints)),
            ("locked_q", len(self.arm.locked)),
        ):
            if key not in state or np.asarray(state[key]).size != size:
                raise ValueError(
                    f"state: {key} expected {size} values, got "
                    f"{None if key not in state else np.asarray(state[key]).size}"
                )
        self.controller = self._build(np.asarray(state["locked_q"], dtype=float).ravel())
        self.controller.restore(
            np.asarray(state["ee_position_0"], float),
            np.asarray(state["ee_rotation_0"], float).reshape(3, 3),
            np.asarray(state["base_rotation_0"], float).reshape(3, 3),
            np.asarray(state["q_posture"], float),
        )
        self.last_quaternions = {
            k: np.array(state[f"last_{k}"], dtype=float) for k in QUATERNION_OUTPUTS if f"last_{k}" in state
        }
        initial = {k[len(INITIAL) :]: np.array(v, dtype=float) for k, v in state.items() if k.startswith(INITIAL)}
        self._initial_inputs = initial or None
