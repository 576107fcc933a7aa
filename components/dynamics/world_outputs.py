"""What an :class:`~components.dynamics.world.OrbitalWorld` reports of its bodies at the current
state: the state outputs, the per-link environment wrenches and poses, momentum, LVLH and the
frames relative to it, a sun sensor and an IMU."""

from __future__ import annotations

import numpy as np

from components.dynamics import environment as env
from components.dynamics.bodies import THIRD_BODIES, Environment
from components.dynamics.world_inputs import WorldInputs
from components.rotations import cross3, matrix_to_quat


class WorldOutputs(WorldInputs):
    """The world's outputs (a part of ``OrbitalWorld``)."""

    environment: Environment

    def momentum(self, name: str) -> np.ndarray:
        """(linear kg m/s, angular kg m^2/s about the body's CoM), W axes."""
        body = self.bodies[name]
        return body.momentum(body.com(), body.base_pose()[1])

    def outputs(self, name: str, links: bool = True) -> dict[str, np.ndarray]:
        """Every output of body ``name`` at the current state (see the component's table);
        ``links=False`` leaves out the per-link ones (poses and environment wrenches)."""
        out = self.bodies[name].state_outputs()
        if links:
            out.update(self.link_outputs(name))
        return out

    def link_outputs(self, name: str) -> dict[str, np.ndarray]:
        """Per URDF link (file order), W axes: environment wrenches at the current state
        (``gg_torque``, ``tidal_force``, ``drag_force``, ``srp_force``, ``srp_torque``; with
        third bodies ``third_body_force``) and ``link_position``, ``link_orientation``."""
        body = self.bodies[name]
        T = body.link_transforms()
        zeros = np.zeros((len(body.link_names), 3))
        reference = self.reference(self.elapsed) if self.environment_on else None
        tidal, drag, gg = body.environment_wrenches(*reference) if reference else (zeros,) * 3
        srp_force, srp_torque = body.srp_wrenches(*reference) if reference and body.has_srp else (zeros,) * 2
        out = {
            "gg_torque": gg.ravel(),
            "tidal_force": tidal.ravel(),
            "drag_force": drag.ravel(),
            "srp_force": srp_force.ravel(),
            "srp_torque": srp_torque.ravel(),
            "link_position": T[:, :3, 3].ravel(),
            "link_orientation": matrix_to_quat(T[:, :3, :3]).ravel(),
        }
        if self.third_bodies:
            out["third_body_force"] = (body.third_body_forces(*reference) if reference else zeros).ravel()
        return out

    def sun_outputs(self, name: str) -> dict[str, np.ndarray]:
        """A sun sensor at the base origin, true values: ``sun_body``, the unit vector from it to the
        Sun in base axes, and ``sunlit``, the illumination factor there (the world's eclipse model;
        1 without an orbit, r_eci = 0). Needs ``set_sun``."""
        from components.space.eclipse import illumination

        R_base, p = self.bodies[name].base_pose()
        orbit = any(self.r_eci.tolist())
        x = self.reference(self.elapsed)[0] + p if orbit else p
        s = self.sun_eci - x
        model = self.environment.eclipse
        nu = illumination(x, self.sun_eci, self.moon_eci if model == "conical" else None, model) if orbit else 1.0
        return {"sun_body": R_base.T @ (s / np.linalg.norm(s)), "sunlit": np.float64(nu)}

    def lvlh(self) -> tuple[np.ndarray, np.ndarray]:
        """R_W_LVLH and LVLH's angular velocity (rad/s, W axes) now, from the reference point as
        propagated to the current time (the orbit inputs may be a step old)."""
        cached = self._reference_cache.get(("lvlh", self.elapsed))  # (every body's frame outputs ask)
        if cached is None:
            R, V = self.reference(self.elapsed)
            h = cross3(R, V)
            x, z = R / np.linalg.norm(R), h / np.linalg.norm(h)
            cached = np.column_stack([x, cross3(z, x), z]), h / np.dot(R, R)
            self._reference_cache[("lvlh", self.elapsed)] = cached
        return cached

    def frame_outputs(self, name: str) -> dict[str, np.ndarray]:
        """The body's CoM frame (origin at the CoM, base axes: the paper's F_c / F_t) relative to
        LVLH: ``p_lvlh_com`` (m), ``q_lvlh_body``, ``v_lvlh_com`` (m/s, the rate seen in LVLH),
        ``w_lvlh_body`` (rad/s), LVLH axes. Without an orbit (r_eci = 0) LVLH is W."""
        body = self.bodies[name]
        c, v_c = body.com(), body.com_velocity()
        R_base = body.base_pose()[0]
        w = body.velocities()[:3]
        R_WL, w_L = self.lvlh() if any(self.r_eci.tolist()) else (np.eye(3), np.zeros(3))
        return {
            "p_lvlh_com": R_WL.T @ c,
            "q_lvlh_body": matrix_to_quat(R_WL.T @ R_base),
            "v_lvlh_com": R_WL.T @ (v_c - cross3(w_L, c)),
            "w_lvlh_body": R_WL.T @ (w - w_L),
        }

    def relative_frames(self, chaser: str, target: str) -> dict[str, np.ndarray]:
        """Target's CoM frame F_t relative to the chaser's F_c, in F_c axes: ``p_c_t`` (m),
        ``q_c_t`` (q_Fc_Ft), ``v_c_t`` (m/s, the rate of p_c_t seen in F_c), ``w_c_t`` (rad/s)."""
        c, t = self.bodies[chaser], self.bodies[target]
        R_c, R_t = c.base_pose()[0], t.base_pose()[0]
        w_c, w_t = c.velocities()[:3], t.velocities()[:3]
        d = t.com() - c.com()
        v = t.com_velocity() - c.com_velocity() - cross3(w_c, d)
        return {
            "p_c_t": R_c.T @ d,
            "q_c_t": matrix_to_quat(R_c.T @ R_t),
            "v_c_t": R_c.T @ v,
            "w_c_t": R_c.T @ (w_t - w_c),
        }

    def imu_outputs(self, name: str, accelerations: np.ndarray) -> dict[str, np.ndarray]:
        """An IMU at the base origin: ``imu_rate`` (rad/s) and ``specific_force`` (m/s^2: the
        origin's acceleration minus the gravity the world applies there, i.e. the tidal
        acceleration when tidal_force is on and the third bodies' when they are), base axes.
        ``accelerations``: the body's, from ``accelerations()``."""
        body = self.bodies[name]
        R_base, p = body.base_pose()
        a = np.array(accelerations[3:6], dtype=float)  # classical acceleration of the base origin, W
        if self.tidal and self.environment_on:
            R, _ = self.reference(self.elapsed)
            a = a - env.tidal_acceleration(R, p[None, :], self.mu)[0]
        if self.third_bodies and self.environment_on:
            R, _ = self.reference(self.elapsed)
            for b, s in (("sun", self.sun_eci), ("moon", self.moon_eci)):
                if b in self.third_bodies:
                    assert s is not None, "set_sun comes first with third bodies"
                    a = a - env.third_body_tidal_acceleration(R, p[None, :], s, THIRD_BODIES[b])[0]
        return {"imu_rate": R_base.T @ body.velocities()[:3], "specific_force": R_base.T @ a}
