"""The computed-torque controller's model quantities (M*, C*, J_g, drift) against independent references.

- M*, C*: DART's free-floating forward dynamics (OrbitalWorld, a second library): for the arm
  torques tau the arm accelerates as qdd = M*^-1 (tau - C*), base unactuated.
- J_g and the drift: DART's classical end-effector acceleration for random states (nonzero
  momentum) and torques equals J_g qdd + a_drift; DART's end-effector velocity equals the
  model's twist (checks the W-axes / base-local velocity conversion).
- J_g by finite differences of the end-effector pose (DART's kinematics) under zero-momentum
  motion (base and passive-joint rates from DART's mass matrix; total momentum zero when the
  left arm is locked), and the drift against a finite difference of J_g qdot.
"""

from pathlib import Path

import numpy as np
import pytest

from components.controller.computed_torque import dls_inverse
from components.controller.free_floating_arm import FreeFloatingArm
from components.dynamics.world import BodySpec, OrbitalWorld
from components.robots.urdf import read_urdf
from components.rotations import log_so3
from tests import validation

ROOT = Path(__file__).resolve().parents[2]
URDF = ROOT / "models" / "humanoid_torso.urdf"
ARM = [f"arm_right_{i}_joint" for i in range(1, 8)]
LEFT = [f"arm_left_{i}_joint" for i in range(1, 8)]
TOOL_OFFSET = np.array([0.0, 0.0, -0.1])  # arm_right_tool_joint origin in arm_right_7_link


def random_rotation(rng):
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


class Setup:
    """The humanoid in DART (no environment) and in the controller's Pinocchio model."""

    def __init__(self, locked: bool):
        self.model = read_urdf(URDF)
        self.joints = self.model.movable_joints
        self.lock = {j: 0.3 * (-1) ** i for i, j in enumerate(LEFT)} if locked else {}
        # in-range values for the locked left arm
        self.lock = {
            j: float(np.clip(v, self.model.joint(j).lower, self.model.joint(j).upper)) for j, v in self.lock.items()
        }
        spec = BodySpec("robot", URDF, q=dict(self.lock), locked_joints=tuple(self.lock))
        self.world = OrbitalWorld([spec], tidal_force=False, gravity_gradient=False, joint_limits=False)
        self.body = self.world.bodies["robot"]
        self.arm = FreeFloatingArm(URDF, self.joints, ARM, "arm_right_tool_link", self.lock)
        self.lower = np.array([self.model.joint(j).lower for j in self.joints])
        self.upper = np.array([self.model.joint(j).upper for j in self.joints])
        self.arm_index = np.array([self.joints.index(j) for j in ARM])
        self.hand = self.body.skel.getBodyNode("arm_right_7_link")

    def random_state(self, rng, scale=1.0):
        p, quat = rng.normal(size=3), random_rotation(rng)
        twist = rng.normal(size=6) * 0.3 * scale
        q = rng.uniform(self.lower, self.upper)
        qd = rng.normal(size=len(self.joints)) * scale
        for j, v in self.lock.items():
            q[self.joints.index(j)], qd[self.joints.index(j)] = v, 0.0
        return p, quat, twist, q, qd

    def set(self, p, quat, twist, q, qd):
        self.world.set_body_state("robot", p, quat, twist, q, qd)
        self.arm.set_state(p, quat, twist, q, qd)

    def ee_pose_dart(self):
        T = self.hand.getTransform().matrix()
        return T[:3, :3] @ TOOL_OFFSET + T[:3, 3], T[:3, :3]


@pytest.fixture(scope="module", params=[True, False], ids=["left-arm-locked", "left-arm-passive"])
def setup(request):
    return Setup(request.param)


def test_generalized_inertia_and_coriolis_match_dart(setup):
    """qdd from DART for tau = 0 and for each unit arm torque: M* (qdd(e_i) - qdd(0)) = e_i and
    M* qdd(0) + C* = 0, over random states (base twist, joint rates, passive left arm or locked)."""
    rng = np.random.default_rng(11)
    worst = 0.0
    n = len(ARM)
    for _ in range(8):
        state = setup.random_state(rng)
        setup.set(*state)
        s = setup.arm.compute()
        accelerations = []
        for k in range(n + 1):
            tau = np.zeros(len(setup.joints))
            if k < n:
                tau[setup.arm_index[k]] = 1.0
            setup.world.set_torques("robot", tau)
            accelerations.append(setup.world.forward_dynamics("robot")["qdd"][setup.arm_index])
        qdd0 = accelerations[-1]
        Q = np.column_stack(accelerations[:-1]) - qdd0[:, None]
        worst = max(
            worst,
            np.abs(s.M_star @ Q - np.eye(n)).max(),
            np.abs(s.M_star @ qdd0 + s.C_star).max() / max(1.0, np.abs(s.C_star).max()),
        )
        assert np.allclose(s.M_star, s.M_star.T, atol=1e-14)
        assert np.all(np.linalg.eigvalsh(s.M_star) > 0)
    print(f"M*, C* vs DART: max residual {worst:.2e}")
    validation.check("generalized_inertia", worst)


