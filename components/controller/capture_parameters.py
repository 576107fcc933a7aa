"""The parameters of ``controller.capture``, declared once: the servicer's URDF and joints, the
approach and its planner, the close's tolerances, the grasp's limits and the detumbling after
capture, the gains and the estimator."""

from __future__ import annotations

from components.controller.gains import CARTESIAN_GAINS, DAMPING, STIFFNESS, gain
from components.schema import Float, Int, ListOf, Str
from components.sdk import Parameter
from components.units import DEG

PARAMETERS = (
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
