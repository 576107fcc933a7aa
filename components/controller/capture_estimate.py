r"""Where the grapple is and how it moves (issues 23 and 33): the grasp frame in W from delayed
relative-pose measurements, and a rigid motion fitted to the latest of them. Plain classes, no
bus, no I/O; the capture controller (:mod:`components.controller.capture`) uses them.

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
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from components.controller.free_floating_arm import ArmState
from components.controller.trajectory import PoseSample
from components.errors import ComponentError
from components.rotations import exp_so3, log_so3, quat_to_matrix, skew

# --------------------------------------------------------------------------- SO(3)


def left_jacobian(phi) -> np.ndarray:
    """Left Jacobian of SO(3): d/dt exp(phi) = [J_l(phi) phi']x exp(phi)."""
    phi = np.asarray(phi, dtype=float)
    t2 = float(phi @ phi)
    K = skew(phi)
    if t2 < 1e-4:  # series: the closed forms cancel at small angles
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
    dot = float(phi @ dphi)  # t t'
    if t2 < 1e-4:  # series (the closed forms cancel)
        a, b = 0.5 - t2 * (1.0 / 24.0 - t2 / 720.0), 1.0 / 6.0 - t2 * (1.0 / 120.0 - t2 / 5040.0)
        da_t = -1.0 / 12.0 + t2 * (1.0 / 180.0 - t2 / 6720.0)  # a'(t) / t
        db_t = -1.0 / 60.0 + t2 * (1.0 / 1260.0 - t2 / 90720.0)  # b'(t) / t
    else:
        t = math.sqrt(t2)
        c, sn = math.cos(t), math.sin(t)
        a, b = (1.0 - c) / t2, (t - sn) / (t2 * t)
        da_t = (t * sn - 2.0 * (1.0 - c)) / (t2 * t2)  # a'(t) / t
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
        return PoseSample(
            p,
            self.v + tau * self.a,
            self.a.copy(),
            exp_so3(phi) @ self.R,
            J @ dphi,
            J @ self.ddphi + left_jacobian_rate(phi, dphi) @ dphi,
        )

    def to_array(self) -> np.ndarray:
        return np.concatenate(
            [[self.t], self.p, self.v, self.a, self.R.ravel(), self.phi, self.dphi, self.ddphi, [self.rate_sigma]]
        )

    @classmethod
    def from_array(cls, x) -> MotionFit:
        x = np.asarray(x, dtype=float)
        if x.size != 29:
            raise ValueError(f"state: a motion fit has 29 values, got {x.size}")
        return cls(
            float(x[0]),
            x[1:4].copy(),
            x[4:7].copy(),
            x[7:10].copy(),
            x[10:19].reshape(3, 3).copy(),
            x[19:22].copy(),
            x[22:25].copy(),
            x[25:28].copy(),
            float(x[28]),
        )


def fit_motion(times, positions, rotations, memory: float) -> MotionFit:
    """Fading-memory least-squares fit of a rigid motion to poses (module doc).

    ``times`` (k,) s, increasing; ``positions`` (k, 3) m; ``rotations`` (k, 3, 3) R_W_frame;
    ``memory`` s: weight ``exp((t_i - t_k) / memory)`` (inf: equal weights)."""
    times = np.asarray(times, dtype=float)
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    rotations = np.asarray(rotations, dtype=float).reshape(-1, 3, 3)
    k = times.size
    if k == 0 or positions.shape[0] != k or rotations.shape[0] != k:
        raise ValueError(
            f"fit_motion: expected as many times, positions and rotations (>= 1), got "
            f"{k}, {positions.shape[0]}, {rotations.shape[0]}"
        )
    t_ref, R_ref = float(times[-1]), rotations[-1].copy()
    tau = times - t_ref
    span = float(-tau[0]) if k > 1 else 1.0
    if not span > 0.0:
        raise ValueError("fit_motion: expected increasing times")
    u = tau / span  # in [-1, 0]: a well-conditioned basis
    Y = np.empty((k, 6))
    Y[:, :3] = positions
    Y[:, 3:] = [log_so3(R @ R_ref.T) for R in rotations]
    order = min(2, k - 1)
    A = np.column_stack([np.ones(k), u, 0.5 * u * u][: order + 1])
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
    c[: order + 1] = coef
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
            raise ValueError(
                f"estimator_minimum: expected 1 to estimator_window = {self.window} measurements, got {self.minimum}"
            )
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
        return {
            f"{prefix}t": self.t.copy(),
            f"{prefix}p": self.p.copy(),
            f"{prefix}R": self.R.copy(),
            f"{prefix}fit": self.fit.to_array() if self.fit is not None else np.zeros(0),
        }

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
        self.t: list[float] = []
        self.p: list[np.ndarray] = []
        self.R: list[np.ndarray] = []
        self.v: list[np.ndarray] = []
        self.w: list[np.ndarray] = []

    @property
    def full(self) -> bool:
        """It spans ``span`` seconds: a time older than its first is older than ``span``."""
        return bool(self.t) and self.t[-1] - self.t[0] >= self.span

    def record(self, t: float, p, R, v, w) -> None:
        entry = (
            float(t),
            np.array(p, dtype=float),
            np.array(R, dtype=float),
            np.array(v, dtype=float),
            np.array(w, dtype=float),
        )
        columns: tuple[list[Any], ...] = (self.t, self.p, self.R, self.v, self.w)
        if self.t and t <= self.t[-1]:
            if t < self.t[-1]:
                raise ValueError(f"end-effector pose at t = {t} s is older than the last one ({self.t[-1]} s)")
            for column, value in zip(columns, entry):  # same time: replace
                column[-1] = value
            return
        for column, value in zip(columns, entry):
            column.append(value)
        while len(self.t) > 2 and self.t[1] <= t - self.span:
            for column in columns:
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
        return {
            f"{prefix}t": np.array(self.t, dtype=float),
            f"{prefix}p": np.array(self.p).reshape(n, 3),
            f"{prefix}R": np.array(self.R).reshape(n, 3, 3),
            f"{prefix}v": np.array(self.v).reshape(n, 3),
            f"{prefix}w": np.array(self.w).reshape(n, 3),
        }

    def set_state(self, state: Mapping[str, np.ndarray], prefix: str) -> None:
        t = np.asarray(state[f"{prefix}t"], dtype=float).ravel()
        n = t.size
        self.t = [float(x) for x in t]
        self.p = [x.copy() for x in np.asarray(state[f"{prefix}p"], dtype=float).reshape(n, 3)]
        self.R = [x.copy() for x in np.asarray(state[f"{prefix}R"], dtype=float).reshape(n, 3, 3)]
        self.v = [x.copy() for x in np.asarray(state[f"{prefix}v"], dtype=float).reshape(n, 3)]
        self.w = [x.copy() for x in np.asarray(state[f"{prefix}w"], dtype=float).reshape(n, 3)]


class GraspTracker:
    """The grasp frame's estimate from the pose sensor: the end effector's poses by time, the
    estimator over the grasp poses in W, the time of the last measurement looked at and the
    distance it measured (state: ``last_seen``, ``last_distance``, ``estimator.*``, ``history.*``)."""

    def __init__(self, window: int, memory: float, minimum: int, pose_history: float):
        self.estimator = GraspEstimator(window, memory, minimum)
        self.history = PoseHistory(pose_history)
        self.last_seen = -math.inf  # time of the last measurement looked at
        self.last_distance = 0.0  # |grasp_p| of the last measurement taken

    def record(self, t: float, s: ArmState) -> None:
        """The end effector's pose and twist at t (the state measured then)."""
        self.history.record(t, s.p, s.R, s.xdot[:3], s.xdot[3:])

    def measure(self, t: float, x: Mapping[str, np.ndarray]) -> None:
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
                    f"end-effector poses for pose_history = {self.history.span:g} s: raise pose_history"
                )
            return  # taken before the controller's first state
        q = np.asarray(x["grasp_q"], dtype=float)
        if not 0.5 < float(np.linalg.norm(q)) < 2.0:
            raise ComponentError(f"grasp_q: expected a unit quaternion [x, y, z, w], got {q.tolist()}")
        p_ee, R_ee = pose
        p = np.asarray(x["grasp_p"], dtype=float)
        self.estimator.add(t_m, p_ee + R_ee @ p, R_ee @ quat_to_matrix(q))
        self.last_distance = float(np.linalg.norm(p))

    def estimate(self, t: float) -> PoseSample | None:
        """The grasp frame at t (W), once the estimator holds its minimum of measurements."""
        if not self.estimator.ready:
            return None
        assert self.estimator.fit is not None  # each measurement refits
        return self.estimator.fit.sample(t)

    def get_state(self) -> dict[str, np.ndarray | np.float64]:
        return {
            "last_seen": np.float64(self.last_seen),
            "last_distance": np.float64(self.last_distance),
            **self.estimator.get_state("estimator."),
            **self.history.get_state("history."),
        }

    def set_state(self, state: Mapping[str, np.ndarray], read: Callable[[str, int], np.ndarray]) -> None:
        """``read(key, size)``: the state's value, checked."""
        self.last_seen = float(read("last_seen", 1)[0])
        self.last_distance = float(read("last_distance", 1)[0])
        self.estimator.set_state(state, "estimator.")
        self.history.set_state(state, "history.")
