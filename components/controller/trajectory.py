"""End-effector and joint trajectories for the controllers: quintic time law, the paper's
parabolic move, Cartesian and joint-space waypoints. Plain functions and classes, no I/O.

Time law (rest to rest, C2): ``s(u) = 10 u^3 - 15 u^4 + 6 u^5`` with ``u = (t - t0) / T`` clipped
to [0, 1]; ``s' = 30 u^2 (1 - u)^2 / T``, ``s'' = 60 u (1 - u)(1 - 2u) / T^2``. Peak rate
``1.875 / T``, peak acceleration ``5.774 / T^2`` (per unit of path).

Cartesian trajectories are anchored at the end effector's initial pose ``(p0, R0)`` in W and
written in the axes ``R_axes`` (the robot base's initial orientation for ``axes: body``, the
identity for ``axes: world``). ``sample(t)`` returns the desired pose and its first two time
derivatives, all in W:

| field | unit | meaning |
|---|---|---|
| p, v, a | m, m/s, m/s^2 | position of the end-effector frame origin, its (classical) rate and acceleration |
| R | - | 3x3 rotation R_W_ee |
| w, dw | rad/s, rad/s^2 | angular velocity and acceleration, W axes |

Config forms (``trajectory`` parameter of ``controller.computed_torque``):

    {type: hold}                                                  # keep the initial pose
    {type: parabola, start: 1 s, duration: 10 s, displacement: 0.5 m, height: 0.1 m}
    {type: waypoints, axes: body, start: 0 s,
     waypoints: [{time: 4 s, position: [0.1, 0, 0.05], rotation: [0, 0, 0.2]}, ...]}

``parabola`` is the paper's move (IAC-22, Fig. 4): ``displacement`` along the base's initial x
axis, y held, z on the parabola ``4 h s (1 - s)`` (apex ``height`` halfway, back to the start
height at the end), orientation kept, with the quintic law between ``start`` and
``start + duration``. ``waypoints``: rest-to-rest quintic segments, straight lines in position
and a constant-axis rotation in orientation; ``position`` is the offset from the initial
end-effector position and ``rotation`` a rotation vector (rad) applied to the initial orientation,
both in ``axes``; each waypoint is reached at its ``time``, leaving the previous one (or the
initial pose) at the previous ``time`` (or ``start``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from components.errors import ConfigError
from components.rotations import exp_so3, log_so3
from components.schema import Float, ListOf, Parameter, Record, Str, Tagged, Vector

AXES = ("body", "world")


# --------------------------------------------------------------------------- time law


def quintic(t: float, t0: float, duration: float) -> tuple[float, float, float]:
    """Rest-to-rest quintic time law: (s, ds/dt, d2s/dt2) with s from 0 at t0 to 1 at t0 + T."""
    if duration <= 0.0:
        return (0.0, 0.0, 0.0) if t < t0 else (1.0, 0.0, 0.0)
    u = (t - t0) / duration
    if u <= 0.0:
        return 0.0, 0.0, 0.0
    if u >= 1.0:
        return 1.0, 0.0, 0.0
    s = u * u * u * (10.0 + u * (-15.0 + 6.0 * u))
    ds = 30.0 * u * u * (1.0 - u) ** 2 / duration
    dds = 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u) / duration**2
    return s, ds, dds


# --------------------------------------------------------------------------- Cartesian trajectories


@dataclass(frozen=True)
class PoseSample:
    """Desired end-effector pose and derivatives at one time, W (see the module table)."""

    p: np.ndarray
    v: np.ndarray
    a: np.ndarray
    R: np.ndarray
    w: np.ndarray
    dw: np.ndarray


class Hold:
    """The initial pose, forever."""

    def __init__(self, p0: np.ndarray, R0: np.ndarray):
        self.p0, self.R0 = np.array(p0, dtype=float), np.array(R0, dtype=float)

    def sample(self, t: float) -> PoseSample:
        z = np.zeros(3)
        return PoseSample(self.p0.copy(), z, z.copy(), self.R0.copy(), z.copy(), z.copy())

    def checkpoints(self) -> list[tuple[str, np.ndarray]]:
        """Points of the path (W) with the config key (below ``trajectory``) that places them:
        enough points that the path lies within any ball containing them all (reach checks)."""
        return []


class Parabola(Hold):
    """The paper's move: ``displacement`` along the x axis of ``R_axes``, y held, z on a parabola
    of apex ``height``, orientation kept, quintic in time from ``start`` over ``duration``."""

    def __init__(self, p0, R0, R_axes, start: float, duration: float, displacement: float, height: float):
        super().__init__(p0, R0)
        self.R_axes = np.array(R_axes, dtype=float)
        self.start, self.duration = float(start), float(duration)
        self.d, self.h = float(displacement), float(height)

    def _offsets(self, s: float, ds: float = 0.0, dds: float = 0.0) -> np.ndarray:
        """Rows: the offset from p0 in R_axes at the path parameter s, and its first two time
        derivatives for the path rates ds/dt = ds, d2s/dt2 = dds (built from floats in one array:
        the per-step cost is numpy's per-call overhead)."""
        d, h = self.d, self.h
        slope = 4.0 * h * (1.0 - 2.0 * s)  # dz/ds; d2z/ds2 = -8 h
        return np.array(
            (
                (d * s, 0.0, 4.0 * h * s * (1.0 - s)),
                (d * ds, 0.0, slope * ds),
                (d * dds, 0.0, -8.0 * h * ds * ds + slope * dds),
            )
        )

    def sample(self, t: float) -> PoseSample:
        s, ds, dds = quintic(t, self.start, self.duration)
        p, v, a = self._offsets(s, ds, dds) @ self.R_axes.T
        z = np.zeros(3)
        return PoseSample(self.p0 + p, v, a, self.R0.copy(), z, z.copy())

    def checkpoints(self) -> list[tuple[str, np.ndarray]]:
        points = [("displacement", self.p0 + self.R_axes @ self._offsets(1.0)[0])]
        return points + [("height", self.p0 + self.R_axes @ self._offsets(s)[0]) for s in np.linspace(0.0, 1.0, 41)]


class Waypoints(Hold):
    """Rest-to-rest quintic segments through Cartesian waypoints (offsets from the initial pose).

    ``times`` (s, increasing, after ``start``), ``positions`` (n, 3) m and ``rotations`` (n, 3) rad,
    in the axes ``R_axes``.
    """

    def __init__(self, p0, R0, R_axes, start: float, times, positions, rotations):
        super().__init__(p0, R0)
        Ra = np.array(R_axes, dtype=float)
        self.t = np.concatenate([[float(start)], np.asarray(times, dtype=float)])
        self.p = np.vstack([self.p0, self.p0 + np.asarray(positions, dtype=float).reshape(-1, 3) @ Ra.T])
        self.R = [self.R0] + [
            exp_so3(Ra @ np.asarray(r, dtype=float)) @ self.R0
            for r in np.asarray(rotations, dtype=float).reshape(-1, 3)
        ]
        # rotation vector of each segment, W axes: R_{i+1} = exp(phi_i) R_i
        self.phi = [log_so3(self.R[i + 1] @ self.R[i].T) for i in range(len(self.R) - 1)]

    def sample(self, t: float) -> PoseSample:
        z = np.zeros(3)
        if t <= self.t[0]:
            return PoseSample(self.p[0].copy(), z, z.copy(), self.R[0].copy(), z.copy(), z.copy())
        if t >= self.t[-1]:
            return PoseSample(self.p[-1].copy(), z, z.copy(), self.R[-1].copy(), z.copy(), z.copy())
        i = int(np.searchsorted(self.t, t, side="right")) - 1
        s, ds, dds = quintic(t, self.t[i], self.t[i + 1] - self.t[i])
        dp, phi = self.p[i + 1] - self.p[i], self.phi[i]
        return PoseSample(self.p[i] + s * dp, ds * dp, dds * dp, exp_so3(s * phi) @ self.R[i], ds * phi, dds * phi)

    def checkpoints(self) -> list[tuple[str, np.ndarray]]:
        # straight segments: a ball (convex) holding the waypoints holds the whole path
        return [(f"waypoints[{i}].position", p) for i, p in enumerate(self.p[1:])]


# --------------------------------------------------------------------------- config parsing

_START = Parameter("start", Float("s", minimum=0.0), default=0.0, description="time the move starts")
_AXES = Parameter(
    "axes", Str(AXES), default="body", description="axes of the offsets: body (the base's initial axes) or world (W)"
)
CARTESIAN_WAYPOINT = Record(
    "Cartesian waypoint",
    (
        Parameter(
            "time",
            Float("s"),
            description="the run time (s from t = 0, not from the previous waypoint) at which it is reached; later than the previous one (or start)",
        ),
        Parameter(
            "position",
            Vector(3, "m", plausible=(-100.0, 100.0)),
            default=[0.0, 0.0, 0.0],
            description="offset from the initial end-effector position",
        ),
        Parameter(
            "rotation",
            Vector(3, "rad", plausible=(-2 * math.pi, 2 * math.pi)),
            default=[0.0, 0.0, 0.0],
            description="rotation vector applied to the initial orientation",
        ),
    ),
    description="one waypoint of a waypoints trajectory (offsets in its axes)",
)
CARTESIAN = Tagged(
    "Trajectory",
    "type",
    (
        Record("hold", (), description="keep the initial pose (type: hold)"),
        Record(
            "parabola",
            (
                _START,
                Parameter(
                    "duration",
                    Float("s", positive=True, plausible=(1e-3, 86400.0)),
                    description="time from the start to the end of the move",
                ),
                Parameter(
                    "displacement",
                    Float("m", plausible=(-100.0, 100.0)),
                    default=0.5,
                    description="along the x axis of axes",
                ),
                Parameter(
                    "height",
                    Float("m", plausible=(-100.0, 100.0)),
                    default=0.1,
                    description="apex of the parabola, halfway",
                ),
                _AXES,
            ),
            description="the paper's move (type: parabola)",
        ),
        Record(
            "waypoints",
            (
                _START,
                _AXES,
                Parameter(
                    "waypoints", ListOf(CARTESIAN_WAYPOINT, min_items=1), description="reached one after the other"
                ),
            ),
            description="rest-to-rest segments through waypoints (type: waypoints)",
        ),
    ),
)


def parse_cartesian(spec: Any, prefix: str = "trajectory") -> dict:
    """Check a ``trajectory`` (config mapping, or one CARTESIAN converted); return it in SI, the
    waypoints as ``times``, ``positions``, ``rotations`` (ConfigError naming the key)."""
    out = CARTESIAN.convert({"type": "hold"} if spec is None else spec, prefix)
    if out["type"] != "waypoints":
        return out
    previous = out["start"]
    for i, point in enumerate(out["waypoints"]):
        if not point["time"] > previous:
            raise ConfigError(
                f"{prefix}.waypoints[{i}].time",
                f"expected a time after {previous:g} s (the previous waypoint or start), got {point['time']:g} s",
            )
        previous = point["time"]
    points = out.pop("waypoints")
    out.update(
        times=[p["time"] for p in points],
        positions=[p["position"] for p in points],
        rotations=[p["rotation"] for p in points],
    )
    return out


def build_cartesian(parsed: Mapping, p0, R0, R_base) -> Hold:
    """A trajectory object from ``parse_cartesian``'s result, anchored at the pose (p0, R0) in W;
    ``R_base`` is the base's orientation (for ``axes: body``)."""
    kind = parsed["type"]
    if kind == "hold":
        return Hold(p0, R0)
    R_axes = np.asarray(R_base, dtype=float) if parsed["axes"] == "body" else np.eye(3)
    if kind == "parabola":
        return Parabola(p0, R0, R_axes, parsed["start"], parsed["duration"], parsed["displacement"], parsed["height"])
    return Waypoints(p0, R0, R_axes, parsed["start"], parsed["times"], parsed["positions"], parsed["rotations"])


def max_offset(parsed: Mapping) -> tuple[str, float]:
    """The config key and size (m) of the largest offset from the initial end-effector position
    (a necessary reach check: a reachable path lies within twice the arm's reach of its start)."""
    kind = parsed["type"]
    if kind == "hold":
        return "type", 0.0
    if kind == "parabola":
        d, h = parsed["displacement"], parsed["height"]
        sizes = [math.hypot(d * s, 4.0 * h * s * (1.0 - s)) for s in np.linspace(0.0, 1.0, 101)]
        return "displacement", float(max(sizes))
    sizes = [float(np.linalg.norm(p)) for p in parsed["positions"]]
    i = int(np.argmax(sizes))
    return f"waypoints[{i}].position", sizes[i]


# --------------------------------------------------------------------------- joint-space trajectories


class JointWaypoints:
    """Rest-to-rest quintic segments between joint-space waypoints.

    ``q0`` (n,) the positions at ``start``; ``times`` (m,) increasing; ``targets`` (m, n).
    ``sample(t)`` -> (q, qd, qdd) (rad, rad/s, rad/s^2 or m, m/s, m/s^2).
    """

    def __init__(self, q0, start: float, times, targets):
        self.t = np.concatenate([[float(start)], np.asarray(times, dtype=float)])
        q0 = np.asarray(q0, dtype=float).ravel()
        self.q = np.vstack([q0, np.asarray(targets, dtype=float).reshape(len(times), q0.size)])

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        z = np.zeros(self.q.shape[1])
        if t <= self.t[0]:
            return self.q[0].copy(), z, z.copy()
        if t >= self.t[-1]:
            return self.q[-1].copy(), z, z.copy()
        i = int(np.searchsorted(self.t, t, side="right")) - 1
        s, ds, dds = quintic(t, self.t[i], self.t[i + 1] - self.t[i])
        dq = self.q[i + 1] - self.q[i]
        return self.q[i] + s * dq, ds * dq, dds * dq
