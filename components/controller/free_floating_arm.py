r"""The model of a free-floating manipulator for computed-torque control: its Pinocchio model and
one arm's Generalized-Jacobian terms at a measured state (Ramón, Pomares, Felicetti, IAC-22,
eqs. 1-7; the law, eqs. 6 and 8, is :mod:`components.controller.computed_torque`). Plain classes,
no bus, no I/O.

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
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from components.controller import kernels


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


def load_model(urdf, locked: Mapping[str, float]):
    """(model, mimics, path): the body's Pinocchio model on a free flyer with the ``locked`` joints
    welded at their positions, its mimic joints (joint -> (followed, multiplier, offset)) and the
    URDF's path. ``urdf``: a parsed URDF (``UrdfModel``) or a path."""
    import pinocchio as pin

    mimics = {}
    if hasattr(urdf, "text"):  # a UrdfModel: the text as parsed, package URIs resolved
        mimics = urdf.mimics
        # Pinocchio's own mimic joints are not in computeAllTerms: the mimic joints are
        # independent in the model, and the constraint is applied to M, c and J (compute)
        full = pin.buildModelFromXML(urdf.text, pin.JointModelFreeFlyer())
        urdf = urdf.path
    else:
        full = pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer())
    if not locked:
        return full, mimics, urdf
    reference = pin.neutral(full)
    for name, value in locked.items():
        joint = full.joints[full.getJointId(name)]
        if joint.nq == 2:  # continuous joint: (cos, sin)
            reference[joint.idx_q : joint.idx_q + 2] = math.cos(value), math.sin(value)
        else:
            reference[joint.idx_q] = value
    return pin.buildReducedModel(full, [full.getJointId(n) for n in locked], reference), mimics, urdf


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
        locked = dict(locked or {})
        model, mimics, path = load_model(urdf, locked)
        model.gravity = pin.Motion.Zero()
        self.model, self.data = model, model.createData()
        self.body_joints, self.arm_joints = list(body_joints), list(arm_joints)
        self.n_body, self.n = len(self.body_joints), len(self.arm_joints)
        self._map_body(locked)
        self.locked = locked
        self._locked_body = [(self.body_joints.index(j), j, float(locked[j])) for j in locked]
        self.body_arm = np.array([self.body_joints.index(j) for j in self.arm_joints])
        self.arm_v = np.array([model.joints[model.getJointId(j)].idx_v for j in self.arm_joints])
        self._order_velocities(locked)
        self._G = self._mimic_reduction(mimics, locked)
        if not model.existFrame(end_effector):
            raise ValueError(f"end_effector: {end_effector!r} is not a frame of {Path(path).name}")
        self.ee = model.getFrameId(end_effector)
        self.q_pin = pin.neutral(model)
        self.v_pin = np.zeros(model.nv)
        self._R_base = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))

    def _map_body(self, locked: Mapping[str, float]) -> None:
        """The body's layout (URDF order) -> Pinocchio's q and v indices; locked joints are not in
        the model, continuous joints take two q entries (cos, sin)."""
        model = self.model
        q1_body, q1_pin, v_body, v_pin = [], [], [], []
        self._q2: list[tuple[int, int]] = []
        for k, name in enumerate(self.body_joints):
            if name in locked:
                continue
            joint = model.joints[model.getJointId(name)]
            if joint.nv == 0:  # a mimic joint: Pinocchio moves it with the joint it follows
                continue
            if joint.nq == 2:
                self._q2.append((joint.idx_q, k))
            else:
                q1_body.append(k)
                q1_pin.append(joint.idx_q)
            v_body.append(k)
            v_pin.append(joint.idx_v)
        self._q1_body, self._q1_pin = np.array(q1_body, dtype=int), np.array(q1_pin, dtype=int)
        self._v_body, self._v_pin = np.array(v_body, dtype=int), np.array(v_pin, dtype=int)

    def _order_velocities(self, locked: Mapping[str, float]) -> None:
        """The unactuated velocity coordinates (the base's 6, then the passive joints) and the
        (base, arm) ordering of all of them; ValueError when they do not cover the model."""
        model = self.model
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

    def _mimic_reduction(self, mimics: Mapping, locked: Mapping[str, float]) -> np.ndarray | None:
        """G of the passive mimic joints (None without any): ValueError when a driven joint takes part."""
        # mimic joints (v_k = multiplier v_f, both passive): v_b = G v_b', M_bb' = G^T M_bb G,
        # [M_bm, c_b]' = G^T [M_bm, c_b], J_b' = J_b G (the constraint's Jacobian is constant)
        model = self.model
        pairs = [(j, f, m) for j, (f, m, _) in mimics.items() if j not in locked and f not in locked]
        for j, f, _ in pairs:
            if j in self.arm_joints or f in self.arm_joints:
                raise ValueError(f"joints: {j!r} mimics {f!r}; a driven joint can neither mimic nor be mimicked")
        if not pairs:
            return None
        base = list(self.base_v)
        drop = [base.index(model.joints[model.getJointId(j)].idx_v) for j, _, _ in pairs]
        G = np.eye(len(base))
        for (_, f, m), k in zip(pairs, drop):
            G[k, :] = 0.0
            G[k, base.index(model.joints[model.getJointId(f)].idx_v)] = m
        return np.ascontiguousarray(np.delete(G, drop, axis=1))

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
