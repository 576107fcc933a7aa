"""An :class:`~components.dynamics.world.OrbitalWorld`'s state: everything a restart or a swap to
the other engine needs to continue, in one form for both engines."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from components.dynamics.capture import Grasp
from components.dynamics.world_inputs import WorldInputs
from components.signals import ORBIT

BODY_STATE = {"position": 3, "rotation_vector": 3, "twist": 6}  # + q, qd, tau, stop_side: one per joint


class WorldState(WorldInputs):
    """``get_state`` and ``set_state`` (a part of ``OrbitalWorld``)."""

    grasp: Grasp | None

    def get_state(self) -> dict[str, np.ndarray | np.float64]:
        """Everything needed to continue bit-exactly, in one form for every engine: per body
        ``position`` (m), ``rotation_vector`` (rad: R_W_base = exp of it), ``twist`` (m/s, rad/s:
        the base origin's, W), ``q``, ``qd``, ``tau`` (URDF joint order, locked joints at their
        lock), ``stop_side`` (per joint: +1 resting on its upper stop, -1 on its lower, 0 free);
        the orbit inputs and the time since they were set; the grasp's weld."""
        orbit = (self.r_eci, self.v_eci, self.q_eci_lvlh, self.w_lvlh)
        state: dict[str, np.ndarray | np.float64] = {
            **{key: value.copy() for key, value in zip(ORBIT, orbit)},
            "elapsed": np.float64(self.elapsed),
        }
        for name, body in self.bodies.items():
            x, v = body.positions(), body.velocities()
            side = np.zeros(body.ndofs)
            side[body.stops] = body.stop_sides
            state[f"{name}.position"], state[f"{name}.rotation_vector"] = x[3:6].copy(), x[0:3].copy()
            state[f"{name}.twist"] = np.concatenate([v[3:6], v[0:3]])
            state[f"{name}.q"], state[f"{name}.qd"] = body.joint_positions(x), body.joint_velocities(v)
            state[f"{name}.tau"] = body.joint_velocities(body.tau)
            state[f"{name}.stop_side"] = body.joint_velocities(side)
        if self.grasp is not None:
            state.update(self.grasp.get_state())
        return state

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        for key in ORBIT + ("elapsed",):
            if key not in state:
                raise ValueError(f"state: missing {key!r}")
        for name, body in self.bodies.items():
            sizes = {**BODY_STATE, **dict.fromkeys(("q", "qd", "tau", "stop_side"), len(body.joints))}
            for key, size in sizes.items():
                value = state.get(f"{name}.{key}")
                if value is None or np.shape(value) != (size,):
                    raise ValueError(
                        f"state: {name}.{key} expected {size} values, got {None if value is None else np.shape(value)}"
                    )
            if not np.all(np.isin(state[f"{name}.stop_side"], (-1.0, 0.0, 1.0))):
                raise ValueError(
                    f"state: {name}.stop_side expected -1, 0 or 1 per joint, got {state[f'{name}.stop_side']}"
                )
        self.r_eci, self.v_eci, self.q_eci_lvlh, self.w_lvlh = (np.array(state[key], dtype=float) for key in ORBIT)
        self.elapsed = float(state["elapsed"])
        self._orbit_changed()
        for name, body in self.bodies.items():
            x, v, side = np.zeros(body.ndofs), np.zeros(body.ndofs), np.zeros(body.ndofs)
            twist = np.asarray(state[f"{name}.twist"], dtype=float)
            x[0:3], x[3:6] = state[f"{name}.rotation_vector"], state[f"{name}.position"]
            v[0:3], v[3:6] = twist[3:6], twist[0:3]
            for target, key in ((x, "q"), (v, "qd"), (body.tau, "tau"), (side, "stop_side")):
                target[body.free_dofs] = np.asarray(state[f"{name}.{key}"], dtype=float)[body.free]
            body.set_state(x, v)
            body.torques_changed()
            body.stops = np.flatnonzero(side)
            body.stop_sides = side[body.stops]
        if self.grasp is not None:
            self.grasp.set_state(state)
