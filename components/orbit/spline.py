"""C2 quintic Hermite spline through waypoints with position, velocity and acceleration.

Plain numpy; no bus, no I/O. Times in s, positions in m, velocities in m/s, accelerations in
m/s^2, in any fixed frame (ECI for ``orbit.custom_path``).

On each segment [t_k, t_k+1] (length h, s = (t - t_k)/h in [0, 1]) the curve is the unique
quintic p(s) = c0 + c1 s + ... + c5 s^5 with p, dp/dt, d2p/dt2 equal to the waypoint values at
both ends. With P = p1 - p0 - h v0 - h^2 a0 / 2, V = h (v1 - v0) - h^2 a0, A = h^2 (a1 - a0):
    c0 = p0, c1 = h v0, c2 = h^2 a0 / 2,
    c3 = 10 P - 4 V + A / 2,  c4 = -15 P + 7 V - A,  c5 = 6 P - 3 V + A / 2.
Neighbouring segments share the waypoint's p, v, a, so the spline is C2 everywhere.
"""

from __future__ import annotations

import bisect

import numpy as np


class SplineError(ValueError):
    """Invalid waypoints; ``index`` is the waypoint at fault (None when it is the whole list)."""

    def __init__(self, message: str, index: int | None = None):
        super().__init__(message)
        self.index = index


class QuinticHermiteSpline:
    """Piecewise quintic through (t_k, p_k, v_k, a_k), k = 0..N-1, N >= 2, t strictly increasing.

    times: (N,) s; positions, velocities, accelerations: (N, d) in m, m/s, m/s^2.
    Evaluate with :meth:`evaluate` inside [t_0, t_N-1].
    """

    def __init__(self, times, positions, velocities, accelerations):
        t = np.asarray(times, dtype=np.float64)
        p = np.asarray(positions, dtype=np.float64)
        v = np.asarray(velocities, dtype=np.float64)
        a = np.asarray(accelerations, dtype=np.float64)
        if t.ndim != 1 or t.size < 2:
            raise SplineError(f"expected at least 2 waypoints, got {t.size}")
        for name, arr in (("position", p), ("velocity", v), ("acceleration", a)):
            if arr.ndim != 2 or arr.shape[0] != t.size or arr.shape != p.shape:
                raise SplineError(f"expected {name}s of shape {(t.size,) + p.shape[1:]}, got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                k = int(np.argwhere(~np.isfinite(arr))[0, 0])
                raise SplineError(f"expected finite {name}s, got {arr[k].tolist()} at waypoint {k}", k)
        if not np.all(np.isfinite(t)):
            k = int(np.argwhere(~np.isfinite(t))[0, 0])
            raise SplineError(f"expected finite times, got {float(t[k])!r} at waypoint {k}", k)
        steps = np.diff(t)
        if np.any(steps <= 0.0):
            k = int(np.argmax(steps <= 0.0)) + 1
            raise SplineError(
                f"expected strictly increasing times, got t[{k - 1}] = {float(t[k - 1])!r} s "
                f"then t[{k}] = {float(t[k])!r} s",
                k,
            )
        self.times = t
        h = steps[:, None]
        p0, p1, v0, v1, a0, a1 = p[:-1], p[1:], v[:-1], v[1:], a[:-1], a[1:]
        big_p = p1 - p0 - h * v0 - 0.5 * h * h * a0
        big_v = h * (v1 - v0) - h * h * a0
        big_a = h * h * (a1 - a0)
        # coefficients in s, shape (segments, 6, d)
        self._coef = np.stack(
            [
                p0,
                h * v0,
                0.5 * h * h * a0,
                10.0 * big_p - 4.0 * big_v + 0.5 * big_a,
                -15.0 * big_p + 7.0 * big_v - big_a,
                6.0 * big_p - 3.0 * big_v + 0.5 * big_a,
            ],
            axis=1,
        )

    @property
    def start(self) -> float:
        """First waypoint time, s."""
        return float(self.times[0])

    @property
    def end(self) -> float:
        """Last waypoint time, s."""
        return float(self.times[-1])

    def segment(self, t: float) -> int:
        """Index k of the segment [t_k, t_k+1] holding t (the last one for t = t_N-1)."""
        k = bisect.bisect_right(self.times, t) - 1
        return min(max(k, 0), len(self.times) - 2)

    def evaluate(self, t: float, segment: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position (m), velocity (m/s) and acceleration (m/s^2) at time t (s).

        ``segment`` forces the polynomial of one segment (to probe continuity at a joint).
        Raises ValueError outside [t_0, t_N-1].
        """
        t = float(t)
        if not self.start <= t <= self.end:
            raise ValueError(f"time {t!r} s is outside the waypoints' span [{self.start!r}, {self.end!r}] s")
        k = self.segment(t) if segment is None else int(segment)
        t0, t1 = self.times[k], self.times[k + 1]
        h = t1 - t0
        s = (t - t0) / h
        c = self._coef[k]
        pos = c[0] + s * (c[1] + s * (c[2] + s * (c[3] + s * (c[4] + s * c[5]))))
        dps = c[1] + s * (2.0 * c[2] + s * (3.0 * c[3] + s * (4.0 * c[4] + s * 5.0 * c[5])))
        d2ps = 2.0 * c[2] + s * (6.0 * c[3] + s * (12.0 * c[4] + s * 20.0 * c[5]))
        return pos, dps / h, d2ps / (h * h)
