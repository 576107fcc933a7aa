"""The ``controller.capture`` component type: a thin wrapper around
:mod:`components.controller.capture` (the phases; the estimator, the planner and the laws are in
the modules it names).

Connections (a capture run): the servicer's state from the dynamics (``position``,
``orientation``, ``twist``, ``q``, ``qd`` as for ``controller.computed_torque``), the relative-pose
sensor (``grasp_p``, ``grasp_q``, ``grasp_t``, ``grasp_valid``), the dynamics' ``captured``, the
IMU's ``rate_imu`` and the wrist force-torque sensor's ``wrench``; ``tau`` goes to the dynamics'
``<servicer>.tau`` and ``close`` to whatever closes the grasp.

Time: ``do_step(t, h)`` reads the state measured at t (its sample time, ``input_times_ns``) and
returns the torques to apply from t + h on, as ``controller.computed_torque`` does.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from components.constants import NS_PER_S
from components.controller import plots as controller_plots
from components.controller.gains import CARTESIAN_GAINS, DAMPING, STIFFNESS, TASK_AXES, gain, per_item
from components.controller.view import ControllerView
from components.errors import ConfigError
from components.robots.model import arm_reach, read_model
from components.rotations import rpy_to_matrix
from components.schema import Float, Int, ListOf, Str
from components.sdk import Component, Outcome, Parameter, Variable
from components.signals import BODY_STATE, body_signals, torque_signal
from components.units import DEG


@dataclass(frozen=True)
class CaptureSetup:
    """The parameters checked against the URDF: arm and wheel joints, the wheels' axes in the base
    frame (columns) and limits, the arm's limits, the shoulder and reach, the gains per axis or joint;
    ``checked``: the parameters they come from."""

    checked: Mapping[str, Any]
    model: Any
    joints: list[str]
    wheels: list[str]
    wheel_axes: np.ndarray
    wheel_effort: np.ndarray
    wheel_velocity: np.ndarray
    effort: np.ndarray
    velocity: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    shoulder: str
    reach: float
    kp: np.ndarray
    kd: np.ndarray
    null_kp: np.ndarray
    null_kd: np.ndarray
    hold_kp: np.ndarray
    hold_kd: np.ndarray
    captured_kp: np.ndarray
    captured_kd: np.ndarray


class CaptureComponent(Component):
    """Capture of a tumbling target by a free-floating servicer's arm, then detumbling of the
    assembly with reaction wheels (type ``controller.capture``; issue 23, see
    :mod:`components.controller.capture` for the estimator and the laws).

    From measurements of the target's grasp frame relative to the end effector (delayed: each
    carries its time), it estimates the grasp frame's motion in W (fading-memory least squares
    over the last ``estimator_window`` measurements, the end-effector pose taken at each
    measurement's time), blends the end effector onto the moving grasp frame over
    ``approach_time`` (phase 0), tracks it (phase 1) with the Generalized-Jacobian computed-torque
    law and feed-forward, and sets ``close`` once the estimated errors have stayed within the
    tolerances for ``tolerance_time``. When ``captured`` is 1 (phase 2) the arm holds its joint
    configuration (a joint PD in torque units, ``captured_kp``/``captured_kd``: the target's
    inertia is not in the servicer's model) and the wheels damp the bus rate measured by the IMU,
    within their effort and speed limits and scaled down to keep the wrist wrench within the grasp
    limits. Before the first estimate the arm holds its initial joint configuration.

    A grasp point beyond the arm's reach (from the shoulder, the first joint of ``joints``), or
    one whose following needs joint rates beyond the URDF velocity limits or torques beyond the
    effort limits for longer than ``limit_window``, makes the arm retreat to its posture (a
    ``capture_retreat`` event naming the limit, the figure and the limit) and try the next window;
    after ``attempts`` approaches, ``capture_aborted``. The run goes on either way.

    Outputs: ``tau`` (arm and wheels; zero elsewhere), ``close``, ``phase``, ``grasp_distance``,
    ``ee_error`` (the reference minus the end effector: the blend in approach, the estimated grasp
    frame in track and after capture), the estimated grasp frame's position, velocity and angular
    velocity (W); ``describe`` lists them.

    State (``get_state``): the estimator's measurements and fit, the end-effector pose history,
    the phase, ``close``, the approach's anchor, the hold configurations, the tolerance and limit
    timers and the wheel-torque factor: ``set_state`` on a fresh instance continues bit for bit.
    """

    type_name = "controller.capture"
    plots = (controller_plots.TORQUES, controller_plots.PHASES)
    view = ControllerView
    # the controller's own events: a capture the grasp lost again (capture_retreat) is undecided again
    outcomes = (
        Outcome(
            "undecided",
            "undecided: neither captured nor aborted by {end:g} s",
            ("capture_retreat",),
            "neither captured nor aborted at the end (or the grasp opened again after a capture)",
        ),
        Outcome(
            "captured",
            "captured at {time:g} s",
            ("capture_closed",),
            "the dynamics closed the grasp and it held to the end",
        ),
        Outcome(
            "aborted",
            "capture aborted at {time:g} s: {reason}",
            ("capture_aborted",),
            "the capture was given up (attempts, no window, capture_timeout)",
        ),
    )
    parameters = (
        Parameter("urdf", "str", description="the servicer's URDF, relative to the config file"),
        Parameter(
            "joints",
            ListOf(Str(), min_items=1, unique=True),
            description="the arm's joints (driven), e.g. [arm_1_joint, ..., arm_6_joint]",
        ),
        Parameter(
            "wheels",
            ListOf(Str(), unique=True),
            description="the reaction wheels' joints (continuous joints on the base link), "
            "e.g. [wheel_x_joint, wheel_y_joint, wheel_z_joint]",
        ),
        Parameter(
            "end_effector", "str", description="link whose frame is brought onto the grasp frame (z out of the tool)"
        ),
        Parameter(
            "approach_time",
            Float("s", positive=True, plausible=(0.1, 3600.0)),
            description="duration of the joint-space move onto the pre-grasp pose (and of a retreat)",
        ),
        Parameter(
            "closing_time",
            Float("s", positive=True, plausible=(0.01, 600.0)),
            default=1.0,
            description="duration of the straight-line close from the pre-grasp pose onto the grapple",
        ),
        Parameter(
            "standoff",
            Float("m", minimum=0.0, plausible=(0.0, 10.0)),
            default=0.1,
            description="the pre-grasp pose: the grasp frame moved back this far along its z (out of the target)",
        ),
        Parameter(
            "track_time",
            Float("s", positive=True, plausible=(0.01, 3600.0)),
            default=4.0,
            description="how long tracking may wait for the tolerances before the arm retreats and tries again",
        ),
        Parameter(
            "attempts",
            Int(minimum=1),
            default=3,
            description="approaches before the capture is given up (capture_aborted)",
        ),
        Parameter(
            "capture_timeout",
            Float("s", positive=True, plausible=(0.1, 2.6e6)),
            default=300.0,
            description="time from t = 0 after which a capture not under way is given up (capture_aborted)",
        ),
        Parameter(
            "replan_period",
            Float("s", positive=True, plausible=(1e-3, 600.0)),
            default=0.5,
            description="how often the planner looks for a window while the arm waits",
        ),
        Parameter(
            "singularity_margin",
            Float(positive=True),
            default=0.08,
            description="lowest smallest singular value of the arm's Jacobian (m/rad and 1, W axes) for planning a window and for closing",
        ),
        Parameter(
            "rate_fraction",
            Float(positive=True, maximum=1.0),
            default=0.5,
            description="share of the URDF velocity limits the planner allows for following the grapple",
        ),
        Parameter(
            "joint_margin",
            Float("rad", minimum=0.0, plausible=(0.0, 45 * DEG)),
            default=0.15,
            description="the planner keeps the arm this far inside the URDF position limits",
        ),
        Parameter(
            "position_tolerance",
            Float("m", positive=True, plausible=(0.0, 1.0)),
            description="close when the estimated position error stays below this (and the other tolerances)",
        ),
        Parameter(
            "attitude_tolerance",
            Float("rad", positive=True, plausible=(0.0, 45 * DEG)),
            description="bound of the estimated attitude error angle for closing",
        ),
        Parameter(
            "velocity_tolerance",
            Float("m/s", positive=True, plausible=(0.0, 1.0)),
            description="bound of the estimated relative linear velocity for closing",
        ),
        Parameter(
            "rate_tolerance",
            Float("rad/s", positive=True, plausible=(0.0, 60 * DEG)),
            description="bound of the estimated relative angular velocity for closing",
        ),
        Parameter(
            "tolerance_time",
            Float("s", minimum=0.0, plausible=(0.0, 600.0)),
            description="how long the errors must stay within the tolerances before close goes to 1",
        ),
        Parameter(
            "grasp_force_limit",
            Float("N", positive=True, plausible=(0.1, 1e6)),
            description="bound of the measured wrist force while detumbling (the wheel torques are scaled down)",
        ),
        Parameter(
            "grasp_torque_limit",
            Float("N*m", positive=True, plausible=(0.01, 1e6)),
            description="bound of the measured wrist torque while detumbling",
        ),
        Parameter(
            "detumble_gain",
            Float("N*m*s/rad", minimum=0.0, plausible=(0.0, 1e6)),
            description="bus torque per unit of IMU rate (rate damping) after capture",
        ),
        Parameter(
            "captured_kp",
            gain("N*m/rad", (0.0, 1e6)),
            description="joint stiffness holding the arm after capture (torque units: the target's inertia "
            "is not in the model), one or per arm joint",
        ),
        Parameter(
            "captured_kd",
            gain("N*m*s/rad", (0.0, 1e5)),
            description="joint damping holding the arm after capture, one or per arm joint (stable for "
            "kd * step well below the smallest joint-space inertia of the assembly)",
        ),
        Parameter(
            "wrench_recovery_time",
            Float("s", positive=True, plausible=(1e-3, 600.0)),
            default=2.0,
            description="time for the wheel-torque factor to recover from 0 to 1 once the wrench is within limits",
        ),
        *CARTESIAN_GAINS,
        Parameter(
            "hold_kp",
            gain("1/s^2", STIFFNESS),
            default=25.0,
            description="computed-torque joint hold stiffness before the first estimate, one or per arm joint",
        ),
        Parameter(
            "hold_kd",
            gain("1/s", DAMPING),
            default=10.0,
            description="computed-torque joint hold damping before the first estimate, one or per arm joint",
        ),
        Parameter(
            "estimator_window",
            Int(minimum=3),
            default=10,
            description="measurements in the least-squares fit (the latest)",
        ),
        Parameter(
            "estimator_minimum",
            Int(minimum=3),
            default=None,
            description="measurements before the estimate is first used (the first plan); null: estimator_window. "
            "Fewer plan sooner, more keep the estimate steadier while the arm tracks",
        ),
        Parameter(
            "estimator_memory",
            Float("s", positive=True, plausible=(1e-3, 3600.0)),
            default=0.5,
            description="fading-memory time constant: a measurement tau seconds older weighs exp(-tau/memory)",
        ),
        Parameter(
            "pose_history",
            Float("s", positive=True, plausible=(1e-3, 600.0)),
            default=1.0,
            description="end-effector poses kept by time: the longest measurement latency handled",
        ),
        Parameter(
            "limit_window",
            Float("s", minimum=0.0, plausible=(0.0, 60.0)),
            default=0.2,
            description="how long needed joint rates or torques may exceed the URDF limits before the arm retreats",
        ),
    )

    @classmethod
    def validate(cls, params, run) -> CaptureSetup:
        """What the parameters mean for this URDF, checked."""
        model = read_model(params["urdf"], run.config_dir, "urdf", run.packages)
        movable = model.movable_joints
        for key in ("joints", "wheels"):
            for name in params[key]:
                if name not in movable:
                    raise ConfigError(
                        key, f"{name!r} is not a movable joint of the URDF (expected one of: {', '.join(movable)})"
                    )
        joints, wheels = list(params["joints"]), list(params["wheels"])
        both = [j for j in wheels if j in joints]
        if both:
            raise ConfigError("wheels", f"{both[0]!r} is also in joints")
        shoulder, reach = arm_reach(model, joints, params["end_effector"])
        axes = []
        for name in wheels:
            joint = model.joint(name)
            if joint.type != "continuous" or joint.parent != model.root:
                raise ConfigError(
                    "wheels",
                    f"{name!r} is a {joint.type} joint on {joint.parent!r}: expected a "
                    f"continuous joint on the base link {model.root!r}",
                )
            axes.append(rpy_to_matrix(joint.rpy) @ np.array(joint.axis))
            if not math.isfinite(joint.effort):
                raise ConfigError("wheels", f"{name!r} has no effort limit in the URDF: the wheel torques need one")
        n = len(joints)
        setup = CaptureSetup(
            checked=params,
            model=model,
            joints=joints,
            wheels=wheels,
            wheel_axes=np.array(axes, dtype=float).reshape(-1, 3).T,
            wheel_effort=np.array([model.joint(j).effort for j in wheels]),
            wheel_velocity=np.array([model.joint(j).velocity for j in wheels]),
            effort=np.array([model.joint(j).effort for j in joints]),
            velocity=np.array([model.joint(j).velocity for j in joints]),
            lower=np.array([model.joint(j).lower for j in joints]),
            upper=np.array([model.joint(j).upper for j in joints]),
            shoulder=shoulder,
            reach=reach,
            kp=per_item(params["kp"], 6, "kp", TASK_AXES),
            kd=per_item(params["kd"], 6, "kd", TASK_AXES),
            null_kp=per_item(params["null_kp"], n, "null_kp"),
            null_kd=per_item(params["null_kd"], n, "null_kd"),
            hold_kp=per_item(params["hold_kp"], n, "hold_kp"),
            hold_kd=per_item(params["hold_kd"], n, "hold_kd"),
            captured_kp=per_item(params["captured_kp"], n, "captured_kp"),
            captured_kd=per_item(params["captured_kd"], n, "captured_kd"),
        )
        minimum = params["estimator_minimum"]
        if minimum is not None and minimum > params["estimator_window"]:
            raise ConfigError(
                "estimator_minimum",
                f"expected at most estimator_window = {params['estimator_window']} measurements, got {minimum}",
            )
        return setup

    @classmethod
    def declare(cls, params, run):
        model = params.model
        return body_signals("input", model, names=BODY_STATE) + [
            Variable(
                "grasp_p",
                "input",
                (3,),
                "m",
                [0.0] * 3,
                "measured position of the grasp frame's origin relative to the end effector, EE axes",
            ),
            Variable(
                "grasp_q",
                "input",
                (4,),
                "1",
                [0.0, 0.0, 0.0, 1.0],
                "measured orientation of the grasp frame, q_ee_grasp [x, y, z, w]",
            ),
            Variable("grasp_t", "input", (), "s", -1.0, "time the measurement was taken (it arrives late)"),
            Variable("grasp_valid", "input", (), "1", 0.0, "1 when the measurement is valid, else 0"),
            Variable("captured", "input", (), "1", 0.0, "1 once the grasp holds the target (from the dynamics)"),
            Variable(
                "rate_imu", "input", (3,), "rad/s", [0.0] * 3, "the bus's angular rate measured by the IMU, bus axes"
            ),
            Variable(
                "wrench", "input", (6,), "N, N*m", [0.0] * 6, "wrench measured at the wrist: force then torque, EE axes"
            ),
            torque_signal("output", model, note="arm and wheels; zero on other joints"),
            Variable(
                "close", "output", (), "1", 0.0, "1: close the grasp (the estimated errors stayed within tolerance)"
            ),
            Variable(
                "phase",
                "output",
                (),
                "1",
                0.0,
                "0 wait, 1 approach, 2 closing, 3 track, 4 retreat, 5 captured, 6 aborted",
            ),
            Variable("attempt", "output", (), "1", 0.0, "approaches started so far"),
            Variable(
                "close_errors",
                "output",
                (4,),
                "m, rad, m/s, rad/s",
                [0.0] * 4,
                "estimated errors behind close (closing and track; else 0): position, attitude angle, "
                "linear velocity, angular velocity",
            ),
            Variable(
                "close_within",
                "output",
                (4,),
                "1",
                [0.0] * 4,
                "1 where close_errors is within its tolerance (position, attitude, velocity, rate)",
            ),
            Variable(
                "grasp_distance",
                "output",
                (),
                "m",
                0.0,
                "estimated distance from the end effector to the grasp frame (the last measured one before "
                "the first estimate)",
            ),
            Variable(
                "ee_error",
                "output",
                (6,),
                "m, rad",
                [0.0] * 6,
                "reference minus end effector: position (m), then log(R_ref R_ee^T) (rad), W; the reference "
                "is the blend in approach, the estimated grasp frame after",
            ),
            Variable("grasp_position_est", "output", (3,), "m", [0.0] * 3, "estimated grasp frame origin, W"),
            Variable("grasp_velocity_est", "output", (3,), "m/s", [0.0] * 3, "its estimated velocity, W"),
            Variable(
                "grasp_rate_est", "output", (3,), "rad/s", [0.0] * 3, "estimated angular velocity of the grasp frame, W"
            ),
        ]

    def __init__(self, params, run):
        from components.controller.computed_torque import compile_kernels

        super().__init__(params.checked, run)
        self.config = params
        self.controller = self._build()
        warm = self._build()  # the first control step comes with the approach, seconds into the run
        compile_kernels(warm.arm, warm.law)

    def _build(self):
        from components.controller.capture import CaptureController
        from components.controller.capture_settings import CaptureSettings
        from components.controller.computed_torque import ComputedTorqueLaw
        from components.controller.free_floating_arm import FreeFloatingArm

        c, p = self.config, self.params
        arm = FreeFloatingArm(c.model, c.model.movable_joints, c.joints, p["end_effector"])
        law = ComputedTorqueLaw(
            c.kp, c.kd, c.null_kp, c.null_kd, c.effort, dls_threshold=p["dls_threshold"], dls_damping=p["dls_damping"]
        )
        settings = CaptureSettings(
            approach_time=p["approach_time"],
            closing_time=p["closing_time"],
            standoff=p["standoff"],
            track_time=p["track_time"],
            attempts=p["attempts"],
            capture_timeout=p["capture_timeout"],
            replan_period=p["replan_period"],
            singularity_margin=p["singularity_margin"],
            rate_fraction=p["rate_fraction"],
            joint_margin=p["joint_margin"],
            position_tolerance=p["position_tolerance"],
            attitude_tolerance=p["attitude_tolerance"],
            velocity_tolerance=p["velocity_tolerance"],
            rate_tolerance=p["rate_tolerance"],
            tolerance_time=p["tolerance_time"],
            grasp_force_limit=p["grasp_force_limit"],
            grasp_torque_limit=p["grasp_torque_limit"],
            detumble_gain=p["detumble_gain"],
            wrench_recovery_time=p["wrench_recovery_time"],
            hold_kp=c.hold_kp,
            hold_kd=c.hold_kd,
            captured_kp=c.captured_kp,
            captured_kd=c.captured_kd,
            estimator_window=p["estimator_window"],
            estimator_minimum=p["estimator_window"] if p["estimator_minimum"] is None else p["estimator_minimum"],
            estimator_memory=p["estimator_memory"],
            pose_history=p["pose_history"],
            limit_window=p["limit_window"],
            shoulder=c.shoulder,
            reach=c.reach,
            arm_velocity=c.velocity,
            arm_lower=c.lower,
            arm_upper=c.upper,
            wheel_axes=c.wheel_axes,
            wheel_effort=c.wheel_effort,
            wheel_velocity=c.wheel_velocity,
        )
        return CaptureController(arm, law, settings, c.wheels)

    def _idle_outputs(self) -> dict[str, np.ndarray]:
        z3 = np.zeros(3)
        return {
            "tau": np.zeros(self.controller.arm.n_body),
            "close": 0.0,
            "phase": 0.0,
            "attempt": 0.0,
            "grasp_distance": 0.0,
            "ee_error": np.zeros(6),
            "close_errors": np.zeros(4),
            "close_within": np.zeros(4),
            "grasp_position_est": z3,
            "grasp_velocity_est": z3,
            "grasp_rate_est": z3,
        }

    def initialize(self, t0_ns, inputs):
        self.controller = self._build()
        if "q" not in self.input_times_ns:
            # the state holds its start values (the dynamics initializes later in config order, or a
            # harness said nothing): take the initial configuration at the first step
            return self._idle_outputs()
        self.controller.start(inputs)
        return self._step(self.input_times_ns["q"] / NS_PER_S, 0.0, inputs)

    def do_step(self, t_ns, h_ns, inputs):
        if not self.controller.started:
            self.controller.start(inputs)
        t_state = self.input_times_ns.get("q", t_ns)
        return self._step(t_state / NS_PER_S, h_ns / NS_PER_S, inputs)

    def _step(self, t, h, inputs):
        outputs = self.controller.step(t, h, inputs)
        for kind, fields in self.controller.take_events():
            self.emit(kind, **fields)
        return outputs

    def get_state(self):
        return self.controller.get_state()

    def set_state(self, state):
        """Restore on a fresh instance (``initialize`` is not called): the estimator, the history,
        the phase and every timer as they were; the next steps are those of the saved instance."""
        self.controller = self._build()
        self.controller.set_state(state)
