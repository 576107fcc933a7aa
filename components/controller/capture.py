r"""Capture of a tumbling target by a free-floating servicer, and the detumbling of the assembly
(issues 23 and 33): the phases. Plain classes, no bus, no I/O; ``controller.capture``
(:mod:`components.controller.capture_component`) wraps them. The phases use the grasp frame's
estimate (:mod:`components.controller.capture_estimate`: frames, measurements and the fit), the
planner (:mod:`components.controller.capture_plan`: prediction, inverse kinematics, windows, the
joint move) and the torques (:mod:`components.controller.capture_law`); what the controller is
told is :class:`components.controller.capture_settings.CaptureSettings`.

Phases (``phase`` output)
-------------------------
The approach is planned in joint space and the close is made in Cartesian space, as servicing
arms do:

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
capture with a joint PD in torque units and the servicer's Coriolis terms (the welded target's
inertia is not in the model), and the reaction wheels damp the bus rate measured by the IMU, within
their limits and scaled down to keep the wrist wrench within the grasp limits
(:mod:`components.controller.capture_law`). Total momentum is never an input.

6, aborted: the capture is given up and the arm holds its posture, the target free; an event
``capture_aborted`` gives the time and a reason a person can act on. It comes after ``attempts``
retreats (the reason of the last), when a whole turn of the predicted tumble offers no window (the
check that failed at the best sample, with its figure), or at ``capture_timeout`` without an
approach under way (no window, or no estimate). Not capturing is an outcome: the run goes on and
ends normally.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from components.controller.capture_estimate import GraspTracker, fit_motion
from components.controller.capture_law import JointLaw, LimitWatch, WheelLaw, closing_reference
from components.controller.capture_plan import JointMove, WindowPlanner
from components.controller.capture_settings import CLOSE_ERRORS, CaptureSettings
from components.controller.computed_torque import ComputedTorqueLaw
from components.controller.free_floating_arm import ArmState, FreeFloatingArm
from components.controller.trajectory import PoseSample
from components.rotations import log_so3

# fit_motion: the estimator's fit, for the controller's tests
__all__ = [
    "ABORTED",
    "APPROACH",
    "CAPTURED",
    "CLOSING",
    "PHASES",
    "RETREAT",
    "TRACK",
    "WAIT",
    "CaptureController",
    "fit_motion",
]

WAIT, APPROACH, CLOSING, TRACK, RETREAT, CAPTURED, ABORTED = range(7)
PHASES = ("wait", "approach", "closing", "track", "retreat", "captured", "aborted")


def _under_way(move: JointMove | None) -> JointMove:
    """The joint move of the approach or the retreat under way (set on entering either)."""
    assert move is not None, "an approach or a retreat has its move"
    return move


class CaptureController:
    """The capture controller of one servicer (module doc): the phases over the grasp frame's
    estimate, the planner and the laws. ``start(state)`` takes the arm's initial configuration (the
    posture it waits and retreats to); ``step(t, h, inputs)`` returns the outputs for the inputs
    measured at t (h: the control period, s). ``wheels`` are the wheel joints' names (body joints).
    ``take_events()`` returns the events of the steps since the last call (name, fields)."""

    def __init__(self, arm: FreeFloatingArm, law: ComputedTorqueLaw, settings: CaptureSettings, wheels: Sequence[str]):
        self.arm, self.law, self.cfg = arm, law, settings
        self.wheel_index = np.array([arm.body_joints.index(j) for j in wheels], dtype=int)
        self.wheels = WheelLaw(settings, self.wheel_index)
        self.joints = JointLaw(settings, law.effort)
        self.planner = WindowPlanner(arm, settings)
        self.limits = LimitWatch(arm, law, settings)
        self.tracker = GraspTracker(
            settings.estimator_window, settings.estimator_memory, settings.estimator_minimum, settings.pose_history
        )
        self.estimator = self.tracker.estimator
        n = arm.n
        self.started = False
        self.q_posture = np.zeros(n)
        self.phase = WAIT
        self.close = False
        self.move: JointMove | None = None
        self.closing = (math.nan, np.zeros(3), np.zeros(3))  # start time, offset and rotation in G
        self.track_since = math.nan
        self.track_stats = np.zeros(10)  # track: steps, steps above each tolerance, sums of the errors, singular steps
        self.attempt = 0
        self.next_plan = -math.inf
        self.reason = ""  # why the last attempt or plan failed
        self.errors = np.zeros(4)
        self.q_hold = np.zeros(n)
        self.within_since = math.nan
        self.wheel_scale = 1.0
        self.events: list[tuple[str, dict]] = []

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
        self.tracker.record(t, s)
        self.tracker.measure(t, x)
        captured = float(x["captured"]) > 0.5
        if self.phase != CAPTURED and captured:
            self.phase, self.close, self.q_hold = CAPTURED, True, s.q.copy()
            self.events.append(("capture_closed", {"time": t, "attempt": self.attempt}))
        elif self.phase == CAPTURED and not captured:
            self._retreat(
                t,
                s,
                "the grasp opened after the capture (the dynamics' grasp_overload event: the wrist "
                "loads exceeded the fixture's limits)",
            )
        estimate = self.tracker.estimate(t)
        tau = np.zeros(arm.n_body)
        reference = None
        if self.phase == CAPTURED:
            tau_arm = self.joints.hold_captured(s, self.q_hold)
            tau[self.wheel_index] = self._detumble(h, x)
        else:
            if self.phase == WAIT:
                self._wait(t, s, estimate, x)
            if self.phase in (APPROACH, RETREAT) and t >= _under_way(self.move).t0 + _under_way(self.move).T:
                self._arrive(t, s, estimate)
            if self.phase in (CLOSING, TRACK):
                assert estimate is not None  # an approach starts from one, and the estimator stays ready
                reference = self._reference(t, estimate)
                out = self.law.control(s, reference, self.q_posture)
                problem = self.limits.check(t, s, estimate, reference, out.qdd) or self._update_close(
                    t, s, estimate, out.sigma_min
                )
                tau_arm = out.tau
                if problem:
                    self._retreat(t, s, problem)
            if self.phase in (APPROACH, RETREAT):
                tau_arm = self.joints.follow(_under_way(self.move), t, s)
            elif self.phase in (WAIT, ABORTED):
                tau_arm = self.joints.hold(s, self.q_posture)
        tau[arm.body_arm] = tau_arm
        return self._outputs(s, tau, estimate, reference)

    # ------------------------------------------------------------ transitions

    def _wait(self, t: float, s: ArmState, g: PoseSample | None, x: Mapping[str, np.ndarray]) -> None:
        """Look for a window at most every replan_period; go, wait, or give up."""
        cfg = self.cfg
        if t < self.next_plan:
            return
        if g is None:
            if t >= cfg.capture_timeout:
                self._abort(
                    t,
                    f"no estimate of the grapple's motion by capture_timeout = {cfg.capture_timeout:g} s: "
                    f"{self.estimator.t.size} of the estimator_minimum = {self.estimator.minimum} "
                    f"measurements arrived (is the pose sensor connected and is the grapple in view?)",
                )
            return
        self.next_plan = t + cfg.replan_period
        look = self.planner.look(t, s, g, x["position"], x["twist"], self.estimator, self.q_posture)
        if look.approach is not None:
            duration, q1, qd1 = look.approach
            self.attempt += 1
            self.move = JointMove(t, duration, s.q, s.qd, q1, qd1)
            self.phase = APPROACH
            self.events.append(("capture_approach", {"time": t, "attempt": self.attempt, "meet_time": t + duration}))
            return
        self.reason = look.reason
        if look.give_up:
            self._abort(t, look.give_up)

    def _arrive(self, t: float, s: ArmState, g: PoseSample | None) -> None:
        """End of a joint move: an approach goes on to closing (the offset of the end effector
        from the estimated grasp frame, in its axes, shrinks to zero); a retreat waits again."""
        if self.phase == RETREAT:
            self.phase, self.move = WAIT, None
            if self.attempt >= self.cfg.attempts:
                self._abort(t, f"{self.attempt} approach{'es' if self.attempt != 1 else ''}: {self.reason}")
            return
        assert g is not None  # the approach started from one, and the estimator stays ready
        d = g.R.T @ (s.p - g.p)
        psi = log_so3(g.R.T @ s.R)
        self.closing = (t, d, psi)
        self.phase, self.move = CLOSING, None
        self.track_since, self.track_stats = math.nan, np.zeros(10)

    def _reference(self, t: float, g: PoseSample) -> PoseSample:
        """Closing: the grasp frame with the offset of the approach's end shrinking (capture_law);
        track, from closing_time on: the grasp frame."""
        t0, d0, psi0 = self.closing
        if self.phase == CLOSING and t >= t0 + self.cfg.closing_time:
            self.phase, self.track_since = TRACK, t
        if self.phase == TRACK:
            return g
        return closing_reference(t, t0, d0, psi0, self.cfg.closing_time, g)

    def _retreat(self, t: float, s: ArmState, reason: str) -> None:
        """Back to the posture over approach_time; the planner looks for another window after."""
        cfg = self.cfg
        self.reason, self.close, self.within_since = reason, False, math.nan
        self.limits.reset()
        self.move = JointMove(t, cfg.approach_time, s.q, s.qd, self.q_posture, np.zeros_like(s.q))
        self.phase = RETREAT
        self.events.append(("capture_retreat", {"time": t, "attempt": self.attempt, "reason": reason}))

    def _abort(self, t: float, reason: str) -> None:
        self.phase, self.close, self.reason = ABORTED, False, reason
        self.events.append(("capture_aborted", {"time": t, "attempts": self.attempt, "reason": reason}))

    def _update_close(self, t: float, s: ArmState, g: PoseSample, sigma: float) -> str:
        """Track: close once the estimated errors have stayed within the tolerances, and the arm
        away from singularities (the smallest singular value ``sigma`` of J_g at least
        singularity_margin: a weld on a singular arm carries the target's tumble in the singular
        direction as a load), for tolerance_time; '' or, after track_time without that, what
        blocked it most of the time."""
        cfg = self.cfg
        self.errors = np.array(
            [
                float(np.linalg.norm(g.p - s.p)),
                float(np.linalg.norm(log_so3(g.R @ s.R.T))),
                float(np.linalg.norm(g.v - s.xdot[:3])),
                float(np.linalg.norm(g.w - s.xdot[3:])),
            ]
        )
        if self.phase != TRACK:
            return ""
        if self.close:  # asked for: the dynamics closes when the true errors are within its tolerance
            if t - self.within_since - cfg.tolerance_time <= cfg.track_time:
                return ""
            return (
                f"close was asked for track_time = {cfg.track_time:g} s and the grasp did not close: the true "
                f"errors stayed outside the dynamics' grasp.tolerance while the estimated ones were within the "
                f"controller's (tighter tolerances, or a better sensor, would tell)"
            )
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
        steps, above, total, singular = (
            self.track_stats[0],
            self.track_stats[1:5],
            self.track_stats[5:9],
            self.track_stats[9],
        )
        i = int(np.argmax(above))
        if singular > above[i]:
            return (
                f"the arm stayed near a singularity on the grapple (the smallest singular value of J_g below "
                f"singularity_margin = {cfg.singularity_margin:g}) {100.0 * singular / steps:.0f}% of "
                f"track_time = {cfg.track_time:g} s"
            )
        unit, scale = (("mm", 1e3), ("deg", 180.0 / math.pi), ("mm/s", 1e3), ("deg/s", 180.0 / math.pi))[i]
        return (
            f"the estimated errors did not stay within the tolerances for tolerance_time = {cfg.tolerance_time:g} s "
            f"in track_time = {cfg.track_time:g} s: the {CLOSE_ERRORS[i]} error was above "
            f"{CLOSE_ERRORS[i]}_tolerance = {tolerance[i] * scale:.3g} {unit} {100.0 * above[i] / steps:.0f}% of the "
            f"time (mean {total[i] / steps * scale:.3g} {unit})"
        )

    def _detumble(self, h: float, x: Mapping[str, np.ndarray]) -> np.ndarray:
        """The wheels' torques, the wrench factor updated once per control period (not at initialize)."""
        if not self.wheel_index.size:
            return np.zeros(0)
        tau = self.wheels.torques(x["rate_imu"], x["qd"])
        if h > 0.0:
            self.wheel_scale = self.wheels.next_scale(self.wheel_scale, h, x["wrench"])
        return self.wheel_scale * tau

    # ------------------------------------------------------------ outputs and state

    def _outputs(self, s: ArmState, tau: np.ndarray, g: PoseSample | None, d: PoseSample | None) -> dict:
        zero = np.zeros(3)
        error = np.zeros(6) if d is None else np.concatenate([d.p - s.p, log_so3(d.R @ s.R.T)])
        tolerance = self.cfg.close_tolerances
        errors = self.errors if self.phase in (TRACK, CLOSING) else np.zeros(4)
        return {
            "tau": tau,
            "close": np.float64(1.0 if self.close else 0.0),
            "phase": np.float64(self.phase),
            "attempt": np.float64(self.attempt),
            "grasp_distance": np.float64(self.tracker.last_distance if g is None else np.linalg.norm(g.p - s.p)),
            "ee_error": error,
            "close_errors": errors.copy(),
            "close_within": (errors < tolerance).astype(np.float64) if self.phase in (TRACK, CLOSING) else np.zeros(4),
            "grasp_position_est": zero if g is None else g.p,
            "grasp_velocity_est": zero.copy() if g is None else g.v,
            "grasp_rate_est": zero.copy() if g is None else g.w,
        }

    def get_state(self) -> dict[str, np.ndarray | np.float64]:
        t0, d0, psi0 = self.closing
        return {
            "started": np.float64(self.started),
            "q_posture": self.q_posture.copy(),
            "phase": np.float64(self.phase),
            "close": np.float64(self.close),
            "move": self.move.to_array() if self.move is not None else np.zeros(0),
            "closing_t": np.float64(t0),
            "closing_d": d0.copy(),
            "closing_psi": psi0.copy(),
            "track_since": np.float64(self.track_since),
            "track_stats": self.track_stats.copy(),
            "attempt": np.float64(self.attempt),
            "next_plan": np.float64(self.next_plan),
            "reason": np.frombuffer(self.reason.encode(), dtype=np.uint8).astype(float),
            "errors": self.errors.copy(),
            "q_hold": self.q_hold.copy(),
            "within_since": np.float64(self.within_since),
            **self.limits.get_state(),
            "wheel_scale": np.float64(self.wheel_scale),
            **self.tracker.get_state(),
        }

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
        self.limits.set_state(vector)
        self.wheel_scale = float(vector("wheel_scale", 1)[0])
        self.tracker.set_state(state, vector)
