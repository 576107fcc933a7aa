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

Windows (``WindowPlanner``)
---------------------------
While the arm waits, the planner predicts the grapple's motion at the estimated rate and looks,
from ``SHORTEST_APPROACH`` on in steps of ``PLAN_STEP``, for the earliest meeting time after which
the arm can follow the grapple for ``closing_time + tolerance_time + WINDOW_MARGIN``: a feasible
solution at every sample of that window, moving continuously, and a pre-grasp configuration (the
grasp frame moved back ``standoff`` along its z) the arm reaches by then within
``MOVE_RATE_FRACTION`` of its rate limits. It scans one turn of the relative tumble (at most
``LONGEST_SCAN``, and not past ``capture_timeout``); a grapple that turns less than ``STILL`` over
that, or slower than the estimator can tell, is still: its one pose is its whole turn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from components.controller.capture_estimate import GraspEstimator
from components.controller.capture_settings import CaptureSettings
from components.controller.free_floating_arm import ArmState, FreeFloatingArm
from components.controller.trajectory import PoseSample
from components.rotations import exp_so3, skew

PLAN_STEP = 0.5  # s between the planner's samples of the predicted grapple motion
WINDOW_MARGIN = 0.5  # s of following beyond closing_time + tolerance_time a window must offer
LONGEST_SCAN = 180.0  # s: the planner looks no further ahead than this
SHORTEST_APPROACH = 1.0  # s: the quickest joint move onto the pre-grasp pose
STILL = 0.02  # rad over LONGEST_SCAN: a grapple turning less is taken as still
MOVE_RATE_FRACTION = 0.8  # share of the URDF velocity limits a joint move may reach
CONTINUITY = 0.5  # rad: the largest joint change between two samples of one window


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
        return PoseSample(
            self.c + self.v_c * dt + r, v, np.cross(self.w, np.cross(self.w, r)), E @ self.R, self.w.copy(), np.zeros(3)
        )


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
    TOLERANCE = 1e-7  # |log6| (m, rad) at convergence
    DAMPING = 1e-3
    MAX_STEP = 0.5  # rad: the largest joint change of one Newton step (far seeds converge)

    def __init__(
        self, model, arm_v: np.ndarray, arm_q: np.ndarray, ee: int, shoulder: int, names: list[str], limits: Limits
    ):
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
            if float(e @ e) < self.TOLERANCE**2:
                return q
            J = pin.computeFrameJacobian(model, data, x, self.ee, pin.LOCAL)[:, self.arm_v]
            dq = J.T @ np.linalg.solve(J @ J.T + self.DAMPING**2 * np.eye(6), e)
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
            where = (
                "the arm reaches"
                if distance > L.reach
                else "within the arm's reach but not in this orientation; the arm reaches"
            )
            return Verdict(
                nan,
                nan,
                False,
                f"no inverse kinematics solution: the grasp point is {distance:.2f} m "
                f"from the shoulder, {where} {L.reach:.2f} m",
                0.0,
            )
        pin, model, data = self.pin, self.model, self.data
        x = self._configure(q_pin, q)
        pin.computeJointJacobians(model, data, x)
        pin.updateFramePlacements(model, data)
        J = pin.getFrameJacobian(model, data, self.ee, pin.LOCAL_WORLD_ALIGNED)[:, self.arm_v]
        sigma = np.linalg.svd(J, compute_uv=False)
        qd = np.linalg.solve(J, twist) if sigma[-1] > 1e-9 else np.full(n, math.inf)
        margins = [
            (min(float(np.min(q - L.lower)), float(np.min(L.upper - q))) / L.joint_margin, "joint position", q),
            (float(sigma[-1]) / L.sigma_min, "singularity", None),
            (float(np.min(L.rate_fraction * L.velocity / np.maximum(np.abs(qd), 1e-12))), "joint rate", qd),
        ]
        score = min(m for m, _, _ in margins)
        reason = ""
        if score < 1.0:  # the first that fails, in this order: a singular arm's rates follow from it
            _ratio, what, _values = next(m for m in margins if m[0] < 1.0)
            if what == "joint position":
                gap = np.minimum(q - L.lower, L.upper - q)
                i = int(np.argmin(gap))
                reason = (
                    f"{self.names[i]} at {q[i]:.3g} rad is within {L.joint_margin:g} rad of its URDF limits "
                    f"[{L.lower[i]:.3g}, {L.upper[i]:.3g}]"
                )
            elif what == "singularity":
                reason = (
                    f"the arm is near a singularity (smallest singular value of its Jacobian "
                    f"{sigma[-1]:.3g} < {L.sigma_min:g})"
                )
            else:
                i = int(np.argmax(np.abs(qd) / L.velocity))
                reason = (
                    f"following the grapple needs {self.names[i]} at {abs(qd[i]):.3g} rad/s, more than "
                    f"{L.rate_fraction:g} of its URDF velocity limit {L.velocity[i]:.3g} rad/s"
                )
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
    def from_array(cls, x, n: int) -> JointMove:
        x = np.asarray(x, dtype=float)
        move = cls.__new__(cls)
        move.t0, move.T = float(x[0]), float(x[1])
        move.c = x[2 : 2 + 5 * n].reshape(5, n).copy()
        move.q1, move.qd1 = x[2 + 5 * n : 2 + 6 * n].copy(), x[2 + 6 * n : 2 + 7 * n].copy()
        return move


