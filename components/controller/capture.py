r"""Capture of a tumbling target by a free-floating servicer, and the detumbling of the assembly
(issues 23 and 33). Plain classes, no bus, no I/O; ``controller.capture``
(:mod:`components.controller.capture_component`) wraps them.

Frames and measurements
-----------------------
W is the dynamics' world frame (docs/design.md §2). The end effector's frame (EE, a link of the
servicer's URDF, z out of the tool) must be brought onto the target's *grasp frame* (the
fixture's frame, z into the target): at capture the two coincide. A pose sensor measures the grasp
frame relative to the EE at time ``t_m`` and delivers it later (latency): ``p`` the grasp origin in
EE axes (m), ``q = q_ee_grasp``. The grasp pose in W at ``t_m`` is

    p_g = p_ee(t_m) + R_ee(t_m) p,    R_g = R_ee(t_m) R(q),

with the EE pose at ``t_m`` (not now) from the Pinocchio model at the measured base and joint state:
the controller keeps the EE poses of the last ``pose_history`` seconds by time (``PoseHistory``),
interpolated between steps (linear in position, geodesic in rotation), extrapolated with the EE
twist when ``t_m`` is newer than the last state.

Estimator (``fit_motion``)
--------------------------
A fading-memory least-squares fit over the last N grasp poses (times t_i, latest t_N,
``tau_i = t_i - t_N``), weights ``exp(tau_i / memory)``:

    position:  p(tau)   = p_0 + v tau + a tau^2 / 2
    attitude:  phi(tau) = phi_0 + w tau + dw tau^2 / 2,   phi_i = log(R_i R_N^T)  (W axes)

(one order less for 2 samples, a constant for 1). For a rotation ``R(tau) = exp(phi(tau)) R_N``
the angular velocity (W) is ``J_l(phi) phi'`` (J_l: left Jacobian of SO(3)); at phi = 0 that is phi'
itself and the second derivative of phi is the angular acceleration (the Jacobian's first-order term
``[phi]x phi' / 2`` vanishes there), so the fit's slope and curvature are the grasp frame's angular
velocity and acceleration at t_N. A rigid motion with constant linear acceleration and a constant
angular velocity is recovered exactly. The estimate at the current time t extrapolates the
polynomials to ``tau = t - t_N``: ``R = exp(phi) R_N``, ``w = J_l(phi) phi'``,
``dw = J_l(phi) phi'' + J_l(phi)' phi'``. Without new measurements the last fit goes on being
extrapolated (``grasp_valid`` = 0 keeps measurements out, not the fit). Deterministic (LAPACK
least squares on the same numbers).

Phases (``phase`` output)
-------------------------
The approach is planned in joint space and the close is made in Cartesian space, as servicing
arms do (:mod:`components.controller.capture_plan` has the prediction, the inverse kinematics and
the joint move):

0, wait: the arm holds its initial configuration (the *posture*; joint PD with the computed-torque
terms below). Once the estimator holds N measurements, every ``replan_period`` the planner
predicts the grapple's motion (a rigid tumble at the estimated rate) and looks for the earliest
meeting time, from 1 s on, after which the arm can follow the grapple for ``closing_time +
tolerance_time`` and half a second more: an inverse-kinematics solution at every half second of
that window (from the arm's configuration, its posture, and each with the wrist turned over),
inside the joint limits by ``joint_margin``, with the smallest singular value of the Jacobian above
``singularity_margin`` and the rates that follow the grapple within ``rate_fraction`` of the URDF
limits; and the pre-grasp configuration must be reachable by then within 0.8 of the rate limits.
A meeting within ``approach_time`` starts the approach; a later one is waited for (the arm waits
for the grapple to come round), re-planned as the estimate improves.

1, approach: a quintic joint move from the arm's configuration and rates to the *pre-grasp*
configuration at the meeting time (the predicted grasp frame moved back ``standoff`` along its z)
with the rates that follow it, tracked by joint-space computed torque ``tau = M* qdd + C*`` (the
base's reaction is in M* and C*).

2, closing: the Cartesian law (below) on the estimated grasp frame carrying the end effector's
offset at the end of the approach (position and rotation vector, both in the grasp frame's axes),
shrunk to zero by a quintic over ``closing_time``: a straight line along the grapple's axis from the
pre-grasp pose, with every derivative of the reference exact (the grasp frame's velocity and
acceleration carried through the offset).

3, track: the reference is the estimated grasp frame (pose, velocity, acceleration). Closing and
track use :class:`ComputedTorqueLaw` (eqs. 6 and 8, Generalized Jacobian, null-space posture at the
initial configuration); the wheels are passive joints of its model (they get no torque before
capture). ``close`` goes to 1 once the estimated errors of the EE relative to the grasp frame
(position, attitude angle, linear velocity, angular velocity: the ``close_errors`` output) have
stayed within their tolerances, and the arm away from singularities (``singularity_margin``), for
``tolerance_time``.

4, retreat: when, in closing or track, the grapple leaves the arm's reach, or following it needs
joint rates or torques beyond the URDF limits for longer than ``limit_window``, or the tolerances
were not met within ``track_time`` (or were, and the grasp still has not closed ``track_time``
after close), or after a capture the grasp opens again (the dynamics released
an overloaded weld), a quintic joint move takes the arm back to its posture over ``approach_time``
(an event ``capture_retreat`` says why) and the planner looks for the next window.

5, captured (the ``captured`` input is 1; latched): the arm holds the joint configuration it had at
capture with a joint PD in torque units and the servicer's Coriolis terms,
``tau = K_p (q_hold - q) - K_d qd + C*``: the welded target's inertia, which the model lacks (an
uncooperative target), dwarfs the servicer's M* at the wrist (M* times a gain in 1/s^2 would hold
the target's load with a few N m/rad: 0.4 rad of wrist deflection in a detumble). With the one
step of delay of a sampled loop the hold is stable for ``K_d h`` well below the smallest eigenvalue
of the assembly's M* (about 5 kg m^2 for models/capture with its 300 kg target: K_d = 100 N m s/rad
at h = 10 ms is, 500 is not) and unstable on the bare arm (M* down to 0.004 kg m^2). The reaction
wheels detumble the assembly:
the bus torque ``T = -k omega`` from the IMU rate omega (bus axes); a wheel torque tau_j about its
axis a_j puts ``-tau_j a_j`` on the bus, so ``tau = A^+ k omega`` (A = [a_j], bus axes). A wheel at
its URDF speed limit gets no torque that would spin it faster; the torques are scaled together
(direction kept) to the URDF effort limits, then by a factor that keeps the measured wrist wrench
within ``grasp_force_limit``/``grasp_torque_limit``: whenever the wrench exceeds a limit by the
ratio r > 1 the factor is divided by r; otherwise it recovers linearly to 1 over
``wrench_recovery_time``. Total momentum is never an input.

6, aborted: the capture is given up and the arm holds its posture, the target free; an event
``capture_aborted`` gives the time and a reason a person can act on. It comes after ``attempts``
retreats (the reason of the last), when a whole turn of the predicted tumble offers no window (the
check that failed at the best sample, with its figure), or at ``capture_timeout`` without an
approach under way (no window, or no estimate). Not capturing is an outcome: the run goes on and
ends normally.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from components.controller.capture_plan import ArmKinematics, JointMove, Limits, RigidPrediction, Verdict
from components.controller.computed_torque import ArmState, ComputedTorqueLaw, FreeFloatingArm, dls_inverse
from components.controller.trajectory import PoseSample, quintic
from components.errors import ComponentError
from components.rotations import exp_so3, log_so3, quat_to_matrix, skew

WAIT, APPROACH, CLOSING, TRACK, RETREAT, CAPTURED, ABORTED = range(7)
PHASES = ("wait", "approach", "closing", "track", "retreat", "captured", "aborted")
EMPTY = np.zeros(0)


# --------------------------------------------------------------------------- SO(3)

def left_jacobian(phi) -> np.ndarray:
    """Left Jacobian of SO(3): d/dt exp(phi) = [J_l(phi) phi']x exp(phi)."""
    phi = np.asarray(phi, dtype=float)
    t2 = float(phi @ phi)
    K = skew(phi)
    if t2 < 1e-4:                                 # series: the closed forms cancel at small angles
        a, b = 0.5 - t2 * (1.0 / 24.0 - t2 / 720.0), 1.0 / 6.0 - t2 * (1.0 / 120.0 - t2 / 5040.0)
    else:
        t = math.sqrt(t2)
        a, b = (1.0 - math.cos(t)) / t2, (t - math.sin(t)) / (t2 * t)
    return np.eye(3) + a * K + b * (K @ K)


def left_jacobian_rate(phi, dphi) -> np.ndarray:
    """d/dt J_l(phi(t)) for phi' = dphi: with J_l = I + a(t) K + b(t) K^2, K = [phi]x, t = |phi|,
    its rate is a' t' K + a K' + b' t' K^2 + b (K' K + K K'), K' = [phi']x, t' = phi . phi' / t."""
    phi, dphi = np.asarray(phi, dtype=float), np.asarray(dphi, dtype=float)
    t2 = float(phi @ phi)
    K, dK = skew(phi), skew(dphi)
    dot = float(phi @ dphi)                                  # t t'
    if t2 < 1e-4:                                            # series (the closed forms cancel)
        a, b = 0.5 - t2 * (1.0 / 24.0 - t2 / 720.0), 1.0 / 6.0 - t2 * (1.0 / 120.0 - t2 / 5040.0)
        da_t = -1.0 / 12.0 + t2 * (1.0 / 180.0 - t2 / 6720.0)   # a'(t) / t
        db_t = -1.0 / 60.0 + t2 * (1.0 / 1260.0 - t2 / 90720.0)  # b'(t) / t
    else:
        t = math.sqrt(t2)
        c, sn = math.cos(t), math.sin(t)
        a, b = (1.0 - c) / t2, (t - sn) / (t2 * t)
        da_t = (t * sn - 2.0 * (1.0 - c)) / (t2 * t2)        # a'(t) / t
        db_t = ((1.0 - c) * t - 3.0 * (t - sn)) / (t2 * t2 * t)
    return (da_t * dot) * K + a * dK + (db_t * dot) * (K @ K) + b * (dK @ K + K @ dK)


# --------------------------------------------------------------------------- estimator

@dataclass(frozen=True)
class MotionFit:
    """A fitted rigid motion about the time ``t`` of its latest measurement (module doc).

    | field | unit | meaning |
    |---|---|---|
    | t | s | time of the latest measurement |
    | p, v, a | m, m/s, m/s^2 | position, velocity, acceleration at t (W) |
    | R | - | the latest measured rotation R_W_grasp, the origin of the rotation vectors |
    | phi, dphi, ddphi | rad, rad/s, rad/s^2 | fitted rotation vector relative to R and its rates at t |
    | rate_sigma | rad/s | standard error of |dphi| from the fit's residuals (NaN: too few measurements) |
    """
    t: float
    p: np.ndarray
    v: np.ndarray
    a: np.ndarray
    R: np.ndarray
    phi: np.ndarray
    dphi: np.ndarray
    ddphi: np.ndarray
    rate_sigma: float = math.nan

    def sample(self, t: float) -> PoseSample:
        """The motion extrapolated to time t (W): p, v, a, R, w, dw."""
        tau = t - self.t
        p = self.p + tau * self.v + (0.5 * tau * tau) * self.a
        phi = self.phi + tau * self.dphi + (0.5 * tau * tau) * self.ddphi
        dphi = self.dphi + tau * self.ddphi
        J = left_jacobian(phi)
        return PoseSample(p, self.v + tau * self.a, self.a.copy(), exp_so3(phi) @ self.R,
                          J @ dphi, J @ self.ddphi + left_jacobian_rate(phi, dphi) @ dphi)

    def to_array(self) -> np.ndarray:
        return np.concatenate([[self.t], self.p, self.v, self.a, self.R.ravel(), self.phi, self.dphi, self.ddphi,
                               [self.rate_sigma]])

    @classmethod
    def from_array(cls, x) -> "MotionFit":
        x = np.asarray(x, dtype=float)
        if x.size != 29:
            raise ValueError(f"state: a motion fit has 29 values, got {x.size}")
        return cls(float(x[0]), x[1:4].copy(), x[4:7].copy(), x[7:10].copy(), x[10:19].reshape(3, 3).copy(),
                   x[19:22].copy(), x[22:25].copy(), x[25:28].copy(), float(x[28]))


def fit_motion(times, positions, rotations, memory: float) -> MotionFit:
    """Fading-memory least-squares fit of a rigid motion to poses (module doc).

    ``times`` (k,) s, increasing; ``positions`` (k, 3) m; ``rotations`` (k, 3, 3) R_W_frame;
    ``memory`` s: weight ``exp((t_i - t_k) / memory)`` (inf: equal weights)."""
    times = np.asarray(times, dtype=float)
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    rotations = np.asarray(rotations, dtype=float).reshape(-1, 3, 3)
    k = times.size
    if k == 0 or positions.shape[0] != k or rotations.shape[0] != k:
        raise ValueError(f"fit_motion: expected as many times, positions and rotations (>= 1), got "
                         f"{k}, {positions.shape[0]}, {rotations.shape[0]}")
    t_ref, R_ref = float(times[-1]), rotations[-1].copy()
    tau = times - t_ref
    span = float(-tau[0]) if k > 1 else 1.0
    if not span > 0.0:
        raise ValueError("fit_motion: expected increasing times")
    u = tau / span                                            # in [-1, 0]: a well-conditioned basis
    Y = np.empty((k, 6))
    Y[:, :3] = positions
    Y[:, 3:] = [log_so3(R @ R_ref.T) for R in rotations]
    order = min(2, k - 1)
    A = np.column_stack([np.ones(k), u, 0.5 * u * u][:order + 1])
    sw = np.sqrt(np.exp(tau / memory)) if math.isfinite(memory) else np.ones(k)
    Aw = A * sw[:, None]
    coef = np.linalg.lstsq(Aw, Y * sw[:, None], rcond=None)[0]
    rate_sigma = math.nan
    if k > order + 1:
        # the slope's standard error: residual variance (weighted, per rotation component) times
        # the slope's entry of (A^T W A)^-1, over the three components
        residual = (Y[:, 3:] - A @ coef[:, 3:]) * sw[:, None]
        variance = float(np.sum(residual * residual)) / (3.0 * (k - order - 1))
        rate_sigma = math.sqrt(3.0 * variance * np.linalg.inv(Aw.T @ Aw)[1, 1]) / span
    c = np.zeros((3, 6))
    c[:order + 1] = coef
    c[1] /= span
    c[2] /= span * span
    return MotionFit(t_ref, c[0, :3], c[1, :3], c[2, :3], R_ref, c[0, 3:], c[1, 3:], c[2, 3:], rate_sigma)


class GraspEstimator:
    """The last ``window`` grasp poses (W) and their ``fit_motion`` (refitted at each new one),
    used once it holds ``minimum`` of them."""

    def __init__(self, window: int, memory: float, minimum: int | None = None):
        if window < 1:
            raise ValueError(f"estimator_window: expected at least 1 measurement, got {window}")
        self.window, self.memory = int(window), float(memory)
        self.minimum = self.window if minimum is None else int(minimum)
        if not 1 <= self.minimum <= self.window:
            raise ValueError(f"estimator_minimum: expected 1 to estimator_window = {self.window} measurements, "
                             f"got {self.minimum}")
        self.t, self.p, self.R = np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3))
        self.fit: MotionFit | None = None

    @property
    def ready(self) -> bool:
        """It holds ``minimum`` measurements: the estimate is used from then on."""
        return self.t.size >= self.minimum

    @property
    def full(self) -> bool:
        """It holds ``window`` measurements: the estimate is as good as it gets."""
        return self.t.size >= self.window

    def add(self, t: float, p, R) -> None:
        if self.t.size and not t > self.t[-1]:
            raise ValueError(f"grasp measurement at t = {t} s is not newer than the last one ({self.t[-1]} s)")
        keep = slice(max(0, self.t.size + 1 - self.window), None)
        self.t = np.append(self.t, t)[keep]
        self.p = np.vstack([self.p, np.reshape(p, (1, 3))])[keep]
        self.R = np.concatenate([self.R, np.reshape(R, (1, 3, 3))])[keep]
        self.fit = fit_motion(self.t, self.p, self.R, self.memory)

    def get_state(self, prefix: str) -> dict[str, np.ndarray]:
        return {f"{prefix}t": self.t.copy(), f"{prefix}p": self.p.copy(), f"{prefix}R": self.R.copy(),
                f"{prefix}fit": self.fit.to_array() if self.fit is not None else EMPTY.copy()}

    def set_state(self, state: Mapping[str, np.ndarray], prefix: str) -> None:
        t = np.asarray(state[f"{prefix}t"], dtype=float).ravel()
        self.t = t.copy()
        self.p = np.asarray(state[f"{prefix}p"], dtype=float).reshape(t.size, 3).copy()
        self.R = np.asarray(state[f"{prefix}R"], dtype=float).reshape(t.size, 3, 3).copy()
        fit = np.asarray(state[f"{prefix}fit"], dtype=float)
        self.fit = MotionFit.from_array(fit) if fit.size else None


