"""The Earth's magnetic field at each body and the magnetorquers' torque, for an OrbitalWorld.

| quantity | formula | unit, frame |
|---|---|---|
| base position | r = R(t) + p_base, R the reference orbit point propagated to t, p_base in W | m, ECI |
| field | B_eci = field.b_eci(r, t) (:mod:`components.space.geomagnetic`) | T, ECI (= W axes) |
| b_body | R_W_base^T B_eci | T, base axes |
| applied dipole | m_i = clip(m_cmd,i, -m_max,i, m_max,i), per base axis | A m^2, base axes |
| torque | tau_W = (R_W_base m) x B_eci, a pure torque on the base | N m, W |
| mtb_torque | R_W_base^T tau_W = m x b_body | N m, base axes |

The field is evaluated once per step, at the step's end (t + h) for the outputs; the next step's
torque uses that field and the attitude at its start (the same instant), and holds the torque in
W axes over the step (a zero-order hold, as an actuator commanded once per step; the body turns
by w h within it: 0.25 deg at 5 deg/s and 50 ms). No orbit (r_eci = 0): no field, no torque.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from components.rotations import cross3


class Magnetics:
    """The field at every body's base origin and the torque of the bodies with magnetorquers.

    ``field``: a :class:`components.space.geomagnetic.GeomagneticField`; ``max_dipole``: body ->
    (3,) saturation (A m^2, base axes) of the bodies with magnetorquers."""

    def __init__(self, world, field, max_dipole: Mapping[str, np.ndarray]):
        self.world, self.field = world, field
        self.names = list(world.bodies)
        self.max_dipole = {name: np.asarray(m, dtype=float) for name, m in max_dipole.items()}
        self.b_eci = {name: np.zeros(3) for name in self.names}
        self.torque_body = {name: np.zeros(3) for name in self.max_dipole}

    def outputs(self, t_ns: int) -> dict[str, np.ndarray]:
        """``<body>.b_body`` (and ``<body>.mtb_torque``) at the current state and run time ``t_ns``;
        keeps the field for the next step's torque."""
        world, out = self.world, {}
        poses = [world.bodies[name].base_pose() for name in self.names]
        if any(world.r_eci.tolist()):
            R, _ = world.reference(world.elapsed)
            b = self.field.b_eci(np.array([R + p for _, p in poses]), t_ns)
        else:
            b = np.zeros((len(self.names), 3))
        for k, (name, (rotation, _)) in enumerate(zip(self.names, poses)):
            self.b_eci[name] = b[k]
            out[f"{name}.b_body"] = rotation.T @ b[k]
        for name, torque in self.torque_body.items():
            out[f"{name}.mtb_torque"] = torque.copy()
        return out

    def apply(self, inputs: Mapping[str, np.ndarray]) -> None:
        """The step's torque of each body's magnetorquers from its ``<body>.dipole`` input."""
        for name, limit in self.max_dipole.items():
            m = np.minimum(np.maximum(np.asarray(inputs[f"{name}.dipole"], dtype=float), -limit), limit)
            rotation, _ = self.world.bodies[name].base_pose()
            torque_W = cross3(rotation @ m, self.b_eci[name])
            self.world.set_base_torque(name, torque_W)
            self.torque_body[name] = rotation.T @ torque_W

    def get_state(self) -> dict[str, np.ndarray]:
        return {
            **{f"magnetic.b_eci.{n}": b.copy() for n, b in self.b_eci.items()},
            **{f"magnetic.mtb_torque.{n}": t.copy() for n, t in self.torque_body.items()},
        }

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        for name in self.names:
            self.b_eci[name] = np.array(state[f"magnetic.b_eci.{name}"], dtype=float).reshape(3)
        for name in self.torque_body:
            self.torque_body[name] = np.array(state[f"magnetic.mtb_torque.{name}"], dtype=float).reshape(3)
