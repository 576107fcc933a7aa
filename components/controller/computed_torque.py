r"""Computed-torque control of a free-floating manipulator with the Generalized Jacobian
(Ramón, Pomares, Felicetti, IAC-22, eqs. 1-8). Plain classes, no bus, no I/O.

Model
-----
The body is its URDF on a free-flyer base (``pin.JointModelFreeFlyer``), built by Pinocchio from
the same file the dynamics loads, in zero gravity; joints the dynamics welds (``locked_joints``)
are removed with ``pin.buildReducedModel`` at their measured position. Generalized velocity, in
Pinocchio's convention: ``nu = (v_b, w_b, qdot)`` with the base velocity in the base's *local*
frame (``v_b = R^T v_W`` of the base origin, ``w_b = R^T w_W``); the dynamics publishes the twist
in W axes (``twist = (v_W, w_W)``), converted here with the base orientation R = R_W_base.

Partition the coordinates into the actuated ones ``m`` (the arm's joints, driven by this
controller) and the unactuated ones ``b`` (the base's 6, plus any joint of the body that is neither
driven nor locked: it is passive, zero torque, and moves with the base). Eq. (1):

    [ M_bb   M_bm ] [ dnu_b ]   [ c_b ]   [ 0   ]
    [ M_bm^T M_mm ] [ qdd   ] + [ c_m ] = [ tau ]

(c = Coriolis/centrifugal terms, Pinocchio's ``nonLinearEffects`` with gravity zero; external
environment forces are not modelled — feedback absorbs them). The first row gives the base's
reaction ``dnu_b = -M_bb^-1 (M_bm qdd + c_b)``; substituted in the second, eqs. (2)-(4):

    tau = M* qdd + C*,   M* = M_mm - M_bm^T M_bb^-1 M_bm,   C* = c_m - M_bm^T M_bb^-1 c_b.

(M* and C* do not depend on how the base velocity is parametrised: a change ``nu_b' = T nu_b``
cancels in the Schur complement.)  The end-effector twist ``xdot = (v_e, w_e)`` (frame origin's
linear velocity, angular velocity, both W axes) is ``xdot = J_b nu_b + J_m qdot`` with
``J = getFrameJacobian(..., LOCAL_WORLD_ALIGNED)``; with the momentum ``h = M_bb nu_b + M_bm qdot``
(eq. 5) it is ``xdot = J_g qdot + J_b M_bb^-1 h``, eq. (7): ``J_g = J_m - J_b M_bb^-1 M_bm``.

Drift term (the ``Jdot_g qdot + nu_gm-dot`` of eq. 6), exact and without numerical
differentiation: differentiating ``xdot = J nu`` and inserting the base reaction,

    xddot = J (dnu) + Jdot nu = (J_m - J_b M_bb^-1 M_bm) qdd + [J_b (-M_bb^-1 c_b) + Jdot nu]
          = J_g qdd + a_drift,

where ``a_drift`` is the end effector's (classical) acceleration when ``qdd = 0`` and the base
accelerates as ``dnu_b = -M_bb^-1 c_b``. That acceleration is affine in ``dnu`` with slope J (the
classical correction ``w x v`` depends on the velocities only), so ``a_drift = a_0 - J_b M_bb^-1
c_b`` with ``a_0`` the classical acceleration at ``dnu = 0``, which the pass that computes M and c
(``computeAllTerms``) leaves in ``data.a`` (``getFrameClassicalAcceleration(...,
LOCAL_WORLD_ALIGNED)``). It holds for any momentum, not only h = 0 (a body co-rotating with LVLH
carries angular momentum). With ``h = 0`` it equals the paper's ``Jdot_g qdot`` (J_b M_bb^-1 h
vanishes and so does its derivative up to the environment).

Control law, eqs. (6) and (8): with ``e = (p_d - p, log(R_d R^T))`` and
``edot = (v_d - v_e, w_d - w_e)``,

    xddot_r = xddot_d + K_d edot + K_p e                                   (per axis gains)
    qdd*    = J_g^+ (xddot_r - a_drift) + N qdd_0,  qdd_0 = k_np (q_posture - q) - k_nd qdot
    tau     = M* qdd* + C*

``J_g^+`` is a damped least-squares inverse ``V diag(s / (s^2 + lambda^2)) U^T`` with
``lambda^2 = lambda_max^2 (1 - (s_min / eps)^2)`` when ``s_min < eps`` (else 0). ``N = I - V_6 V_6^T``
projects onto J_g's null space (7-DOF arm, 6-D task: one self-motion), where a posture/damping
term holds the arm near its initial posture. The torques are clipped to the URDF effort limits.

``base_model: fixed`` is the textbook fixed-base computed torque on the same measurements (the
base is assumed not to accelerate): ``M* = M_mm``, ``C* = c_m``, ``J_g = J_m``, ``a_drift = Jdot_m
qdot``. It ignores the base's reaction; it is there to show what the free-floating model buys.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.linalg.lapack import dgesdd

from components.controller import kernels
from components.controller.trajectory import PoseSample
from components.rotations import matrix_to_quat

BASE_MODELS = ("free_floating", "fixed")


@dataclass
class ArmState:
    """The paper's quantities at one state (actuated joints in the order of ``arm_joints``).

    | field | shape | unit | meaning |
    |---|---|---|---|
    | M_star | (n, n) | kg m^2 | generalized inertia, eq. 3 |
    | C_star | (n,) | N m | generalized Coriolis/centrifugal vector, eq. 4 |
    | J_g | (6, n) | m/rad, 1 | Generalized Jacobian (rows: linear, angular; W axes), eq. 7 |
    | a_drift | (6,) | m/s^2, rad/s^2 | end-effector acceleration at qdd = 0 (see module doc) |
    | p, R | (3,), (3, 3) | m | end-effector position and R_W_ee |
    | quat | (4,) | 1 | q_W_ee [x, y, z, w], w >= 0 |
    | xdot | (6,) | m/s, rad/s | end-effector twist (origin velocity, angular velocity), W |
    | q, qd | (n,) | rad, rad/s | arm joint positions and rates |
    """

    M_star: np.ndarray
    C_star: np.ndarray
    J_g: np.ndarray
    a_drift: np.ndarray
    p: np.ndarray
    R: np.ndarray
    quat: np.ndarray
    xdot: np.ndarray
    q: np.ndarray
    qd: np.ndarray


class FreeFloatingArm:
    """Pinocchio model of a body (URDF on a free flyer) and one arm's Generalized-Jacobian terms.

    | argument | meaning |
    |---|---|
    | urdf | the parsed URDF (``UrdfModel``: package URIs resolved, xacro expanded) or a URDF path (the body's root link is the free base); mimic joints follow their joint (Pinocchio's mimic joints) |
    | body_joints | the body's non-fixed joints in URDF order: the layout of q, qd, tau |
    | arm_joints | the joints this controller drives (names) |
    | end_effector | a link (or frame) name of the URDF |
    | locked | joint name -> position (rad or m) at which it is welded |

    ``set_state`` raises ValueError when a locked joint moves (the dynamics does not lock it: the
    model would be wrong).
    """

    def __init__(
        self,
        urdf,
        body_joints: Sequence[str],
        arm_joints: Sequence[str],
        end_effector: str,
        locked: Mapping[str, float] | None = None,
    ):
        import pinocchio as pin

        self.pin = pin
        mimics = {}
        if hasattr(urdf, "text"):  # a UrdfModel: the text as parsed, package URIs resolved
            mimics = urdf.mimics
            # Pinocchio's own mimic joints are not in computeAllTerms: the mimic joints are
            # independent in the model, and the constraint is applied to M, c and J (compute)
            full = pin.buildModelFromXML(urdf.text, pin.JointModelFreeFlyer())
            urdf = urdf.path
        else:
            full = pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer())
        locked = dict(locked or {})
        if locked:
            reference = pin.neutral(full)
            for name, value in locked.items():
                joint = full.joints[full.getJointId(name)]
                if joint.nq == 2:  # continuous joint: (cos, sin)
                    reference[joint.idx_q : joint.idx_q + 2] = math.cos(value), math.sin(value)
                else:
                    reference[joint.idx_q] = value
            model = pin.buildReducedModel(full, [full.getJointId(n) for n in locked], reference)
        else:
            model = full
        model.gravity = pin.Motion.Zero()
        self.model, self.data = model, model.createData()
        self.body_joints, self.arm_joints = list(body_joints), list(arm_joints)
        self.n_body, self.n = len(self.body_joints), len(self.arm_joints)
        # body layout (URDF order) -> Pinocchio q / v indices; locked joints are not in the model
        self._q1_body, self._q1_pin, self._v_body, self._v_pin, self._q2 = [], [], [], [], []
        for k, name in enumerate(self.body_joints):
            if name in locked:
                continue
            joint = model.joints[model.getJointId(name)]
            if joint.nv == 0:  # a mimic joint: Pinocchio moves it with the joint it follows
                continue
            if joint.nq == 2:
                self._q2.append((joint.idx_q, k))
            else:
                self._q1_body.append(k)
                self._q1_pin.append(joint.idx_q)
            self._v_body.append(k)
            self._v_pin.append(joint.idx_v)
        self._q1_body, self._q1_pin = np.array(self._q1_body, dtype=int), np.array(self._q1_pin, dtype=int)
        self._v_body, self._v_pin = np.array(self._v_body, dtype=int), np.array(self._v_pin, dtype=int)
        self.locked = locked
        self._locked_body = [(self.body_joints.index(j), j, float(locked[j])) for j in locked]
        self.body_arm = np.array([self.body_joints.index(j) for j in self.arm_joints])
        self.arm_v = np.array([model.joints[model.getJointId(j)].idx_v for j in self.arm_joints])
        passive = [
            model.joints[model.getJointId(j)].idx_v
            for j in self.body_joints
            if j not in locked and j not in self.arm_joints and model.joints[model.getJointId(j)].nv > 0
        ]
        self.base_v = np.array(list(range(6)) + sorted(passive))
        # (base, arm) ordering of the velocity coordinates (kernels.gather reads M's upper triangle in it)
        self._perm = np.concatenate([self.base_v, self.arm_v])
        if self._perm.size != model.nv:
            raise ValueError(
                f"joints: the model has {model.nv - 6} free joints, {self.arm_v.size} driven and {len(passive)} passive"
            )
        # mimic joints (v_k = multiplier v_f, both passive): v_b = G v_b', M_bb' = G^T M_bb G,
        # [M_bm, c_b]' = G^T [M_bm, c_b], J_b' = J_b G (the constraint's Jacobian is constant)
        self._G = None
        pairs = [(j, f, m) for j, (f, m, _) in mimics.items() if j not in locked and f not in locked]
        for j, f, _ in pairs:
            if j in self.arm_joints or f in self.arm_joints:
                raise ValueError(f"joints: {j!r} mimics {f!r}; a driven joint can neither mimic nor be mimicked")
        if pairs:
            base = list(self.base_v)
            drop = [base.index(model.joints[model.getJointId(j)].idx_v) for j, _, _ in pairs]
            G = np.eye(len(base))
            for (_, f, m), k in zip(pairs, drop):
                G[k, :] = 0.0
                G[k, base.index(model.joints[model.getJointId(f)].idx_v)] = m
            self._G = np.ascontiguousarray(np.delete(G, drop, axis=1))
        if not model.existFrame(end_effector):
            raise ValueError(f"end_effector: {end_effector!r} is not a frame of {Path(urdf).name}")
        self.ee = model.getFrameId(end_effector)
        self.q_pin = pin.neutral(model)
        self.v_pin = np.zeros(model.nv)
        self._R_base = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))

    # ------------------------------------------------------------ state

    @property
    def R_base(self) -> np.ndarray:
        """R_W_base (3x3) of the last ``set_state``."""
        return np.array(self._R_base)

    def set_state(self, position, orientation, twist, q, qd) -> None:
        """Measured state: base origin (W), q_W_base [x, y, z, w], twist (v_W, w_W), q and qd of
        the whole body (URDF order)."""
        # the base's rotation and twist in plain floats: numpy's per-call overhead on 3-vectors
        # and 3x3 matrices would cost more than the arithmetic
        x, y, z, w = np.asarray(orientation, dtype=float).tolist()
        scale = 1.0 / math.sqrt(x * x + y * y + z * z + w * w)
        x, y, z, w = x * scale, y * scale, z * scale, w * scale
        (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = self._R_base = (
            (1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)),
            (2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)),
            (2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)),
        )
        vx, vy, vz, wx, wy, wz = np.asarray(twist, dtype=float).tolist()
        qp, vp = self.q_pin, self.v_pin
        qp[:3] = position
        qp[3:7] = x, y, z, w
        vp[:6] = (
            r00 * vx + r10 * vy + r20 * vz,
            r01 * vx + r11 * vy + r21 * vz,
            r02 * vx + r12 * vy + r22 * vz,
            r00 * wx + r10 * wy + r20 * wz,
            r01 * wx + r11 * wy + r21 * wz,
            r02 * wx + r12 * wy + r22 * wz,
        )
        q = np.asarray(q, dtype=float)
        qd = np.asarray(qd, dtype=float)
        if self._locked_body:
            q_list, qd_list = q.tolist(), qd.tolist()
            for k, name, value in self._locked_body:
                if qd_list[k] != 0.0 or abs(q_list[k] - value) > 1e-9:
                    raise ValueError(
                        f"locked_joints: {name} moves (q = {q_list[k]:.9g}, locked at {value:.9g}; "
                        f"qd = {qd_list[k]:.3g}): lock it in the dynamics too "
                        "(bodies.<body>.locked_joints) or remove it from the controller's"
                    )
        qp[self._q1_pin] = q[self._q1_body]
        vp[self._v_pin] = qd[self._v_body]
        for iq, k in self._q2:  # continuous joints: (cos, sin)
            qp[iq], qp[iq + 1] = math.cos(q[k]), math.sin(q[k])
        self._q_arm = q[self.body_arm]
        self._qd_arm = qd[self.body_arm]

    def pose(self) -> tuple[np.ndarray, np.ndarray]:
        """End-effector position and rotation (W) at the current state (kinematics only)."""
        pin = self.pin
        pin.forwardKinematics(self.model, self.data, self.q_pin)
        M = pin.updateFramePlacement(self.model, self.data, self.ee)
        return np.array(M.translation), np.array(M.rotation)

    def joint_origin(self, name: str) -> np.ndarray:
        """Position (W) of a joint's frame origin at the current state (after ``pose``)."""
        return np.array(self.data.oMi[self.model.getJointId(name)].translation)

    def compute(self, base_model: str = "free_floating") -> ArmState:
        """M*, C*, J_g, a_drift and the end-effector state at the current state (module doc)."""
        pin, model, data, ee = self.pin, self.model, self.data, self.ee
        # one pass: FK(q, v), M (upper triangle), nle, joint Jacobians and the accelerations at
        # dnu = 0 (data.a: a_0 of the module doc)
        pin.computeAllTerms(model, data, self.q_pin, self.v_pin)
        frame = pin.updateFramePlacement(model, data, ee)
        pose = pin.SE3ToXYZQUAT(frame)  # a new array: origin, quaternion [x, y, z, w]
        if pose[6] < 0.0:
            pose[3:] *= -1.0  # w >= 0, as rotations.matrix_to_quat
        J = pin.getFrameJacobian(model, data, ee, pin.LOCAL_WORLD_ALIGNED)
        velocity = pin.getFrameVelocity(model, data, ee, pin.LOCAL_WORLD_ALIGNED)
        a_0 = pin.getFrameClassicalAcceleration(model, data, ee, pin.LOCAL_WORLD_ALIGNED)
        xdot = velocity.vector.copy()  # a view of the Motion's memory until copied
        # [M | c] reordered (b, m), from crba's upper triangle, and [J_m | a_0]: each pair of
        # blocks then takes one product (kernels.py: the arithmetic, compiled)
        Mc, Ja, J_b = kernels.gather(data.M, data.nle, J, a_0.vector, self._perm, self.base_v, self.arm_v)
        if self._G is not None:  # mimic joints: the reduced coordinates
            G, nb = self._G, self.base_v.size
            Mc = np.vstack(
                [np.hstack([G.T @ Mc[:nb, :nb] @ G, G.T @ Mc[:nb, nb:]]), np.hstack([Mc[nb:, :nb] @ G, Mc[nb:, nb:]])]
            )
            J_b = J_b @ G
        # free floating: M_bb^-1 [M_bm, c_b] by Cholesky (M_bb is symmetric positive definite), then
        # [M*, C*] = [M_mm, c_m] - M_bm^T X and [J_g, a_drift] = [J_m, a_0] - J_b X (module doc)
        M_star, C_star, J_g, a_drift, info = kernels.schur(Mc, Ja, J_b, base_model == "fixed")
        if info != 0:
            raise np.linalg.LinAlgError(f"M_bb is not positive definite (LAPACK dposv info {info})")
        return ArmState(
            M_star,
            C_star,
            J_g,
            a_drift,
            pose[:3],
            np.array(frame.rotation),
            pose[3:],
            xdot,
            self._q_arm.copy(),
            self._qd_arm.copy(),
        )


