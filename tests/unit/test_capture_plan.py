"""The capture planner's parts (components/controller/capture_plan.py) against independent
references: the rigid tumble's closed form, the quintic's boundary conditions and finite
differences, and DART's forward kinematics of the servicer's URDF for the inverse kinematics."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from components.controller.capture_plan import ArmKinematics, JointMove, Limits, RigidPrediction
from components.controller.trajectory import PoseSample
from components.rotations import exp_so3, log_so3

ROOT = Path(__file__).resolve().parents[2]
SERVICER = ROOT / "models" / "capture" / "servicer.urdf"
ARM = [f"arm_{i}_joint" for i in range(1, 7)]


def test_the_prediction_is_the_rigid_tumble_about_a_point_moving_with_the_base():
    """A grapple 0.7 m off a centre c that moves with the base's velocity (the base not turning),
    the body turning at 4 deg/s about a skew axis: from the pose and velocities at t0 alone, the
    prediction 30 s on is the closed form c + v_b dt + exp(w dt)(p0 - c) to 1e-12 m, its attitude
    exp(w dt) R0 to 1e-12 rad, its velocity v_b + w x r to 1e-13 m/s."""
    w = exp_so3([0.3, -0.2, 0.5]) @ np.array([0.2, -0.7, 0.4])
    w *= math.radians(4.0) / np.linalg.norm(w)
    c, v_b, p_b = np.array([1.8, 0.3, 1.1]), np.array([0.004, -0.002, 0.001]), np.array([0.1, -0.2, 0.05])
    p0 = c + exp_so3([0.4, 0.1, -0.3]) @ np.array([0.0, 0.0, 0.7])
    R0 = exp_so3([1.0, -0.4, 0.2])
    grasp = PoseSample(p0, v_b + np.cross(w, p0 - c), np.zeros(3), R0, w, np.zeros(3))
    prediction = RigidPrediction(2.0, grasp, p_b, v_b, np.zeros(3))
    for dt in (0.0, 1.5, 30.0):
        g = prediction.sample(2.0 + dt)
        E = exp_so3(w * dt)
        r = E @ (p0 - c)
        assert np.abs(g.p - (c + v_b * dt + r)).max() < 1e-12
        assert np.linalg.norm(log_so3(g.R @ (E @ R0).T)) < 1e-12
        assert np.abs(g.v - (v_b + np.cross(w, r))).max() < 1e-13
        assert np.abs(g.w - w).max() == 0.0


def test_the_joint_move_meets_its_ends_and_its_derivatives_are_consistent():
    """q, qd and qdd = 0 at both ends (to 1e-13), qd and qdd the central differences of q and qd
    (to 1e-7), and the state round trip is exact."""
    q0, qd0 = np.array([-0.9, 0.2, 1.6, -0.3, 1.2, 0.3]), np.array([0.1, -0.2, 0.0, 0.3, 0.05, -0.1])
    q1, qd1 = np.array([0.1, 0.5, 0.9, 0.3, 1.1, 0.1]), np.array([0.02, 0.03, -0.05, 0.01, 0.0, 0.04])
    move = JointMove(3.0, 1.7, q0, qd0, q1, qd1)
    q, qd, qdd = move.sample(3.0)
    assert np.abs(q - q0).max() < 1e-13 and np.abs(qd - qd0).max() < 1e-13 and np.abs(qdd).max() < 1e-13
    q, qd, qdd = move.sample(4.7)
    assert np.abs(q - q1).max() < 1e-13 and np.abs(qd - qd1).max() < 1e-13 and np.abs(qdd).max() < 1e-12
    h = 1e-5
    for t in (3.3, 3.9, 4.5):
        (qa, qda, _), (qb, qdb, _), (_, qd, qdd) = move.sample(t - h), move.sample(t + h), move.sample(t)
        assert np.abs((qb - qa) / (2 * h) - qd).max() < 1e-7
        assert np.abs((qdb - qda) / (2 * h) - qdd).max() < 1e-6
    again = JointMove.from_array(move.to_array(), 6)
    assert all(np.array_equal(a, b) for a, b in zip(again.sample(4.1), move.sample(4.1)))


@pytest.fixture(scope="module")
def kinematics():
    from components.controller.free_floating_arm import FreeFloatingArm
    from components.robots.model import read_model

    model = read_model(str(SERVICER), None, "urdf", None)
    arm = FreeFloatingArm(model, model.movable_joints, ARM, "ee")
    arm_q = np.array([arm.model.joints[arm.model.getJointId(j)].idx_q for j in ARM])
    limits = Limits(
        np.array([model.joint(j).lower for j in ARM]),
        np.array([model.joint(j).upper for j in ARM]),
        np.array([model.joint(j).velocity for j in ARM]),
        0.15,
        0.05,
        0.5,
        1.54,
    )
    kin = ArmKinematics(arm.model, arm.arm_v, arm_q, arm.ee, arm.model.getJointId("arm_1_joint"), ARM, limits)
    base = ([0.2, -0.1, 0.05], np.array([0.1, -0.2, 0.3, 0.9]) / np.linalg.norm([0.1, -0.2, 0.3, 0.9]))
    arm.set_state(base[0], base[1], np.zeros(6), np.zeros(9), np.zeros(9))
    return kin, arm.q_pin.copy(), base


def dart_ee(q, base):
    """The end effector's pose in W by DART from the URDF, the base at ``base``."""
    from components.dynamics.world import BodySpec, OrbitalWorld

    world = OrbitalWorld(
        [BodySpec("servicer", SERVICER, position=base[0], orientation=base[1], q=dict(zip(ARM, q)))], joint_limits=False
    )
    world.reset_bodies()
    T = world.bodies["servicer"].skel.getBodyNode("ee").getTransform().matrix()
    return T[:3, 3], T[:3, :3]


