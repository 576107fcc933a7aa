"""``controller.capture``'s parameters checked against the servicer's URDF (:class:`CaptureSetup`,
set up once in ``validate``) and the :class:`~components.controller.capture_settings.CaptureSettings`
they make: the arm's and wheels' joints and limits, the shoulder and reach, the gains per axis or joint."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from components.controller.capture_settings import CaptureSettings
from components.controller.gains import TASK_AXES, per_item
from components.errors import ConfigError
from components.robots.model import arm_reach, read_model
from components.rotations import rpy_to_matrix
from components.sdk import RunSettings


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


def check_setup(params: Mapping[str, Any], run: RunSettings) -> CaptureSetup:
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
    axes = _wheel_axes(model, wheels)
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


def _wheel_axes(model, wheels: list[str]) -> list[np.ndarray]:
    """The wheels' spin axes in the base frame; ConfigError unless each is a continuous joint on the
    base link with an effort limit."""
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
    return axes


def capture_settings(setup: CaptureSetup) -> CaptureSettings:
    """What the capture controller is told: the checked parameters and what the URDF gave."""
    c, p = setup, setup.checked
    return CaptureSettings(
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