class PoseHistory:
    """End-effector poses and twists (W) by time, the last ``span`` seconds (and the one before,
    to interpolate at the oldest times)."""

    def __init__(self, span: float):
        self.span = float(span)
        self.t, self.p, self.R, self.v, self.w = [], [], [], [], []

    @property
    def full(self) -> bool:
        """It spans ``span`` seconds: a time older than its first is older than ``span``."""
        return bool(self.t) and self.t[-1] - self.t[0] >= self.span

    def record(self, t: float, p, R, v, w) -> None:
        entry = (float(t), np.array(p, dtype=float), np.array(R, dtype=float), np.array(v, dtype=float),
                 np.array(w, dtype=float))
        if self.t and t <= self.t[-1]:
            if t < self.t[-1]:
                raise ValueError(f"end-effector pose at t = {t} s is older than the last one ({self.t[-1]} s)")
            for column, value in zip((self.t, self.p, self.R, self.v, self.w), entry):   # same time: replace
                column[-1] = value
            return
        for column, value in zip((self.t, self.p, self.R, self.v, self.w), entry):
            column.append(value)
        while len(self.t) > 2 and self.t[1] <= t - self.span:
            for column in (self.t, self.p, self.R, self.v, self.w):
                del column[0]

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The pose (p, R) at time t; None when t is older than the oldest pose held."""
        if not self.t or t < self.t[0]:
            return None
        if t >= self.t[-1]:
            dt = t - self.t[-1]
            if dt == 0.0:
                return self.p[-1].copy(), self.R[-1].copy()
            return self.p[-1] + dt * self.v[-1], exp_so3(dt * self.w[-1]) @ self.R[-1]
        i = int(np.searchsorted(self.t, t, side="right")) - 1
        u = (t - self.t[i]) / (self.t[i + 1] - self.t[i])
        p = self.p[i] + u * (self.p[i + 1] - self.p[i])
        R = exp_so3(u * log_so3(self.R[i + 1] @ self.R[i].T)) @ self.R[i]
        return p, R

    def get_state(self, prefix: str) -> dict[str, np.ndarray]:
        n = len(self.t)
        return {f"{prefix}t": np.array(self.t, dtype=float), f"{prefix}p": np.array(self.p).reshape(n, 3),
                f"{prefix}R": np.array(self.R).reshape(n, 3, 3), f"{prefix}v": np.array(self.v).reshape(n, 3),
                f"{prefix}w": np.array(self.w).reshape(n, 3)}

    def set_state(self, state: Mapping[str, np.ndarray], prefix: str) -> None:
        t = np.asarray(state[f"{prefix}t"], dtype=float).ravel()
        n = t.size
        self.t = [float(x) for x in t]
        self.p = [x.copy() for x in np.asarray(state[f"{prefix}p"], dtype=float).reshape(n, 3)]
        self.R = [x.copy() for x in np.asarray(state[f"{prefix}R"], dtype=float).reshape(n, 3, 3)]
        self.v = [x.copy() for x in np.asarray(state[f"{prefix}v"], dtype=float).reshape(n, 3)]
        self.w = [x.copy() for x in np.asarray(state[f"{prefix}w"], dtype=float).reshape(n, 3)]


# --------------------------------------------------------------------------- controller

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
        return np.array([self.position_tolerance, self.attitude_tolerance, self.velocity_tolerance,
                         self.rate_tolerance])


#: the estimated errors behind ``close``, in the order of the ``close_errors`` output
CLOSE_ERRORS = ("position", "attitude", "velocity", "rate")
PLAN_STEP = 0.5           # s between the planner's samples of the predicted grapple motion
WINDOW_MARGIN = 0.5       # s of following beyond closing_time + tolerance_time a window must offer
LONGEST_SCAN = 180.0      # s: the planner looks no further ahead than this
SHORTEST_APPROACH = 1.0   # s: the quickest joint move onto the pre-grasp pose
STILL = 0.02              # rad over LONGEST_SCAN: a grapple turning less is taken as still
MOVE_RATE_FRACTION = 0.8  # share of the URDF velocity limits a joint move may reach
CONTINUITY = 0.5          # rad: the largest joint change between two samples of one window


class CaptureController:
    """The capture controller of one servicer (module doc): arm model, Cartesian law, estimator,
    planner, phases, detumbling. ``start(state)`` takes the arm's initial configuration (the
    posture it waits and retreats to); ``step(t, h, inputs)`` returns the outputs for the inputs
    measured at t (h: the control period, s). ``wheels`` are the wheel joints' names (body joints).
    ``take_events()`` returns the events of the steps since the last call (name, fields)."""

    def __init__(self, arm: FreeFloatingArm, law: ComputedTorqueLaw, settings: CaptureSettings,
                 wheels: Sequence[str]):
        self.arm, self.law, self.cfg = arm, law, settings
        self.wheel_index = np.array([arm.body_joints.index(j) for j in wheels], dtype=int)
        if self.wheel_index.size:
            self.wheel_map = np.linalg.pinv(np.asarray(settings.wheel_axes, dtype=float).reshape(3, -1))
        else:
            self.wheel_map = np.zeros((0, 3))
        self.shoulder_id = arm.model.getJointId(settings.shoulder)
        self.arm_names = list(arm.arm_joints)
        arm_q = np.array([arm.model.joints[arm.model.getJointId(j)].idx_q for j in self.arm_names])
        self.kinematics = ArmKinematics(arm.model, arm.arm_v, arm_q, arm.ee, self.shoulder_id, self.arm_names, Limits(
            np.asarray(settings.arm_lower, float), np.asarray(settings.arm_upper, float),
            np.asarray(settings.arm_velocity, float), settings.joint_margin, settings.singularity_margin,
            settings.rate_fraction, settings.reach))
        self.estimator = GraspEstimator(settings.estimator_window, settings.estimator_memory, settings.estimator_minimum)
        self.history = PoseHistory(settings.pose_history)
        n = arm.n
        self.started = False
        self.q_posture = np.zeros(n)
        self.phase = WAIT
        self.close = False
        self.move: JointMove | None = None
        self.closing = (math.nan, np.zeros(3), np.zeros(3))      # start time, offset and rotation in G
        self.track_since = math.nan
        self.track_stats = np.zeros(10)       # track: steps, steps above each tolerance, sums of the errors, singular steps
        self.attempt = 0
        self.next_plan = -math.inf
        self.reason = ""                                          # why the last attempt or plan failed
        self.errors = np.zeros(4)
        self.q_hold = np.zeros(n)
        self.within_since = math.nan
        self.rate_since = np.full(n, math.nan)
        self.torque_since = np.full(n, math.nan)
        self.wheel_scale = 1.0
        self.last_seen = -math.inf            # time of the last measurement looked at
        self.last_distance = 0.0              # |grasp_p| of the last measurement taken
        self.events: list[tuple[str, dict]] = []

    # ------------------------------------------------------------ lifecycle

    def start(self, state: Mapping[str, np.ndarray]) -> None:
        self.q_posture = np.asarray(state["q"], dtype=float)[self.arm.body_arm].copy()
        self.started = True

    def take_events(self) -> list[tuple[str, dict]]:
        events, self.events = self.events, []
        return events

    def step(self, t: float, h: float, x: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        arm = self.arm
        arm.set_state(x["position"], x["orientation"], x["twist"], x["q"], x["qd"])
        s = arm.compute(self.law.base_model)
        self.history.record(t, s.p, s.R, s.xdot[:3], s.xdot[3:])
        self._measure(t, x)
        captured = float(x["captured"]) > 0.5
        if self.phase != CAPTURED and captured:
            self.phase, self.close, self.q_hold = CAPTURED, True, s.q.copy()
            self.events.append(("capture_closed", {"time": t, "attempt": self.attempt}))
        elif self.phase == CAPTURED and not captured:
            self._retreat(t, s, "the grasp opened after the capture (the dynamics' grasp_overload event: the wrist "
                                "loads exceeded the fixture's limits)")
        estimate = self.estimator.fit.sample(t) if self.estimator.ready else None
        tau = np.zeros(arm.n_body)
        reference = None
        if self.phase == CAPTURED:
            tau_arm = self._captured_hold(s)
            tau[self.wheel_index] = self._detumble(h, x)
        else:
            if self.phase == WAIT:
                self._wait(t, s, estimate, x)
            if self.phase in (APPROACH, RETREAT) and t >= self.move.t0 + self.move.T:
                self._arrive(t, s, estimate)
            if self.phase in (CLOSING, TRACK):
                reference = self._reference(t, estimate)
                out = self.law.control(s, reference, self.q_posture)
                problem = (self._limits(t, s, estimate, reference, out.qdd)
                           or self._update_close(t, s, estimate, out.sigma_min))
                tau_arm = out.tau
                if problem:
                    self._retreat(t, s, problem)
            if self.phase in (APPROACH, RETREAT):
                tau_arm = self._joint_move(t, s)
            elif self.phase in (WAIT, ABORTED):
                tau_arm = self._joint_hold(s, self.q_posture)
        tau[arm.body_arm] = tau_arm
        return self._outputs(s, tau, estimate, reference)

    # ------------------------------------------------------------ estimation

    def _measure(self, t: float, x: Mapping[str, np.ndarray]) -> None:
        """Take a new valid measurement into the estimator (grasp pose in W at its time)."""
        if not float(x["grasp_valid"]) > 0.5:
            return
        t_m = float(x["grasp_t"])
        if not t_m > self.last_seen:
            return
        self.last_seen = t_m
        pose = self.history.at(t_m)
        if pose is None:
            if self.history.full:
                raise ComponentError(
                    f"the grasp measurement of t = {t_m:.6g} s arrives {t - t_m:.6g} s late; the controller keeps "
                    f"end-effector poses for pose_history = {self.cfg.pose_history:g} s: raise pose_history")
            return                                  # taken before the controller's first state
        q = np.asarray(x["grasp_q"], dtype=float)
        if not 0.5 < float(np.linalg.norm(q)) < 2.0:
            raise ComponentError(f"grasp_q: expected a unit quaternion [x, y, z, w], got {q.tolist()}")
        p_ee, R_ee = pose
        p = np.asarray(x["grasp_p"], dtype=float)
        self.estimator.add(t_m, p_ee + R_ee @ p, R_ee @ quat_to_matrix(q))
        self.last_distance = float(np.linalg.norm(p))

    # ------------------------------------------------------------ waiting and planning

    def _wait(self, t: float, s: ArmState, g: PoseSample | None, x: Mapping[str, np.ndarray]) -> None:
        """Look for a window at most every replan_period; go, wait, or give up."""
        cfg = self.cfg
        if t < self.next_plan:
            return
        if g is None:
            if t >= cfg.capture_timeout:
                self._abort(t, f"no estimate of the grapple's motion by capture_timeout = {cfg.capture_timeout:g} s: "
                               f"{self.estimator.t.size} of the estimator_minimum = {self.estimator.minimum} "
                               f"measurements arrived (is the pose sensor connected and is the grapple in view?)")
            return
        self.next_plan = t + cfg.replan_period
        base_v, base_w = np.asarray(x["twist"][:3], dtype=float), np.asarray(x["twist"][3:], dtype=float)
        prediction = RigidPrediction(t, g, x["position"], base_v, base_w)
        distance = self.kinematics.shoulder_distance(self.arm.q_pin, prediction.c)
        # the tumble relative to the servicer (both co-rotate with LVLH); one that turns the grapple
        # by less than STILL over the longest scan is still: its one pose is its whole turn
        relative_rate = float(np.linalg.norm(prediction.w - base_w))
        fit = self.estimator.fit
        negligible = relative_rate * LONGEST_SCAN < STILL
        unresolved = not negligible and self.estimator.full and relative_rate < 3.0 * fit.rate_sigma   # noise
        still = negligible or unresolved
        turn = 0.0 if still else 2.0 * math.pi / relative_rate
        horizon = min(turn, LONGEST_SCAN, max(cfg.capture_timeout - t - SHORTEST_APPROACH, 0.0))
        plan, reason, found = self._plan(t, s, prediction, horizon)
        if plan is not None:
            duration, q1, qd1 = plan
            self.attempt += 1
            self.move = JointMove(t, duration, s.q, s.qd, q1, qd1)
            self.phase = APPROACH
            self.events.append(("capture_approach", {"time": t, "attempt": self.attempt, "meet_time": t + duration}))
            return
        self.reason = reason
        if t >= cfg.capture_timeout or (not found and horizon >= turn):
            if turn == 0.0:
                scope = ("(it does not turn)" if not unresolved else
                         f"(it does not turn that the estimator can tell: {math.degrees(relative_rate):.2g} deg/s, "
                         f"standard error {math.degrees(fit.rate_sigma):.2g} deg/s)")
            else:
                scope = (f"{'in a whole turn of the tumble' if horizon >= turn else 'by capture_timeout'} "
                         f"({math.degrees(relative_rate):.3g} deg/s about a centre {distance:.3g} m from the "
                         f"shoulder; the arm reaches {cfg.reach:.3g} m)")
            self._abort(t, f"the grapple never comes where the arm can follow it {scope}: {reason}")

    def _plan(self, t: float, s: ArmState, prediction: RigidPrediction, horizon: float):
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
        seeds = self._seeds(s.q)
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
                start = k - window                   # the window's first sample: the meeting time
                duration = SHORTEST_APPROACH + start * PLAN_STEP
                if duration > cfg.approach_time:
                    return None, best.reason if best else "", True      # further away: wait for it
                plan = self._pre_grasp(q_pin, prediction.sample(t + duration), chain[start], s, duration)
                if plan is not None:
                    return (duration, *plan), "", True
                run -= 1                             # too far to reach in time: a later meeting
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

    def _seeds(self, q: np.ndarray) -> list[np.ndarray]:
        """Starting configurations for the inverse kinematics: the arm now and its posture, each
        also with the elbow and the wrist turned over (a 6-joint arm of the UR kind: elbow q2 + q3,
        -q3, q4 + q3; wrist q4 + pi, -q5, q6 + pi), wrapped to (-pi, pi]."""
        def elbow(x):
            return np.array([x[0], x[1] + x[2], -x[2], x[3] + x[2], x[4], x[5]])

        def wrist(x):
            return np.array([x[0], x[1], x[2], x[3] + math.pi, -x[4], x[5] + math.pi])

        seeds = [q.copy(), self.q_posture.copy()]
        if q.size == 6:
            seeds += [f(x) for x in seeds for f in (elbow, wrist, lambda y: wrist(elbow(y)))]
        return [(x + math.pi) % (2.0 * math.pi) - math.pi for x in seeds]

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

    # ------------------------------------------------------------ moves, closing and tracking

    def _arrive(self, t: float, s: ArmState, g: PoseSample | None) -> None:
        """End of a joint move: an approach goes on to closing (the offset of the end effector
        from the estimated grasp frame, in its axes, shrinks to zero); a retreat waits again."""
        if self.phase == RETREAT:
            self.phase, self.move = WAIT, None
            if self.attempt >= self.cfg.attempts:
                self._abort(t, f"{self.attempt} approach{'es' if self.attempt != 1 else ''}: {self.reason}")
            return
        d = g.R.T @ (s.p - g.p)
        psi = log_so3(g.R.T @ s.R)
        self.closing = (t, d, psi)
        self.phase, self.move = CLOSING, None
        self.track_since, self.track_stats = math.nan, np.zeros(10)

    def _reference(self, t: float, g: PoseSample) -> PoseSample:
        """Closing: the grasp frame with the offset of the approach's end shrinking by a quintic
        (a straight line and a fixed axis in the grasp frame); track: the grasp frame."""
        t0, d0, psi0 = self.closing
        T = self.cfg.closing_time
        if self.phase == CLOSING and t >= t0 + T:
            self.phase, self.track_since = TRACK, t
        if self.phase == TRACK:
            return g
        s, ds, dds = quintic(t, t0, T)
        f, df, ddf = 1.0 - s, -ds, -dds
        r, dr, ddr = g.R @ (f * d0), g.R @ (df * d0), g.R @ (ddf * d0)
        u, du = g.R @ (df * psi0), g.R @ (ddf * psi0)
        return PoseSample(g.p + r, g.v + np.cross(g.w, r) + dr,
                          g.a + np.cross(g.dw, r) + np.cross(g.w, np.cross(g.w, r)) + 2.0 * np.cross(g.w, dr) + ddr,
                          g.R @ exp_so3(f * psi0), g.w + u, g.dw + np.cross(g.w, u) + du)

    def _joint_move(self, t: float, s: ArmState) -> np.ndarray:
        """Computed torque on the joint move (M*, C*: the base's reaction included)."""
        q_d, qd_d, qdd_d = self.move.sample(t)
        qdd = qdd_d + self.cfg.hold_kd * (qd_d - s.qd) + self.cfg.hold_kp * (q_d - s.q)
        tau = s.M_star @ qdd + s.C_star
        return np.minimum(np.maximum(tau, -self.law.effort), self.law.effort)

    def _retreat(self, t: float, s: ArmState, reason: str) -> None:
        """Back to the posture over approach_time; the planner looks for another window after."""
        cfg = self.cfg
        self.reason, self.close, self.within_since = reason, False, math.nan
        self.rate_since[:], self.torque_since[:] = math.nan, math.nan
        self.move = JointMove(t, cfg.approach_time, s.q, s.qd, self.q_posture, np.zeros_like(s.q))
        self.phase = RETREAT
        self.events.append(("capture_retreat", {"time": t, "attempt": self.attempt, "reason": reason}))

    def _abort(self, t: float, reason: str) -> None:
        self.phase, self.close, self.reason = ABORTED, False, reason
        self.events.append(("capture_aborted", {"time": t, "attempts": self.attempt, "reason": reason}))

    def _limits(self, t: float, s: ArmState, g: PoseSample, d: PoseSample, qdd: np.ndarray) -> str:
        """Why the arm cannot go on following the grasp frame ('' when it can): the grapple out
        of reach, or joint rates (needed or measured) or torques beyond the URDF limits for longer
        than limit_window."""
        law, cfg = self.law, self.cfg
        centre = np.array(self.arm.data.oMi[self.shoulder_id].translation)
        distance = float(np.linalg.norm(g.p - centre))
        if distance > cfg.reach:
            return (f"the grasp point is {distance:.2f} m from the shoulder; the arm reaches "
                    f"{cfg.reach:.2f} m (estimated at t = {t:.3f} s, from {cfg.shoulder})")
        J_plus, _, _ = dls_inverse(s.J_g, law.eps, law.lam)
        momentum_share = s.xdot - s.J_g @ s.qd
        qd_needed = J_plus @ (np.concatenate([d.v, d.w]) - momentum_share)
        qd_needed = np.where(np.abs(s.qd) > np.abs(qd_needed), s.qd, qd_needed)
        tau_needed = s.M_star @ qdd + s.C_star
        for since, needed, limit, what, unit in (
                (self.rate_since, qd_needed, cfg.arm_velocity, "velocity", "rad/s"),
                (self.torque_since, tau_needed, law.effort, "effort", "N m")):
            over = np.abs(needed) > limit
            since[~over] = math.nan
            since[over & np.isnan(since)] = t
            late = over & (t - since > cfg.limit_window)
            if np.any(late):
                i = int(np.flatnonzero(late)[np.argmax((np.abs(needed) / limit)[late])])
                doing = (f"following the grasp point needs {self.arm_names[i]} at" if what == "velocity" else
                         f"the arm's torques saturate: {self.arm_names[i]} needs")
                return (f"{doing} {abs(needed[i]):.3g} {unit} for {t - since[i]:.3g} s (longer than limit_window = "
                        f"{cfg.limit_window:g} s); its URDF {what} limit is {limit[i]:.3g} {unit}")
        return ""

    def _update_close(self, t: float, s: ArmState, g: PoseSample, sigma: float) -> str:
        """Track: close once the estimated errors have stayed within the tolerances, and the arm
        away from singularities (the smallest singular value ``sigma`` of J_g at least
        singularity_margin: a weld on a singular arm carries the target's tumble in the singular
        direction as a load), for tolerance_time; '' or, after track_time without that, what
        blocked it most of the time."""
        cfg = self.cfg
        self.errors = np.array([float(np.linalg.norm(g.p - s.p)), float(np.linalg.norm(log_so3(g.R @ s.R.T))),
                                float(np.linalg.norm(g.v - s.xdot[:3])), float(np.linalg.norm(g.w - s.xdot[3:]))])
        if self.phase != TRACK:
            return ""
        if self.close:          # asked for: the dynamics closes when the true errors are within its tolerance
            if t - self.within_since - cfg.tolerance_time <= cfg.track_time:
                return ""
            return (f"close was asked for track_time = {cfg.track_time:g} s and the grasp did not close: the true "
                    f"errors stayed outside the dynamics' grasp.tolerance while the estimated ones were within the "
                    f"controller's (tighter tolerances, or a better sensor, would tell)")
        tolerance = cfg.close_tolerances
        ratio = self.errors / tolerance
        singular = sigma < cfg.singularity_margin
        self.track_stats += np.concatenate([[1.0], ratio >= 1.0, self.errors, [singular]])
        if np.all(ratio < 1.0) and not singular:
            if math.isnan(self.within_since):
                self.within_since = t
            if t - self.within_since >= cfg.tolerance_time:
                self.close = True
            return ""
        self.within_since = math.nan
        if t - self.track_since < cfg.track_time:
            return ""
        steps, above, total, singular = self.track_stats[0], self.track_stats[1:5], self.track_stats[5:9], self.track_stats[9]
        i = int(np.argmax(above))
        if singular > above[i]:
            return (f"the arm stayed near a singularity on the grapple (the smallest singular value of J_g below "
                    f"singularity_margin = {cfg.singularity_margin:g}) {100.0 * singular / steps:.0f}% of "
                    f"track_time = {cfg.track_time:g} s")
        unit, scale = (("mm", 1e3), ("deg", 180.0 / math.pi), ("mm/s", 1e3), ("deg/s", 180.0 / math.pi))[i]
        return (f"the estimated errors did not stay within the tolerances for tolerance_time = {cfg.tolerance_time:g} s "
                f"in track_time = {cfg.track_time:g} s: the {CLOSE_ERRORS[i]} error was above "
                f"{CLOSE_ERRORS[i]}_tolerance = {tolerance[i] * scale:.3g} {unit} {100.0 * above[i] / steps:.0f}% of the "
                f"time (mean {total[i] / steps * scale:.3g} {unit})")

    # ------------------------------------------------------------ hold and detumble

    def _joint_hold(self, s: ArmState, q_hold: np.ndarray) -> np.ndarray:
        """Computed-torque joint hold of the servicer alone (waiting, or given up)."""
        qdd = self.cfg.hold_kp * (q_hold - s.q) - self.cfg.hold_kd * s.qd
        tau = s.M_star @ qdd + s.C_star
        return np.minimum(np.maximum(tau, -self.law.effort), self.law.effort)

    def _captured_hold(self, s: ArmState) -> np.ndarray:
        """Joint PD in torque units plus the servicer's C* (after capture: the target's inertia,
        which the model lacks, dominates M*)."""
        tau = self.cfg.captured_kp * (self.q_hold - s.q) - self.cfg.captured_kd * s.qd + s.C_star
        return np.minimum(np.maximum(tau, -self.law.effort), self.law.effort)

    def _detumble(self, h: float, x: Mapping[str, np.ndarray]) -> np.ndarray:
        cfg = self.cfg
        if not self.wheel_index.size:
            return np.zeros(0)
        tau = self.wheel_map @ (cfg.detumble_gain * np.asarray(x["rate_imu"], dtype=float))
        qd = np.asarray(x["qd"], dtype=float)[self.wheel_index]
        tau[(np.abs(qd) >= cfg.wheel_velocity) & (tau * qd > 0.0)] = 0.0
        ratio = float(np.max(np.abs(tau) / cfg.wheel_effort))
        if ratio > 1.0:
            tau = tau / ratio
        wrench = np.asarray(x["wrench"], dtype=float)
        excess = max(float(np.linalg.norm(wrench[:3])) / cfg.grasp_force_limit,
                     float(np.linalg.norm(wrench[3:])) / cfg.grasp_torque_limit)
        if h > 0.0:                               # once per control period (not at initialize)
            if excess > 1.0:
                self.wheel_scale = self.wheel_scale / excess
            else:
                self.wheel_scale = min(1.0, self.wheel_scale + h / cfg.wrench_recovery_time)
        return self.wheel_scale * tau

    # ------------------------------------------------------------ outputs and state

    def _outputs(self, s: ArmState, tau: np.ndarray, g: PoseSample | None, d: PoseSample | None) -> dict:
        zero = np.zeros(3)
        error = np.zeros(6) if d is None else np.concatenate([d.p - s.p, log_so3(d.R @ s.R.T)])
        tolerance = self.cfg.close_tolerances
        errors = self.errors if self.phase in (TRACK, CLOSING) else np.zeros(4)
        return {"tau": tau, "close": np.float64(1.0 if self.close else 0.0), "phase": np.float64(self.phase),
                "attempt": np.float64(self.attempt),
                "grasp_distance": np.float64(self.last_distance if g is None else np.linalg.norm(g.p - s.p)),
                "ee_error": error, "close_errors": errors.copy(),
                "close_within": (errors < tolerance).astype(np.float64) if self.phase in (TRACK, CLOSING)
                else np.zeros(4),
                "grasp_position_est": zero if g is None else g.p,
                "grasp_velocity_est": zero.copy() if g is None else g.v,
                "grasp_rate_est": zero.copy() if g is None else g.w}

    def get_state(self) -> dict[str, np.ndarray]:
        t0, d0, psi0 = self.closing
        return {"started": np.float64(self.started), "q_posture": self.q_posture.copy(),
                "phase": np.float64(self.phase), "close": np.float64(self.close),
                "move": self.move.to_array() if self.move is not None else EMPTY.copy(),
                "closing_t": np.float64(t0), "closing_d": d0.copy(), "closing_psi": psi0.copy(),
                "track_since": np.float64(self.track_since), "track_stats": self.track_stats.copy(),
                "attempt": np.float64(self.attempt), "next_plan": np.float64(self.next_plan),
                "reason": np.frombuffer(self.reason.encode(), dtype=np.uint8).astype(float),
                "errors": self.errors.copy(), "q_hold": self.q_hold.copy(),
                "within_since": np.float64(self.within_since), "rate_since": self.rate_since.copy(),
                "torque_since": self.torque_since.copy(), "wheel_scale": np.float64(self.wheel_scale),
                "last_seen": np.float64(self.last_seen), "last_distance": np.float64(self.last_distance),
                **self.estimator.get_state("estimator."), **self.history.get_state("history.")}

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        n = self.arm.n

        def vector(key: str, size: int | None) -> np.ndarray:
            if key not in state:
                raise ValueError(f"state: missing {key!r}")
            value = np.asarray(state[key], dtype=float).ravel()
            if size is not None and value.size != size:
                raise ValueError(f"state: {key} expected {size} values, got {value.size}")
            return value.copy()

        self.started = bool(vector("started", 1)[0])
        self.q_posture = vector("q_posture", n)
        self.phase = int(vector("phase", 1)[0])
        self.close = bool(vector("close", 1)[0])
        move = vector("move", None)
        self.move = JointMove.from_array(move, n) if move.size else None
        self.closing = (float(vector("closing_t", 1)[0]), vector("closing_d", 3), vector("closing_psi", 3))
        self.track_since = float(vector("track_since", 1)[0])
        self.track_stats = vector("track_stats", 10)
        self.attempt = int(vector("attempt", 1)[0])
        self.next_plan = float(vector("next_plan", 1)[0])
        self.reason = bytes(vector("reason", None).astype(np.uint8)).decode()
        self.errors = vector("errors", 4)
        self.q_hold = vector("q_hold", n)
        self.within_since = float(vector("within_since", 1)[0])
        self.rate_since, self.torque_since = vector("rate_since", n), vector("torque_since", n)
        self.wheel_scale = float(vector("wheel_scale", 1)[0])
        self.last_seen = float(vector("last_seen", 1)[0])
        self.last_distance = float(vector("last_distance", 1)[0])
        self.estimator.set_state(state, "estimator.")
        self.history.set_state(state, "history.")


def _se3(R: np.ndarray, p: np.ndarray):
    import pinocchio as pin

    return pin.SE3(np.ascontiguousarray(R), np.asarray(p, dtype=float))