def test_end_effector_twist_and_acceleration_match_dart(setup):
    """DART's end-effector velocity = the model's xdot (W axes, base twist converted); DART's
    classical end-effector acceleration under random torques = J_g qdd + a_drift, with the body
    carrying momentum (random base twist)."""
    rng = np.random.default_rng(5)
    worst_v, worst_a = 0.0, 0.0
    for _ in range(10):
        state = setup.random_state(rng)
        setup.set(*state)
        s = setup.arm.compute()
        v = np.concatenate([setup.hand.getLinearVelocity(TOOL_OFFSET), setup.hand.getAngularVelocity()])
        worst_v = max(worst_v, np.abs(v - s.xdot).max() / max(1.0, np.abs(v).max()))
        tau = np.zeros(len(setup.joints))
        tau[setup.arm_index] = rng.normal(size=len(ARM))
        setup.world.set_torques("robot", tau)
        qdd = setup.world.forward_dynamics("robot")["qdd"][setup.arm_index]
        skel = setup.body.skel
        skel.setForces(setup.body.tau)
        skel.computeForwardDynamics()
        a = np.concatenate([setup.hand.getLinearAcceleration(TOOL_OFFSET), setup.hand.getAngularAcceleration()])
        predicted = s.J_g @ qdd + s.a_drift
        worst_a = max(worst_a, np.abs(a - predicted).max() / max(1.0, np.abs(a).max()))
    print(f"end effector vs DART: velocity {worst_v:.2e}, acceleration {worst_a:.2e}")
    assert worst_v < 1e-10
    assert worst_a < 1e-8


def zero_momentum_rates(setup, p, quat, q, qd):
    """Base twist (W) and passive-joint rates that make the generalized momentum of the
    unactuated coordinates zero for the arm rates in qd, from DART's mass matrix. With the left
    arm locked this is the body's total momentum (checked against DART's momentum)."""
    setup.world.set_body_state("robot", p, quat, np.zeros(6), q, qd)
    skel, body = setup.body.skel, setup.body
    arm_dofs = body.dof_index[setup.arm_index]
    unactuated = np.array([k for k in range(body.ndofs) if k not in set(arm_dofs)])
    M, v = skel.getMassMatrix(), skel.getVelocities()
    v[unactuated] = np.linalg.solve(M[np.ix_(unactuated, unactuated)], -M[np.ix_(unactuated, arm_dofs)] @ v[arm_dofs])
    skel.setVelocities(v)
    if setup.lock:
        assert np.abs(setup.world.momentum("robot")).max() < 1e-12
    return np.concatenate([v[3:6], v[:3]]), body.joint_velocities()


def dart_pose_after(setup, p, quat, twist, q, qd, eps):
    """End-effector pose after moving the configuration by eps * velocity (DART's own chart)."""
    setup.world.set_body_state("robot", p, quat, twist, q, qd)
    skel = setup.body.skel
    skel.integratePositions(eps)
    return setup.ee_pose_dart()


def test_generalized_jacobian_by_finite_differences_under_zero_momentum(setup):
    """Column i of J_g = the end-effector twist when joint i turns at unit rate and the base moves
    so that the momentum stays zero; measured by central differences of DART's kinematics."""
    rng = np.random.default_rng(3)
    eps = 1e-6
    worst = 0.0
    for _ in range(4):
        p, quat, _, q, _ = setup.random_state(rng)
        setup.set(p, quat, np.zeros(6), q, np.zeros(len(setup.joints)))
        J_g = setup.arm.compute().J_g
        for k, i in enumerate(setup.arm_index):
            qd = np.zeros(len(setup.joints))
            qd[i] = 1.0
            twist, qd = zero_momentum_rates(setup, p, quat, q, qd)
            p_plus, R_plus = dart_pose_after(setup, p, quat, twist, q, qd, eps)
            p_minus, R_minus = dart_pose_after(setup, p, quat, twist, q, qd, -eps)
            column = np.concatenate([(p_plus - p_minus) / (2 * eps), log_so3(R_plus @ R_minus.T) / (2 * eps)])
            worst = max(worst, np.abs(column - J_g[:, k]).max())
    print(f"J_g vs finite differences (zero momentum): {worst:.2e}")
    validation.check("generalized_jacobian", worst)


