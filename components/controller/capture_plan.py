r"""When and how to reach a tumbling target's grapple (issue 33): prediction of the grapple's
motion, inverse kinematics along it, the windows in which the arm can follow it, and the
joint-space move that brings the arm there. Plain classes, no bus, no I/O; the capture controller
(:mod:`components.controller.capture`) uses them.

Prediction (``RigidPrediction``)
--------------------------------
Over a planning horizon (tens of seconds) the fitted polynomials of the estimator diverge; the
target is instead taken as a rigid body turning at its estimated angular velocity ``w`` about a
point ``c`` that moves with the servicer's base (a target station-kept by the servicer: both
co-move with LVLH). With the base's origin ``p_b`` and twist ``(v_b, w_b)`` (W), the grapple's
velocity is ``v_g = v_b + w_b x (c - p_b) + w x (p_g - c)``, linear in ``c``:

    [w_b - w]x c = v_g - v_b + w_b x p_b - w x p_g,

solved in least squares (``c`` along ``w - w_b`` is free and does not matter). Then

    R_g(t) = exp(w dt) R_g,   p_g(t) = c(t) + exp(w dt) (p_g - c),   c(t) = c + (v_b + w_b x (c - p_b)) dt,

with velocities ``v = dc/dt + w x (p_g(t) - c(t))`` and ``w``. A torque-free tumble about an axis
that is not principal precesses: the prediction is only good for a few seconds, which is why the
controller re-plans while it waits and closes on the measured grapple, not on the prediction.

Inverse kinematics (``ArmKinematics``)
--------------------------------------
The servicer's Pinocchio model (the controller's own, a free-flyer base) with the base held at a
predicted pose: damped Newton steps on the arm joints, ``dq = J^T (J J^T + mu^2 I)^-1 e`` with
``e = log6(T_ee^-1 T_des)`` and J the frame Jacobian in the end effector's axes, each step at most
0.5 rad per joint (so that a far seed converges instead of jumping about). A solution is
*feasible* when it converged, stays ``joint_margin`` inside the URDF position limits, the smallest
singular value of the arm's Jacobian (W axes, m/rad and 1) is at least ``sigma_min``, and the joint
rates that follow the grapple's twist (``J^-1 (v_g, w_g)``) stay below ``rate_fraction`` of the
URDF velocity limits. ``Verdict.reason`` names the first of these (in that order) that fails, with
its figure.

Joint move (``JointMove``)
--------------------------
The quintic polynomial from (q0, qd0, 0) to (q1, qd1, 0) in time T: the arm leaves where it is,
with its rates, and arrives at the pre-grasp configuration with the rates that follow the grapple.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from components.controller.trajectory import PoseSample
from components.rotations import exp_so3, skew


# --------------------------------------------------------------------------- prediction

class RigidPrediction:
    """The grapple as a point of a rigid body turning at a constant rate about a point that
    co-moves with the servicer's base (module doc). ``sample(t)`` gives p, v, R, w (W); the
    accelerations of the returned PoseSample are those of the constant-rate motion."""

    def __init__(self, t: float, grasp: PoseSample, base_p, base_v, base_w):
        self.t = float(t)
        self.p, self.R, self.w = np.array(grasp.p, float), np.array(grasp.R, float), np.array(grasp.w, float)
        p_b, v_b, w_b = (np.asarray(x, dtype=float) for x in (base_p, base_v, base_w))
        rhs = grasp.v - v_b + np.cross(w_b, p_b) - np.cross(self.w, self.p)
        self.c = np.linalg.lstsq(skew(w_b - self.w), rhs, rcond=None)[0]
        self.v_c = v_b + np.cross(w_b, self.c - p_b)
        self.r = self.p - self.c

    @property
    def rate(self) -> float:
        """|w| (rad/s)."""
        return float(np.linalg.norm(self.w))

    def sample(self, t: float) -> PoseSample:
        dt = t - self.t
        E = exp_so3(self.w * dt)
        r = E @ self.r
        v = self.v_c + np.cross(self.w, r)
        return PoseSample(self.c + self.v_c * dt + r, v, np.cross(self.w, np.cross(self.w, r)), E @ self.R,
                          self.w.copy(), np.zeros(3))


# --------------------------------------------------------------------------- kinematics

@dataclass(frozen=True)
class Verdict:
    """One inverse-kinematics solution judged for following the grapple.

    | field | unit | meaning |
    |---|---|---|
    | q | rad (n) | arm joints (NaN when it did not converge) |
    | qd | rad/s (n) | joint rates that follow the grapple's twist |
    | feasible | - | every check passed |
    | reason | - | the first check that failed, with its figure ('' when feasible) |
    | score | - | how far inside the limits (min of the margins' ratios; < 1: infeasible) |
    """
    q: np.ndarray
    qd: np.ndarray
    feasible: bool
    reason: str
    score: float


@dataclass(frozen=True)
class Limits:
    """What the planner asks of a configuration (module doc)."""
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    joint_margin: float
    sigma_min: float
    rate_fraction: float
    reach: float


class ArmKinematics:
    """Inverse kinematics of one arm of a free-flyer Pinocchio model with the base held still
    (module doc). ``names`` are the arm joints (for messages)."""

    ITERATIONS = 30
    TOLERANCE = 1e-7         # |log6| (m, rad) at convergence
    DAMPING = 1e-3
    MAX_STEP = 0.5           # rad: the largest joint change of one Newton step (far seeds converge)

    def __init__(self, model, arm_v: np.ndarray, arm_q: np.ndarray, ee: int, shoulder: int,
                 names: list[str], limits: Limits):
        import pinocchio as pin

        self.pin, self.model, self.data = pin, model, model.createData()
        self.arm_v, self.arm_q, self.ee, self.shoulder = arm_v, arm_q, ee, shoulder
        self.names, self.limits = names, limits

    def _configure(self, q_pin: np.ndarray, q: np.ndarray) -> np.ndarray:
        x = q_pin.copy()
        x[self.arm_q] = q
        return x

    def solve(self, q_pin: np.ndarray, target, q_seed: np.ndarray) -> np.ndarray | None:
        """Arm joints putting the end effector at ``target`` (a pin.SE3 in W) with the rest of
        the configuration ``q_pin`` (base pose, other joints) held; None when it does not converge."""
        pin, model, data = self.pin, self.model, self.data
        q = np.array(q_seed, dtype=float)
        for _ in range(self.ITERATIONS):
            x = self._configure(q_pin, q)
            pin.forwardKinematics(model, data, x)
            M = pin.updateFramePlacement(model, data, self.ee)
            e = pin.log6(M.actInv(target)).vector
            if float(e @ e) < self.TOLERANCE ** 2:
                return q
            J = pin.computeFrameJacobian(model, data, x, self.ee, pin.LOCAL)[:, self.arm_v]
            dq = J.T @ np.linalg.solve(J @ J.T + self.DAMPING ** 2 * np.eye(6), e)
            size = float(np.max(np.abs(dq)))
            q = q + (dq if size <= self.MAX_STEP else dq * (self.MAX_STEP / size))
        return None

    def judge(self, q_pin: np.ndarray, q: np.ndarray | None, twist: np.ndarray, point: np.ndarray) -> Verdict:
        """Feasibility of ``q`` (from ``solve``) for following ``twist`` (v, w of the grapple, W)
        at ``point`` (W)."""
        n, L = self.arm_q.size, self.limits
        if q is None:
            nan = np.full(n, math.nan)
            distance = self.shoulder_distance(q_pin, point)
            where = ("the arm reaches" if distance > L.reach else
                     "within the arm's reach but not in this orientation; the arm reaches")
            return Verdict(nan, nan, False, f"no inverse kinematics solution: the grasp point is {distance:.2f} m "
                                            f"from the shoulder, {where} {L.reach:.2f} m", 0.0)
        pin, model, data = self.pin, self.model, self.data
        x = self._configure(q_pin, q)
        pin.computeJointJacobians(model, data, x)
        pin.updateFramePlacements(model, data)
        J = pin.getFrameJacobian(model, data, self.ee, pin.LOCAL_WORLD_ALIGNED)[:, self.arm_v]
        sigma = np.linalg.svd(J, compute_uv=False)
        qd = np.linalg.solve(J, twist) if sigma[-1] > 1e-9 else np.full(n, math.inf)
        margins = [(min(float(np.min(q - L.lower)), float(np.min(L.upper - q))) / L.joint_margin,
                    "joint position", q),
                   (float(sigma[-1]) / L.sigma_min, "singularity", None),
                   (float(np.min(L.rate_fraction * L.velocity / np.maximum(np.abs(qd), 1e-12))), "joint rate", qd)]
        score = min(m for m, _, _ in margins)
        reason = ""
        if score < 1.0:     # the first that fails, in this order: a singular arm's rates follow from it
            ratio, what, values = next(m for m in margins if m[0] < 1.0)
            if what == "joint position":
                gap = np.minimum(q - L.lower, L.upper - q)
                i = int(np.argmin(gap))
                reason = (f"{self.names[i]} at {q[i]:.3g} rad is within {L.joint_margin:g} rad of its URDF limits "
                          f"[{L.lower[i]:.3g}, {L.upper[i]:.3g}]")
            elif what == "singularity":
                reason = (f"the arm is near a singularity (smallest singular value of its Jacobian "
                          f"{sigma[-1]:.3g} < {L.sigma_min:g})")
            else:
                i = int(np.argmax(np.abs(qd) / L.velocity))
                reason = (f"following the grapple needs {self.names[i]} at {abs(qd[i]):.3g} rad/s, more than "
                          f"{L.rate_fraction:g} of its URDF velocity limit {L.velocity[i]:.3g} rad/s")
        return Verdict(np.array(q), qd, score >= 1.0, reason, score)

    def shoulder_distance(self, q_pin: np.ndarray, point: np.ndarray) -> float:
        """Distance (m) from the shoulder joint to a point of W, the base at ``q_pin``."""
        self.pin.forwardKinematics(self.model, self.data, q_pin)
        return float(np.linalg.norm(point - self.data.oMi[self.shoulder].translation))


# --------------------------------------------------------------------------- joint move

class JointMove:
    """Quintic joint trajectory from (q0, qd0, qdd 0) at t0 to (q1, qd1, qdd 0) at t0 + T; beyond
    t0 + T it continues at the final rate (the caller switches to tracking there)."""

    def __init__(self, t0: float, T: float, q0, qd0, q1, qd1):
        if not T > 0.0:
            raise ValueError(f"JointMove: expected a positive duration, got {T}")
        self.t0, self.T = float(t0), float(T)
        q0, qd0, q1, qd1 = (np.asarray(x, dtype=float) for x in (q0, qd0, q1, qd1))
        self.q1, self.qd1 = q1.copy(), qd1.copy()
        d = q1 - q0 - qd0 * T
        e = (qd1 - qd0) * T
        # q(u) = q0 + qd0 T u + c3 u^3 + c4 u^4 + c5 u^5, u = (t - t0)/T, with q(1) = q1, q'(1) = qd1 T, q''(1) = 0
        self.c = np.stack([q0, qd0 * T, 10.0 * d - 4.0 * e, -15.0 * d + 7.0 * e, 6.0 * d - 3.0 * e])

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, qd, qdd) at t (rad, rad/s, rad/s^2)."""
        T = self.T
        u = (t - self.t0) / T
        if u >= 1.0:
            return self.q1 + self.qd1 * (t - self.t0 - T), self.qd1.copy(), np.zeros_like(self.qd1)
        u = max(u, 0.0)
        c0, c1, c3, c4, c5 = self.c
        q = c0 + u * (c1 + u * u * (c3 + u * (c4 + u * c5)))
        qd = (c1 + u * u * (3.0 * c3 + u * (4.0 * c4 + 5.0 * u * c5))) / T
        qdd = (u * (6.0 * c3 + u * (12.0 * c4 + 20.0 * u * c5))) / (T * T)
        return q, qd, qdd

    def peak_rate(self, samples: int = 41) -> np.ndarray:
        """max |qd| per joint over the move (sampled)."""
        return np.max([np.abs(self.sample(self.t0 + self.T * k / (samples - 1))[1]) for k in range(samples)], axis=0)

    def to_array(self) -> np.ndarray:
        return np.concatenate([[self.t0, self.T], self.c.ravel(), self.q1, self.qd1])

    @classmethod
    def from_array(cls, x, n: int) -> "JointMove":
        x = np.asarray(x, dtype=float)
        move = cls.__new__(cls)
        move.t0, move.T = float(x[0]), float(x[1])
        move.c = x[2:2 + 5 * n].reshape(5, n).copy()
        move.q1, move.qd1 = x[2 + 5 * n:2 + 6 * n].copy(), x[2 + 6 * n:2 + 7 * n].copy()
        return move