def compile_kernels(arm: FreeFloatingArm, law: ComputedTorqueLaw) -> None:
    """Compile the numba kernels of a control step (or load them from numba's disk cache) now, by
    one step's calls with ``arm`` at rest in its neutral configuration. A component whose first
    control step comes late (a capture's approach, seconds into the run) calls it at construction:
    a cold compile (~3 s on one idle core) then counts against run.start_timeout, not inside a
    step against run.step_timeout. ``arm`` and ``law`` are throwaway: their state changes."""
    q = np.zeros(arm.n_body)
    for k, _, value in arm._locked_body:
        q[k] = value
    arm.set_state(np.zeros(3), (0.0, 0.0, 0.0, 1.0), np.zeros(6), q, np.zeros(arm.n_body))
    s = arm.compute(law.base_model)
    still = np.zeros(3)
    law.control(s, PoseSample(s.p, still, still, s.R, still, still), s.q.copy())
    dls_inverse(s.J_g, law.eps, law.lam)


def dls_inverse(J: np.ndarray, eps: float, lambda_max: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Damped least-squares inverse of J (m x n, m <= n): (J^+, null-space projector, s_min).

    Damping ``lambda^2 = lambda_max^2 (1 - (s_min/eps)^2)`` only when s_min < eps (Chiaverini's
    variable damping); the projector ``I - V_m V_m^T`` is exact whatever the damping.
    """
    U, s, Vt, s_min, lam2 = damped_svd(J, eps, lambda_max)
    J_plus, N = kernels.pseudo_inverse(U, s, Vt, lam2)
    return J_plus, N, s_min


def damped_svd(J: np.ndarray, eps: float, lambda_max: float):
    """(U, s, Vt, s_min, lambda^2): J's thin SVD and the damping of ``dls_inverse``."""
    # LAPACK's gesdd (as numpy's svd) called directly: numpy's wrapper costs more than the
    # decomposition of a 6x7 matrix
    U, s, Vt, info = dgesdd(J, compute_uv=1, full_matrices=0)  # Vt: the first m rows of V^T
    if info != 0:
        raise np.linalg.LinAlgError(f"SVD did not converge (LAPACK dgesdd info {info})")
    s_min = float(s[-1])
    lam2 = lambda_max**2 * (1.0 - (s_min / eps) ** 2) if s_min < eps else 0.0
    return U, s, Vt, s_min, lam2


@dataclass
class ControlOutput:
    """One control step: arm torques and diagnostics.

    | field | unit | meaning |
    |---|---|---|
    | tau | N m | arm joint torques, ``arm_joints`` order, clipped to the effort limits |
    | error | m, rad | (p_d - p, log(R_d R^T)), W |
    | sigma_min | - | smallest singular value of J_g (J_m for ``fixed``) |
    | qdd | rad/s^2 | the commanded joint acceleration |
    """

    tau: np.ndarray
    error: np.ndarray
    sigma_min: float
    qdd: np.ndarray


class ComputedTorqueLaw:
    """Eqs. (6) and (8) with a damped pseudo-inverse and a null-space posture term.

    | argument | unit | meaning |
    |---|---|---|
    | kp | 1/s^2 (6) | Cartesian stiffness per axis: x, y, z (position), then rotation x, y, z |
    | kd | 1/s (6) | Cartesian damping per axis |
    | null_kp | 1/s^2 (n) | posture stiffness in the null space |
    | null_kd | 1/s (n) | joint damping in the null space |
    | dls_threshold | - | s_min below which the pseudo-inverse is damped (eps) |
    | dls_damping | - | damping at s_min = 0 (lambda_max) |
    | effort | N m (n) | torque limits (URDF) |
    | base_model | - | free_floating (paper) or fixed (ignores the base's reaction) |
    """

    def __init__(
        self,
        kp,
        kd,
        null_kp,
        null_kd,
        effort,
        *,
        dls_threshold: float = 0.02,
        dls_damping: float = 0.05,
        base_model: str = "free_floating",
    ):
        import pinocchio as pin

        if base_model not in BASE_MODELS:
            raise ValueError(f"base_model: expected one of {', '.join(BASE_MODELS)}, got {base_model!r}")
        self.kp, self.kd = np.asarray(kp, dtype=float), np.asarray(kd, dtype=float)
        self.null_kp, self.null_kd = np.asarray(null_kp, dtype=float), np.asarray(null_kd, dtype=float)
        self.effort = np.asarray(effort, dtype=float)
        self.eps, self.lam = float(dls_threshold), float(dls_damping)
        self.base_model = base_model
        self._log3 = pin.log3  # log of SO(3): on one 3x3 a tenth of rotations.log_so3's cost

    def control(self, s: ArmState, d: PoseSample, q_posture: np.ndarray) -> ControlOutput:
        """error = (p_d - p, log(R_d R^T)); xdd_r = xdd_d + K_d edot + K_p e;
        qdd = J_g^+ (xdd_r - a_drift) + N qdd_0 with qdd_0 = k_np (q_posture - q) - k_nd qd;
        tau = M* qdd + C*, clipped to the efforts (kernels.law)."""
        U, sv, Vt, s_min, lam2 = damped_svd(s.J_g, self.eps, self.lam)
        tau, error, qdd = kernels.law(
            U,
            sv,
            Vt,
            lam2,
            d.p,
            s.p,
            self._log3(d.R @ s.R.T),
            d.v,
            d.w,
            d.a,
            d.dw,
            s.xdot,
            self.kp,
            self.kd,
            s.a_drift,
            self.null_kp,
            self.null_kd,
            q_posture,
            s.q,
            s.qd,
            s.M_star,
            s.C_star,
            self.effort,
        )
        return ControlOutput(tau, error, s_min, qdd)


class ArmController:
    """The whole controller of one arm: model, trajectory, law (no I/O; the component wraps it).

    ``start(t, state)`` anchors the trajectory at the measured end-effector pose and takes the
    arm's posture for the null-space term; ``step(t, state)`` returns the outputs for the state
    measured at t (``state`` = position, orientation, twist, q, qd as published by the dynamics).
    The returned ``tau`` covers the whole body (URDF joint order), zero on joints not driven.
    """

    def __init__(
        self,
        arm: FreeFloatingArm,
        law: ComputedTorqueLaw,
        trajectory_spec: Mapping,
        reach: tuple[str, float] | None = None,
    ):
        self.arm, self.law, self.spec = arm, law, trajectory_spec
        self.reach = reach  # (centre joint, reach m) for the out-of-reach check
        self.trajectory = None
        self.q_posture = np.zeros(arm.n)
        self.anchor = None  # p0 (3), R0 (3x3), R_base0 (3x3)

    def start(self, state: Mapping[str, np.ndarray]) -> None:
        from components.controller.trajectory import build_cartesian
        from components.errors import ConfigError

        self.arm.set_state(state["position"], state["orientation"], state["twist"], state["q"], state["qd"])
        p0, R0 = self.arm.pose()
        self.q_posture = np.asarray(state["q"], dtype=float)[self.arm.body_arm].copy()
        self.anchor = (p0, R0, self.arm.R_base)
        self.trajectory = build_cartesian(self.spec, *self.anchor)
        if self.reach is not None:
            joint, reach = self.reach
            centre = self.arm.joint_origin(joint)
            for key, point in self.trajectory.checkpoints():
                distance = float(np.linalg.norm(point - centre))
                if distance > reach:
                    raise ConfigError(
                        f"trajectory.{key}",
                        f"out of reach: the path passes {distance:.3f} m from "
                        f"{joint}, the arm reaches at most {reach:.3f} m",
                    )

    def restore(self, p0, R0, R_base0, q_posture) -> None:
        """Take a saved anchor and posture (the component's set_state): the same trajectory as
        the instance that saved them, without ``start``'s measurement and reach check."""
        from components.controller.trajectory import build_cartesian

        self.anchor = (np.asarray(p0, float), np.asarray(R0, float), np.asarray(R_base0, float))
        self.q_posture = np.asarray(q_posture, dtype=float).copy()
        self.trajectory = build_cartesian(self.spec, *self.anchor)

    def step(self, t: float, state: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        self.arm.set_state(state["position"], state["orientation"], state["twist"], state["q"], state["qd"])
        s = self.arm.compute(self.law.base_model)
        d = self.trajectory.sample(t)
        out = self.law.control(s, d, self.q_posture)
        tau = np.zeros(self.arm.n_body)
        tau[self.arm.body_arm] = out.tau
        return {
            "tau": tau,
            "ee_position": s.p,
            "ee_position_desired": d.p,
            "ee_error": out.error,
            "ee_orientation": s.quat,
            "ee_orientation_desired": matrix_to_quat(d.R),
            "ee_twist": s.xdot,
            "sigma_min": np.float64(out.sigma_min),
        }
