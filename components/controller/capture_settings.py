"""What the capture controller is told (:mod:`components.controller.capture`): the parameters of
``controller.capture`` resolved against the servicer's URDF (its limits, shoulder and reach)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: the estimated errors behind ``close``, in the order of the ``close_errors`` output
CLOSE_ERRORS = ("position", "attitude", "velocity", "rate")


@dataclass(frozen=True)
class CaptureSettings:
    """Everything the capture controller needs besides its arm model and Cartesian law.

    | field | unit | meaning |
    |---|---|---|
    | approach_time | s | duration of the joint-space move onto the pre-grasp pose (and of a retreat) |
    | closing_time | s | duration of the straight-line close from the pre-grasp pose onto the grapple |
    | standoff | m | the pre-grasp pose: the grasp frame moved back along its z (out of the target) |
    | position_tolerance, attitude_tolerance | m, rad | close when the estimated errors stay below... |
    | velocity_tolerance, rate_tolerance | m/s, rad/s | ...these (linear and angular velocity)... |
    | tolerance_time | s | ...for this long |
    | track_time | s | how long tracking may wait for the tolerances before the arm retreats |
    | attempts | - | approaches before the capture is given up |
    | capture_timeout | s | time (from t = 0) after which a capture not under way is given up |
    | replan_period | s | how often the planner looks for a window while the arm waits |
    | singularity_margin | - | the planner's lowest smallest singular value of the arm's Jacobian |
    | rate_fraction | - | the planner's share of the URDF velocity limits for following the grapple |
    | joint_margin | rad | the planner's distance from the URDF position limits |
    | grasp_force_limit, grasp_torque_limit | N, N m | bounds of the measured wrist wrench while detumbling |
    | detumble_gain | N m s/rad | bus torque per bus rate |
    | wrench_recovery_time | s | time for the wheel-torque factor to recover from 0 to 1 |
    | hold_kp, hold_kd | 1/s^2, 1/s (n) | joint gains of the holds and the joint-space moves (computed torque) |
    | captured_kp, captured_kd | N m/rad, N m s/rad (n) | joint hold gains after capture (torque units) |
    | estimator_window | - | measurements in the fit (the latest) |
    | estimator_minimum | - | measurements before the estimate is first used |
    | estimator_memory | s | fading-memory time constant of the fit |
    | pose_history | s | end-effector poses kept: the longest measurement latency |
    | limit_window | s | how long joint rates or torques may exceed the URDF limits |
    | shoulder, reach | -, m | centre and radius of the reach sphere |
    | arm_velocity | rad/s (n) | URDF velocity limits of the arm joints |
    | arm_lower, arm_upper | rad (n) | URDF position limits of the arm joints |
    | wheel_axes | - (3, m) | wheel spin axes in bus axes (columns) |
    | wheel_effort, wheel_velocity | N m, rad/s (m) | URDF limits of the wheels |
    """

    approach_time: float
    closing_time: float
    standoff: float
    position_tolerance: float
    attitude_tolerance: float
    velocity_tolerance: float
    rate_tolerance: float
    tolerance_time: float
    track_time: float
    attempts: int
    capture_timeout: float
    replan_period: float
    singularity_margin: float
    rate_fraction: float
    joint_margin: float
    grasp_force_limit: float
    grasp_torque_limit: float
    detumble_gain: float
    wrench_recovery_time: float
    hold_kp: np.ndarray
    hold_kd: np.ndarray
    captured_kp: np.ndarray
    captured_kd: np.ndarray
    estimator_window: int
    estimator_minimum: int
    estimator_memory: float
    pose_history: float
    limit_window: float
    shoulder: str
    reach: float
    arm_velocity: np.ndarray
    arm_lower: np.ndarray
    arm_upper: np.ndarray
    wheel_axes: np.ndarray
    wheel_effort: np.ndarray
    wheel_velocity: np.ndarray

    @property
    def close_tolerances(self) -> np.ndarray:
        """The tolerances of the close, in the order of CLOSE_ERRORS (m, rad, m/s, rad/s)."""
        return np.array(
            [self.position_tolerance, self.attitude_tolerance, self.velocity_tolerance, self.rate_tolerance]
        )