def test_drift_is_the_rate_of_J_g_qdot_at_zero_momentum():
    """With zero momentum and no external force, xdot = J_g qdot at all times, so the drift
    a_drift (qdd = 0) equals Jdot_g qdot: central difference of J_g along the motion. (Left arm
    locked: the momentum is conserved; a passive joint's generalized momentum is not.)"""
    import pinocchio as pin

    setup = Setup(locked=True)
    rng = np.random.default_rng(8)
    eps = 1e-6
    worst, largest = 0.0, 0.0
    model = setup.arm.model
    for _ in range(5):
        p, quat, _, q, qd = setup.random_state(rng)
        twist, qd = zero_momentum_rates(setup, p, quat, q, qd)
        setup.set(p, quat, twist, q, qd)
        s = setup.arm.compute()
        assert np.allclose(s.xdot, s.J_g @ qd[setup.arm_index], atol=1e-10)  # h = 0: xdot = J_g qdot
        q_pin, v_pin = setup.arm.q_pin.copy(), setup.arm.v_pin.copy()
        J = []
        for sign in (1.0, -1.0):
            moved = pin.integrate(model, q_pin, sign * eps * v_pin)
            q_body = q.copy()
            for j in setup.joints:
                if j not in setup.lock:
                    q_body[setup.joints.index(j)] = moved[model.joints[model.getJointId(j)].idx_q]
            setup.arm.set_state(moved[:3], moved[3:7], np.zeros(6), q_body, qd)
            J.append(setup.arm.compute().J_g)
        rate = (J[0] - J[1]) / (2 * eps) @ qd[setup.arm_index]
        worst = max(worst, np.abs(rate - s.a_drift).max())
        largest = max(largest, np.abs(s.a_drift).max())
    print(f"a_drift vs d/dt(J_g) qdot: {worst:.2e} (a_drift up to {largest:.2g})")
    assert largest > 0.1
    assert worst < 1e-6 * max(1.0, largest)


def test_fixed_base_model_is_the_textbook_one(setup):
    """base_model fixed: M* = M_mm, J_g = J_m (the arm's columns of the full Jacobian)."""
    import pinocchio as pin

    rng = np.random.default_rng(2)
    setup.set(*setup.random_state(rng))
    fixed, free = setup.arm.compute("fixed"), setup.arm.compute()
    model, data = setup.arm.model, setup.arm.data
    M = pin.crba(model, data, setup.arm.q_pin)
    M = np.triu(M) + np.triu(M, 1).T
    assert np.allclose(fixed.M_star, M[np.ix_(setup.arm.arm_v, setup.arm.arm_v)], atol=1e-14)
    assert not np.allclose(fixed.J_g, free.J_g, atol=1e-3)  # the base reaction matters
    # the Schur complement only removes inertia: M* <= M_mm
    assert np.all(np.linalg.eigvalsh(fixed.M_star - free.M_star) > -1e-12)


def test_damped_least_squares_inverse():
    rng = np.random.default_rng(0)
    J = rng.normal(size=(6, 7))
    J_plus, N, s_min = dls_inverse(J, eps=1e-3, lambda_max=0.05)
    assert s_min > 1e-3
    assert np.allclose(J_plus, np.linalg.pinv(J), atol=1e-12)  # undamped away from singularities
    assert np.allclose(J @ N, 0.0, atol=1e-12) and np.allclose(N @ N, N, atol=1e-12)
    # a singular Jacobian (two equal rows): bounded, damped inverse
    J[5] = J[4]
    J_plus, N, s_min = dls_inverse(J, eps=0.02, lambda_max=0.05)
    assert s_min < 1e-12
    assert np.abs(J_plus).max() < 1.0 / 0.05
    assert np.allclose(J @ N, 0.0, atol=1e-12)


