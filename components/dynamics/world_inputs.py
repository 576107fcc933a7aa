"""What an :class:`~components.dynamics.world.OrbitalWorld` is given: the reference orbit (and the
reference point propagated from it), the Sun and the Moon, joint and base torques, and each
body's initial or set state."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from components.dynamics import link_forces
from components.dynamics.bodies import Body
from components.rotations import cross3, quat_to_matrix
from components.signals import orbit_signals


class WorldInputs:
    """The world's inputs (a part of ``OrbitalWorld``; its constructor sets the switches and bodies)."""

    bodies: dict[str, Body]
    r_eci: np.ndarray
    v_eci: np.ndarray
    q_eci_lvlh: np.ndarray
    w_lvlh: np.ndarray
    elapsed: float
    orbit_point: np.ndarray
    environment_on: bool
    sun_eci: np.ndarray | None
    moon_eci: np.ndarray | None
    tidal: bool
    gg: bool
    drag: bool
    srp: bool
    third_bodies: tuple[str, ...]
    mu: float
    _reference_cache: dict

    def set_orbit(
        self, r_eci, v_eci, q_eci_lvlh=(0.0, 0.0, 0.0, 1.0), w_lvlh=(0.0, 0.0, 0.0), age: float = 0.0
    ) -> None:
        """Reference orbit point (m, m/s, ECI), LVLH attitude q_ECI_LVLH and rate (rad/s, ECI axes),
        sampled ``age`` seconds before the current time (negative: after it, as a Gauss-Seidel run
        gives the next step's): the reference point is propagated from its own time."""
        values = (r_eci, v_eci, q_eci_lvlh, w_lvlh)
        orbit = np.concatenate(values, axis=None, dtype=float)
        if orbit.size != 13 or not math.isfinite(
            orbit.dot(orbit)
        ):  # (one product: finite unless one is not; .dot: half @'s cost)
            for signal, value in zip(orbit_signals("input"), values):
                value = np.asarray(value, dtype=float)
                if value.size != signal.size or not np.isfinite(value).all():
                    raise ValueError(f"input {signal.name}: expected {signal.size} finite values, got {value.tolist()}")
        self.r_eci, self.v_eci, self.q_eci_lvlh, self.w_lvlh = orbit[0:3], orbit[3:6], orbit[6:10], orbit[10:13]
        self.elapsed = float(age)
        self._orbit_changed(orbit[0:6])

    def _orbit_changed(self, point=None) -> None:
        self.orbit_point = np.concatenate([self.r_eci, self.v_eci]) if point is None else point  # (r_eci, v_eci)
        self._reference_cache = {}
        self.environment_on = (self.tidal or self.gg or self.drag or self.srp or bool(self.third_bodies)) and any(
            self.r_eci.tolist()
        )

    def reference(self, s: float) -> tuple[np.ndarray, np.ndarray]:
        """Reference point (r_eci, v_eci) s seconds after the orbit inputs were set."""
        cached = self._reference_cache.get(s)
        if cached is None:
            if len(self._reference_cache) > 8:
                self._reference_cache.clear()
            cached = self._reference_cache[s] = link_forces.propagate_reference(self.r_eci, self.v_eci, s, self.mu)
        return cached

    def set_sun(self, sun_eci, moon_eci) -> None:
        """The Sun and the Moon from the Earth's centre (m, ECI = W axes), for SRP, the third bodies'
        tidal force and the sun sensor: held until set again (the component sets them at each step's start)."""
        self.sun_eci = np.array(sun_eci, dtype=float)
        self.moon_eci = np.array(moon_eci, dtype=float)
        for body in self.bodies.values():
            body.set_sun(self.sun_eci, self.moon_eci)

    def set_torques(self, name: str, tau) -> None:
        """Joint torques/forces (N m or N) of body ``name`` in URDF joint order; clipped to the
        URDF effort limits; ignored on locked joints."""
        body = self.bodies[name]
        tau = np.asarray(tau, dtype=float).ravel()
        if tau.size != len(body.joints):
            raise ValueError(f"input {name}.tau: expected {len(body.joints)} values, got {tau.size}")
        if not tau.size:
            return
        if not np.isfinite(tau).all():
            k = int(np.argmax(~np.isfinite(tau)))
            raise ValueError(f"input {name}.tau: expected finite values, got {tau[k]} for {body.joints[k]}")
        body.tau[:] = 0.0
        body.tau[body.free_dofs] = np.minimum(np.maximum(tau, body.negative_effort), body.effort)[body.free]
        body.torques_changed()

    def set_base_torque(self, name: str, torque_W) -> None:
        """A pure torque on body ``name``'s base (N m, W axes; a magnetorquer's m x B), held until
        set again (``set_torques`` of a body with joints clears it: call this after it)."""
        body = self.bodies[name]
        body.tau[0:3] = torque_W
        body.torques_changed()

    def reset_bodies(self) -> None:
        """Put every body in its initial state from its spec (``frame: lvlh`` uses the orbit inputs)."""
        R_WL = quat_to_matrix(self.q_eci_lvlh)
        for body in self.bodies.values():
            spec = body.spec
            p = np.asarray(spec.position, dtype=float)
            R = quat_to_matrix(spec.orientation)
            v, w = np.asarray(spec.twist[:3], dtype=float), np.asarray(spec.twist[3:], dtype=float)
            if spec.frame == "lvlh":
                p, R = R_WL @ p, R_WL @ R
                w = self.w_lvlh + R_WL @ w
                v = R_WL @ v + cross3(self.w_lvlh, p)
            self._set_base(body, p, R, v, w, spec.q, spec.qd)

    def set_body_state(self, name: str, p_W_base, q_W_base, twist_W, q=None, qd=None) -> None:
        """Set a body's base pose and twist (W) and its joint positions/rates (URDF order)."""
        body = self.bodies[name]
        q = {} if q is None else dict(zip(body.joints, np.asarray(q, dtype=float)))
        qd = {} if qd is None else dict(zip(body.joints, np.asarray(qd, dtype=float)))
        twist = np.asarray(twist_W, dtype=float)
        self._set_base(body, np.asarray(p_W_base, dtype=float), quat_to_matrix(q_W_base), twist[:3], twist[3:], q, qd)

    @staticmethod
    def _set_base(body: Body, p, R, v, w, q: Mapping, qd: Mapping) -> None:
        positions = np.zeros(body.ndofs)
        velocities = np.zeros(body.ndofs)
        positions[:6] = body.base_coordinates(R, p)
        velocities[:3], velocities[3:6] = w, v
        for j, k in zip(body.joints, body.dof_index):
            if k >= 0:
                positions[k] = q.get(j, 0.0)
                velocities[k] = qd.get(j, 0.0)
        for k, f, multiplier, offset in body.mimic:  # where the constraint puts them
            positions[k] = multiplier * positions[f] + offset
            velocities[k] = multiplier * velocities[f]
        body.set_state(positions, velocities)