# --------------------------------------------------------------------------- windows


@dataclass(frozen=True)
class Look:
    """One look for a window (module doc).

    | field | meaning |
    |---|---|
    | approach | (duration s, q rad, qd rad/s) of the move onto the pre-grasp configuration, or None |
    | reason | why there is no approach now: the check that failed at the best sample ('' when waiting for a window) |
    | give_up | why the capture should be given up ('' while a window may still come) |
    """

    approach: tuple[float, np.ndarray, np.ndarray] | None
    reason: str = ""
    give_up: str = ""


class WindowPlanner:
    """The planner of one servicer's arm (module doc): ``look`` gives the approach to start now,
    or why not, and whether to give up."""

    def __init__(self, arm: FreeFloatingArm, settings: CaptureSettings):
        self.arm, self.cfg = arm, settings
        shoulder = arm.model.getJointId(settings.shoulder)
        names = list(arm.arm_joints)
        arm_q = np.array([arm.model.joints[arm.model.getJointId(j)].idx_q for j in names])
        self.kinematics = ArmKinematics(
            arm.model,
            arm.arm_v,
            arm_q,
            arm.ee,
            shoulder,
            names,
            Limits(
                np.asarray(settings.arm_lower, float),
                np.asarray(settings.arm_upper, float),
                np.asarray(settings.arm_velocity, float),
                settings.joint_margin,
                settings.singularity_margin,
                settings.rate_fraction,
                settings.reach,
            ),
        )

    def look(
        self, t: float, s: ArmState, g: PoseSample, base_p, base_twist, estimator: GraspEstimator, q_posture: np.ndarray
    ) -> Look:
        """The window from the grapple's estimate g at t, the base's position and twist (W) and the
        arm's state s; ``q_posture`` seeds the inverse kinematics besides the arm's configuration."""
        cfg = self.cfg
        base_v, base_w = np.asarray(base_twist[:3], dtype=float), np.asarray(base_twist[3:], dtype=float)
        prediction = RigidPrediction(t, g, base_p, base_v, base_w)
        distance = self.kinematics.shoulder_distance(self.arm.q_pin, prediction.c)
        # the tumble relative to the servicer (both co-rotate with LVLH); one that turns the grapple
        # by less than STILL over the longest scan is still: its one pose is its whole turn
        relative_rate = float(np.linalg.norm(prediction.w - base_w))
        fit = estimator.fit
        assert fit is not None  # g is its estimate
        negligible = relative_rate * LONGEST_SCAN < STILL
        unresolved = not negligible and estimator.full and relative_rate < 3.0 * fit.rate_sigma  # noise
        still = negligible or unresolved
        turn = 0.0 if still else 2.0 * math.pi / relative_rate
        horizon = min(turn, LONGEST_SCAN, max(cfg.capture_timeout - t - SHORTEST_APPROACH, 0.0))
        approach, reason, found = self._plan(t, s, prediction, horizon, q_posture)
        if approach is not None:
            return Look(approach)
        if not (t >= cfg.capture_timeout or (not found and horizon >= turn)):
            return Look(None, reason)
        if turn == 0.0:
            scope = (
                "(it does not turn)"
                if not unresolved
                else f"(it does not turn that the estimator can tell: {math.degrees(relative_rate):.2g} deg/s, "
                f"standard error {math.degrees(fit.rate_sigma):.2g} deg/s)"
            )
        else:
            scope = (
                f"{'in a whole turn of the tumble' if horizon >= turn else 'by capture_timeout'} "
                f"({math.degrees(relative_rate):.3g} deg/s about a centre {distance:.3g} m from the "
                f"shoulder; the arm reaches {cfg.reach:.3g} m)"
            )
        return Look(None, reason, f"the grapple never comes where the arm can follow it {scope}: {reason}")

    def _plan(self, t: float, s: ArmState, prediction: RigidPrediction, horizon: float, q_posture: np.ndarray):
        """(the approach: (duration, q, qd) of the pre-grasp configuration, or None; the reason of
        the best infeasible sample when there is none; whether a window exists within the horizon).

        The meeting time runs from SHORTEST_APPROACH on in steps of PLAN_STEP. At each the grapple's
        pose is solved from the last feasible solution, or, after an infeasible one, from every
        seed (the best is kept); a window is a run of feasible solutions that move continuously.
        The first meeting time at which the window starts and the pre-grasp pose can be reached in
        time within the rate limits is taken if it is at most approach_time away."""
        cfg = self.cfg
        q_pin = self.arm.q_pin.copy()
        window = int(math.ceil((cfg.closing_time + cfg.tolerance_time + WINDOW_MARGIN) / PLAN_STEP))
        samples = int(horizon / PLAN_STEP) + window + 1
        seeds = ik_seeds(s.q, q_posture)
        best, q_prev, run, chain = None, None, 0, []
        for k in range(samples):
            g = prediction.sample(t + SHORTEST_APPROACH + k * PLAN_STEP)
            verdict = self._solve(q_pin, g, q_prev, seeds, s.q)
            chain.append(verdict.q)
            if verdict.feasible and (q_prev is None or np.max(np.abs(verdict.q - q_prev)) < CONTINUITY):
                run += 1
            else:
                run = 1 if verdict.feasible else 0
                if not verdict.feasible and (best is None or verdict.score > best.score):
                    best = verdict
            q_prev = verdict.q if verdict.feasible else None
            if run > window:
                start = k - window  # the window's first sample: the meeting time
                duration = SHORTEST_APPROACH + start * PLAN_STEP
                if duration > cfg.approach_time:
                    return None, best.reason if best else "", True  # further away: wait for it
                plan = self._pre_grasp(q_pin, prediction.sample(t + duration), chain[start], s, duration)
                if plan is not None:
                    return (duration, *plan), "", True
                run -= 1  # too far to reach in time: a later meeting
        return None, best.reason if best else "no window", False

    def _solve(self, q_pin, g: PoseSample, q_prev, seeds, q_now) -> Verdict:
        """The grapple's pose solved from q_prev (when feasible), else from every seed: of the
        feasible solutions the one the arm reaches soonest from ``q_now`` (the largest joint
        change over its rate limit), or the best infeasible one (its reason)."""
        kin = self.kinematics
        twist = np.concatenate([g.v, g.w])
        target = _se3(g.R, g.p)
        if q_prev is not None:
            verdict = kin.judge(q_pin, kin.solve(q_pin, target, q_prev), twist, g.p)
            if verdict.feasible:
                return verdict
        if kin.shoulder_distance(q_pin, g.p) > self.cfg.reach:
            return kin.judge(q_pin, None, twist, g.p)
        verdicts = [kin.judge(q_pin, kin.solve(q_pin, target, seed), twist, g.p) for seed in seeds]
        feasible = [v for v in verdicts if v.feasible]
        if feasible:
            return min(feasible, key=lambda v: float(np.max(np.abs(v.q - q_now) / self.cfg.arm_velocity)))
        return max(verdicts, key=lambda v: v.score)

    def _pre_grasp(self, q_pin, g: PoseSample, seed: np.ndarray, s: ArmState, duration: float):
        """(q, qd) at the pre-grasp pose of the predicted grapple g, or None when the move there
        in ``duration`` would exceed the rate limits or the configuration is not feasible."""
        cfg, kin = self.cfg, self.kinematics
        z = g.R[:, 2]
        p = g.p - cfg.standoff * z
        v = g.v - cfg.standoff * np.cross(g.w, z)
        q = kin.solve(q_pin, _se3(g.R, p), seed)
        verdict = kin.judge(q_pin, q, np.concatenate([v, g.w]), p)
        if not verdict.feasible:
            return None
        move = JointMove(0.0, duration, s.q, s.qd, verdict.q, verdict.qd)
        if np.any(move.peak_rate() > MOVE_RATE_FRACTION * cfg.arm_velocity):
            return None
        return verdict.q, verdict.qd


def ik_seeds(q: np.ndarray, q_posture: np.ndarray) -> list[np.ndarray]:
    """Starting configurations for the inverse kinematics: the arm now and its posture, each
    also with the elbow and the wrist turned over (a 6-joint arm of the UR kind: elbow q2 + q3,
    -q3, q4 + q3; wrist q4 + pi, -q5, q6 + pi), wrapped to (-pi, pi]."""

    def elbow(x):
        return np.array([x[0], x[1] + x[2], -x[2], x[3] + x[2], x[4], x[5]])

    def wrist(x):
        return np.array([x[0], x[1], x[2], x[3] + math.pi, -x[4], x[5] + math.pi])

    seeds = [q.copy(), q_posture.copy()]
    if q.size == 6:
        seeds += [f(x) for x in seeds for f in (elbow, wrist, lambda y: wrist(elbow(y)))]
    return [(x + math.pi) % (2.0 * math.pi) - math.pi for x in seeds]


def _se3(R: np.ndarray, p: np.ndarray):
    import pinocchio as pin

    return pin.SE3(np.ascontiguousarray(R), np.asarray(p, dtype=float))