@pytest.mark.parametrize("q_true", [[0.07, 0.47, 0.93, 0.26, 1.15, 0.13], [-0.6, 1.1, -0.8, 1.2, -0.9, 2.0]])
def test_inverse_kinematics_reaches_the_pose_dart_gives_and_the_rates_follow_the_twist(kinematics, q_true):
    """The pose DART's forward kinematics gives for q_true (the base turned and moved), solved
    from a seed 0.4 rad away per joint: DART puts the end effector of the solution on it to the
    solver's tolerance (|log6| < 1e-7: 1e-7 m and rad). With the rates judge() gives for a twist,
    DART moves the end effector at that twist (central differences of its poses, to 1e-8)."""
    import pinocchio as pin

    kin, q_pin, base = kinematics
    p, R = dart_ee(q_true, base)
    seed = np.array(q_true) + np.array([0.4, -0.4, 0.4, -0.4, 0.4, -0.4])
    q = kin.solve(q_pin, pin.SE3(R, p), seed)
    assert q is not None
    p_s, R_s = dart_ee(q, base)
    assert (
        np.linalg.norm(p_s - p) < ArmKinematics.TOLERANCE
        and np.linalg.norm(log_so3(R_s @ R.T)) < ArmKinematics.TOLERANCE
    )
    twist = np.array([0.03, -0.02, 0.01, 0.02, 0.05, -0.03])
    verdict = kin.judge(q_pin, q, twist, p)
    h = 1e-5  # DART's pose at q -+ qd h: the end effector's twist
    (pa, Ra), (pb, Rb) = dart_ee(q - verdict.qd * h, base), dart_ee(q + verdict.qd * h, base)
    assert np.abs((pb - pa) / (2 * h) - twist[:3]).max() < 1e-8
    assert np.abs(log_so3(Rb @ Ra.T) / (2 * h) - twist[3:]).max() < 1e-8


def test_a_configuration_is_judged_on_limits_singularities_and_rates(kinematics):
    """At the stretched elbow (arm_3 = 0: a singularity) the verdict is infeasible naming the
    singular value; well inside, feasible; a twist of 3 rad/s about the shoulder's axis needs
    arm_1 beyond half its 2 rad/s limit, and the reason names it; a joint 0.05 rad inside its
    limit is refused naming the joint."""
    kin, q_pin, _ = kinematics
    twist0 = np.zeros(6)
    good = np.array([0.07, 0.47, 0.93, 0.26, 1.15, 0.13])
    assert kin.judge(q_pin, good, twist0, np.zeros(3)).feasible
    stretched = good.copy()
    stretched[2] = 0.0
    verdict = kin.judge(q_pin, stretched, twist0, np.zeros(3))
    assert not verdict.feasible and "singularity" in verdict.reason
    near_limit = good.copy()
    near_limit[2] = 2.75  # arm_3's URDF limit is 2.8 rad
    verdict = kin.judge(q_pin, near_limit, twist0, np.zeros(3))
    assert not verdict.feasible and verdict.reason.startswith("arm_3_joint at 2.75 rad is within 0.15 rad")
    kin.pin.framesForwardKinematics(kin.model, kin.data, kin._configure(q_pin, good))
    axis = kin.data.oMi[kin.shoulder].rotation[:, 2]
    r = kin.data.oMf[kin.ee].translation - kin.data.oMi[kin.shoulder].translation
    fast = np.concatenate([np.cross(3.0 * axis, r), 3.0 * axis])
    verdict = kin.judge(q_pin, good, fast, np.zeros(3))
    assert not verdict.feasible and abs(verdict.qd[0] - 3.0) < 1e-9
    assert "needs arm_1_joint at 3 rad/s, more than 0.5 of its URDF velocity limit 2 rad/s" in verdict.reason