def test_compiled_kernels_equal_the_numpy_expressions_bit_for_bit(setup):
    """components/controller/kernels.py against the numpy expressions it replaced, on random states
    (free floating and fixed base, damped and undamped pseudo-inverse): equal bit for bit, so the
    controller's torques are those of the numpy controller (the same IEEE operations, BLAS and LAPACK)."""
    import pinocchio as pin
    from scipy.linalg.lapack import dgesdd, dposv

    from components.controller import kernels

    rng = np.random.default_rng(5)
    arm = setup.arm
    n, nb, nv = arm.n, arm.base_v.size, arm.model.nv
    rows, cols = np.meshgrid(arm._perm, arm._perm, indexing="ij")
    for _ in range(20):
        setup.set(*setup.random_state(rng))
        pin.computeAllTerms(arm.model, arm.data, arm.q_pin, arm.v_pin)
        J = pin.getFrameJacobian(arm.model, arm.data, arm.ee, pin.LOCAL_WORLD_ALIGNED)
        a_0 = pin.getFrameClassicalAcceleration(arm.model, arm.data, arm.ee, pin.LOCAL_WORLD_ALIGNED).vector
        Mc = np.empty((nv, nv + 1))
        Mc[:, :-1] = arm.data.M[np.minimum(rows, cols), np.maximum(rows, cols)]
        Mc[:, -1] = arm.data.nle[arm._perm]
        Ja = np.empty((6, n + 1))
        Ja[:, :-1], Ja[:, -1] = J[:, arm.arm_v], a_0
        J_b = J[:, arm.base_v]
        gathered = kernels.gather(arm.data.M, arm.data.nle, J, a_0, arm._perm, arm.base_v, arm.arm_v)
        assert all(np.array_equal(a, b) for a, b in zip(gathered, (Mc, Ja, J_b)))
        _, X, _ = dposv(Mc[:nb, :nb], Mc[:nb, nb:])
        for fixed, terms, task in (
            (False, Mc[nb:, nb:] - Mc[:nb, nb:-1].T @ X, Ja - J_b @ X),
            (True, Mc[nb:, nb:], Ja),
        ):
            M_star = terms[:, :n]
            expected = (0.5 * (M_star + M_star.T), terms[:, n], task[:, :n], task[:, n])
            got = kernels.schur(Mc, Ja, J_b, fixed)
            assert got[4] == 0 and all(np.array_equal(a, b) for a, b in zip(got[:4], expected))
        J_g, a_drift = (Ja - J_b @ X)[:, :n], (Ja - J_b @ X)[:, n]
        U, s, Vt, _ = dgesdd(J_g, compute_uv=1, full_matrices=0)
        for lam2 in (0.0, rng.uniform(1e-4, 1e-2)):
            inv = s / (s * s + lam2)
            J_plus, N = Vt.T @ (inv[:, None] * U.T), np.eye(n) - Vt.T @ Vt
            assert all(np.array_equal(a, b) for a, b in zip(kernels.pseudo_inverse(U, s, Vt, lam2), (J_plus, N)))
            p_d, p, rotation, v_d, w_d, a_d, dw_d = rng.normal(size=(7, 3))
            xdot, kp, kd = rng.normal(size=6), rng.uniform(1, 100, 6), rng.uniform(1, 20, 6)
            q_posture, q, qd, null_kp, null_kd = rng.normal(size=(5, n))
            M_s, C_s = kernels.schur(Mc, Ja, J_b, False)[:2]
            error = np.concatenate([p_d - p, rotation])
            xdd_r = np.concatenate([a_d, dw_d]) + kd * (np.concatenate([v_d, w_d]) - xdot) + kp * error
            qdd = J_plus @ (xdd_r - a_drift) + N @ (null_kp * (q_posture - q) - null_kd * qd)
            tau = M_s @ qdd + C_s
            effort = np.abs(tau) * np.where(np.arange(n) % 2, 0.5, 2.0)  # every other torque clipped
            got = kernels.law(
                U,
                s,
                Vt,
                lam2,
                p_d,
                p,
                rotation,
                v_d,
                w_d,
                a_d,
                dw_d,
                xdot,
                kp,
                kd,
                a_drift,
                null_kp,
                null_kd,
                q_posture,
                q,
                qd,
                M_s,
                C_s,
                effort,
            )
            expected = (np.minimum(np.maximum(tau, -effort), effort), error, qdd)
            assert all(np.array_equal(a, b) for a, b in zip(got, expected))
            assert np.array_equal(np.abs(got[0]) < np.abs(tau), np.arange(n) % 2 == 1)
