"""Per-joint PID on effort, as ros_control's ``effort_controllers/JointPositionController``.
Plain class, no bus, no I/O.

For each driven joint i, with the reference (q_d, qd_d) and the measurement (q, qd):

    e = q_d - q,   edot = qd_d - qd
    i_term <- clamp(i_term + i * e * dt, -i_clamp, i_clamp)        (ros_control's Pid order)
    tau = clamp(p * e + i_term + d * edot, -effort, effort)

``effort`` is the joint's URDF effort limit. A fixed target has qd_d = 0 (ros_control's plain
position command: the derivative acts on -qd). A joint-space trajectory gives (q_d, qd_d) from
rest-to-rest quintic segments between waypoints (:class:`trajectory.JointWaypoints`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class PidGains:
    """Per-joint gains (arrays of the driven joints' length).

    | field | unit (revolute) | meaning |
    |---|---|---|
    | p | N m / rad | proportional gain |
    | i | N m / (rad s) | integral gain |
    | d | N m s / rad | derivative gain |
    | i_clamp | N m | bound of the integral term (anti-windup) |
    """

    p: np.ndarray
    i: np.ndarray
    d: np.ndarray
    i_clamp: np.ndarray


class JointPID:
    """The PID law of the module docstring for n joints; ``i_term`` is its only state."""

    def __init__(self, gains: PidGains, effort: np.ndarray):
        self.g = gains
        self.effort = np.asarray(effort, dtype=float)
        self.i_term = np.zeros(self.effort.size)

    def torque(self, q_d, qd_d, q, qd, dt: float) -> np.ndarray:
        e = np.asarray(q_d, dtype=float) - q
        edot = np.asarray(qd_d, dtype=float) - qd
        self.i_term = np.clip(self.i_term + self.g.i * e * dt, -self.g.i_clamp, self.g.i_clamp)
        return np.clip(self.g.p * e + self.i_term + self.g.d * edot, -self.effort, self.effort)
