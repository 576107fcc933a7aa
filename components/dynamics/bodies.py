"""One free-floating body, engine-neutral: its specification, its coordinates, and what an engine gives.

The world (:mod:`components.dynamics.world`) integrates every body in ONE set of coordinates,
whatever engine computes its dynamics (DART's FreeJoint chart):

| | layout |
|---|---|
| positions x | base rotation vector phi (R_W_base = exp(phi)), base origin p (m, W), then the free joints in URDF order (rad or m) |
| velocities v | base angular velocity omega (rad/s, W axes), base origin velocity (m/s, W), then the joint rates |
| forces Q | torque about the base origin (N m, W), force (N, W), then the joint torques / forces (dual to v) |

Free joints: the URDF's movable joints less the locked ones (welded at their initial position).
Mimic joints are coordinates like any joint; the world holds them to their joint by a constraint.

An engine's body (:class:`components.dynamics.dart_body.DartBody`,
:class:`components.dynamics.pinocchio_body.PinocchioBody`) subclasses :class:`Body` and gives, at
the state last set (``set_state``, ``set_stage``, ``set_velocities``), in these coordinates:
``positions()``, ``velocities()``, ``forward_dynamics(reference)`` (the accelerations under
``tau`` and, with ``reference`` = (point, s), the orbital environment with the reference point
``link_forces.propagate_reference``'d s seconds on from point = (R, V)), ``inverse_mass()``; for the
outputs ``base_pose()``, ``orientation()``, ``com()``, ``com_velocity()``, ``momentum()`` (and
``state_outputs()``, the body's outputs at once: from those unless an engine has them at hand),
``link_transforms()``, ``environment_wrenches(R, V)``, ``srp_wrenches(R, V)``,
``third_body_forces(R, V)``; for a grasp ``link_pose``,
``point_jacobian``, ``point_bias``; ``base_coordinates(R, p)`` for an initial state.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from components.dynamics import environment as env
from components.dynamics import manifold_rk4
from components.robots.urdf import UrdfModel
from components.rotations import matrix_to_quat
from components.signals import BODY
from components.space.gravity import MU_MOON, MU_SUN

FRAMES = ("world", "lvlh")
TWIST_ORDER = np.array([3, 4, 5, 0, 1, 2])  # (omega, v) coordinates -> the twist output (v, omega)
DEFAULT_CD = 2.2
DEFAULT_CR = 1.0  # radiation pressure coefficient of a black (absorbing) cannonball
# the third bodies whose tidal force may act on every link, in the kernels' order (link_forces.link_third_bodies),
# with their GMs (JPL DE440, components.space.gravity), m^3/s^2
THIRD_BODIES = {"sun": MU_SUN, "moon": MU_MOON}


class ModelError(ValueError):
    """A body specification that does not fit its URDF; ``key`` is relative to ``bodies``."""

    def __init__(self, key: str, message: str):
        super().__init__(f"{key}: {message}")
        self.key = key
        self.message = message


@dataclass
class BodySpec:
    """One free-floating body.

    | field | unit | meaning |
    |---|---|---|
    | name | - | body name (variables ``<name>.q`` ...) |
    | urdf | - | URDF path; its root link is the free base |
    | frame | - | ``world`` (W) or ``lvlh``: frame of position/orientation/twist |
    | position | m | base link origin |
    | orientation | - | base orientation [x, y, z, w] (q_W_base or q_LVLH_base) |
    | twist | m/s, rad/s | base origin linear velocity, then angular velocity |
    | q, qd | rad or m, per s | initial joint positions/rates by joint name (others 0) |
    | locked_joints | - | joints welded at their initial q |
    | drag_area | m^2 | link name -> reference area (links not named: no drag) |
    | drag_cd | - | drag coefficient, one number or link name -> Cd (default 2.2) |
    | srp_area | m^2 | link name -> cannonball area facing the Sun (links not named: none) |
    | srp_cr | - | radiation pressure coefficient Cr, one number or link name -> Cr (default 1) |
    | srp_facets | - | link name -> facets [{area m^2, normal, centre m (link frame), specular, diffuse}] |
    """

    name: str
    urdf: str | Path
    frame: str = "world"
    position: Sequence[float] | np.ndarray = field(default_factory=lambda: np.zeros(3))
    orientation: Sequence[float] | np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))
    twist: Sequence[float] | np.ndarray = field(default_factory=lambda: np.zeros(6))
    q: Mapping[str, float] = field(default_factory=dict)
    qd: Mapping[str, float] = field(default_factory=dict)
    locked_joints: tuple[str, ...] = ()
    drag_area: Mapping[str, float] = field(default_factory=dict)
    drag_cd: float | Mapping[str, float] = DEFAULT_CD
    srp_area: Mapping[str, float] = field(default_factory=dict)
    srp_cr: float | Mapping[str, float] = DEFAULT_CR
    srp_facets: Mapping[str, list] = field(default_factory=dict)


def check_spec(spec: BodySpec, model: UrdfModel) -> None:
    """Check a spec against its parsed URDF (cheap, no DART); ModelError naming the key."""
    n = spec.name
    if spec.frame not in FRAMES:
        raise ModelError(f"{n}.frame", f"expected one of {', '.join(FRAMES)}, got {spec.frame!r}")
    for key, given, size in (
        ("position", spec.position, 3),
        ("orientation", spec.orientation, 4),
        ("twist", spec.twist, 6),
    ):
        array = np.asarray(given, dtype=float)
        if array.shape != (size,) or not np.all(np.isfinite(array)):
            raise ModelError(f"{n}.{key}", f"expected {size} finite numbers, got {given!r}")
    if not 0.5 < np.linalg.norm(spec.orientation) < 2.0:
        raise ModelError(f"{n}.orientation", f"expected a unit quaternion [x, y, z, w], got {list(spec.orientation)}")
    movable = model.movable_joints
    for key in ("q", "qd"):
        for joint, value in getattr(spec, key).items():
            if joint not in movable:
                raise ModelError(
                    f"{n}.{key}.{joint}",
                    f"not a movable joint of {Path(spec.urdf).name} (joints: {', '.join(movable) or 'none'})",
                )
            if not math.isfinite(value):
                raise ModelError(f"{n}.{key}.{joint}", f"expected a finite number, got {value!r}")
    for key in ("q", "qd"):
        for joint in getattr(spec, key):
            if joint in model.mimics:
                raise ModelError(
                    f"{n}.{key}.{joint}",
                    f"a mimic joint: it follows {model.mimics[joint][0]!r}; set {key} of that joint instead",
                )
    for joint, value in spec.q.items():
        j = model.joint(joint)
        if not j.lower - 1e-9 <= value <= j.upper + 1e-9:
            raise ModelError(f"{n}.q.{joint}", f"expected within the URDF limits [{j.lower}, {j.upper}], got {value}")
    seen = set()
    for joint in spec.locked_joints:
        if joint not in movable:
            raise ModelError(f"{n}.locked_joints", f"{joint!r} is not a movable joint of {Path(spec.urdf).name}")
        if joint in seen:
            raise ModelError(f"{n}.locked_joints", f"{joint!r} listed twice")
        seen.add(joint)
        if spec.qd.get(joint, 0.0) != 0.0:
            raise ModelError(f"{n}.qd.{joint}", "the joint is locked: expected no initial rate")
    links = model.link_names
    for link, area in spec.drag_area.items():
        if link not in links:
            raise ModelError(f"{n}.drag_area.{link}", f"not a link of {Path(spec.urdf).name}")
        if not (area >= 0.0 and math.isfinite(area)):
            raise ModelError(f"{n}.drag_area.{link}", f"expected an area >= 0 m^2, got {area}")
    cds = spec.drag_cd.items() if isinstance(spec.drag_cd, Mapping) else [(None, spec.drag_cd)]
    for cd_link, cd in cds:
        key = f"{n}.drag_cd" + (f".{cd_link}" if cd_link is not None else "")
        if cd_link is not None and cd_link not in links:
            raise ModelError(key, f"not a link of {Path(spec.urdf).name}")
        if not (cd >= 0.0 and math.isfinite(cd)):
            raise ModelError(key, f"expected a drag coefficient >= 0, got {cd}")
    _check_srp(spec, model)


def _check_srp(spec: BodySpec, model: UrdfModel) -> None:
    """SRP on links that exist and have mass (a massless link carries no force); facets that can be."""
    from components.space.srp import facet_rows

    n, massive = spec.name, {link.name for link in model.links if link.mass > 0.0}
    crs = spec.srp_cr.items() if isinstance(spec.srp_cr, Mapping) else [(None, spec.srp_cr)]
    for key, links in (("srp_area", spec.srp_area), ("srp_facets", spec.srp_facets), ("srp_cr", dict(crs))):
        for link in links:
            if link is None:
                continue
            if link not in model.link_names:
                raise ModelError(
                    f"{n}.{key}.{link}", f"not a link of {Path(spec.urdf).name} (links: {', '.join(model.link_names)})"
                )
            if link not in massive and key != "srp_cr":
                raise ModelError(
                    f"{n}.{key}.{link}",
                    f"a link without mass carries no force in the dynamics: expected "
                    f"one with mass ({', '.join(sorted(massive))})",
                )
    for link, area in spec.srp_area.items():
        if not (area >= 0.0 and math.isfinite(area)):
            raise ModelError(f"{n}.srp_area.{link}", f"expected an area >= 0 m^2, got {area}")
    for link, cr in crs:
        if not (cr >= 0.0 and math.isfinite(cr)):
            raise ModelError(
                f"{n}.srp_cr" + (f".{link}" if link is not None else ""),
                f"expected a radiation pressure coefficient >= 0, got {cr}",
            )
    for link, facets in spec.srp_facets.items():
        try:
            facet_rows(facets, where=f"{n}.srp_facets.{link}")
        except ValueError as e:
            key, _, message = str(e).partition(": ")
            raise ModelError(key, message) from None


@dataclass(frozen=True)
class Environment:
    """The orbital environment's settings, shared by a world's bodies."""

    mu: float
    tidal: bool
    gravity_gradient: bool
    drag: bool
    atmosphere: env.ExponentialAtmosphere
    srp: bool = False
    eclipse: str = "conical"  # components.space.eclipse.MODELS
    solar_flux: float = 1361.0  # W/m^2 at 1 AU (components.space.srp.SOLAR_FLUX)
    third_bodies: tuple = ()  # THIRD_BODIES whose tidal force acts on every link

    def third(self) -> np.ndarray:
        """The kernels' ``third`` (2,): the GM (m^3/s^2) of the Sun, of the Moon, 0 for one off."""
        return np.array([THIRD_BODIES[b] if b in self.third_bodies else 0.0 for b in THIRD_BODIES])

    def light(self) -> np.ndarray:
        """The kernels' ``light`` (link_forces.LIGHT_SIZE); until ``set_sun`` (which a world's step
        requires with SRP or third bodies on) the Sun 1 AU along x, the Moon 384 400 km along y."""
        from components.constants import R_EARTH
        from components.space import eclipse, srp

        return np.array(
            [
                srp.pressure_1au(self.solar_flux),
                srp.AU,
                eclipse.MODELS[self.eclipse],
                eclipse.R_SUN,
                R_EARTH,
                eclipse.R_MOON,
                1.0 if self.eclipse == "conical" else 0.0,
                srp.AU,
                0.0,
                0.0,
                0.0,
                3.844e8,
                0.0,
            ]
        )


class Body:
    """A body's layout in the world's coordinates (see the module docstring) and the engine's interface.

    | attribute | meaning |
    |---|---|
    | joints | the URDF's movable joints, in file order: the layout of q, qd, tau |
    | dof_index | per joint: its coordinate (6...), -1 when locked |
    | lower, upper | per coordinate: the URDF position limits (+-inf for the base and unlimited joints) |
    | mimic | (mimic coordinate, followed coordinate, multiplier, offset) of each mimic pair, both free |
    | tau | generalized forces of the joints (coordinates), clipped to the URDF efforts |
    | stops, stop_sides | coordinates resting on a limit stop (rk4), +1 upper, -1 lower |
    """

    light: np.ndarray  # the kernels' light row: the engine's own array (DartBody, PinocchioBody), set_sun writes it

    def __init__(self, spec: BodySpec, model: UrdfModel, environment: Environment):
        self.spec, self.model, self.name, self.environment = spec, model, spec.name, environment
        self.joints = model.movable_joints
        self.locked = {j: float(spec.q.get(j, 0.0)) for j in spec.locked_joints}
        self.free_joints = [j for j in self.joints if j not in self.locked]
        self.ndofs = 6 + len(self.free_joints)
        coordinate = {j: 6 + i for i, j in enumerate(self.free_joints)}
        self.dof_index = np.array([coordinate.get(j, -1) for j in self.joints], dtype=int)
        self.free = self.dof_index >= 0
        self.free_dofs = self.dof_index[self.free]
        self.effort = np.array([model.joint(j).effort for j in self.joints])
        self.negative_effort = -self.effort
        self.locked_q = np.array([self.locked.get(j, 0.0) for j in self.joints])
        self.lower = np.full(self.ndofs, -np.inf)
        self.upper = np.full(self.ndofs, np.inf)
        for j, k in coordinate.items():
            self.lower[k], self.upper[k] = model.joint(j).lower, model.joint(j).upper
        self.limited = bool(np.any(np.isfinite(self.lower) | np.isfinite(self.upper)))
        # mimic pairs: rows of J (J a = 0); both joints free (a locked one holds the other through
        # the weld, or the mimic joint is locked itself)
        self.mimic = [
            (coordinate[j], coordinate[followed], multiplier, offset)
            for j, (followed, multiplier, offset) in model.mimics.items()
            if j in coordinate and followed in coordinate
        ]
        self.mimic_J = np.zeros((len(self.mimic), self.ndofs))
        for row, (k, f, multiplier, _) in enumerate(self.mimic):
            self.mimic_J[row, k], self.mimic_J[row, f] = 1.0, -multiplier
        self.link_names = model.link_names
        cd = spec.drag_cd
        self.drag_k = {
            link: 0.5
            * (float(cd.get(link, DEFAULT_CD)) if isinstance(cd, Mapping) else float(cd))
            * float(spec.drag_area.get(link, 0.0))
            for link in self.link_names
        }
        self.has_drag = any(k > 0.0 for k in self.drag_k.values())
        cr = spec.srp_cr
        self.srp_cr_area = {
            link: (float(cr.get(link, DEFAULT_CR)) if isinstance(cr, Mapping) else float(cr)) * float(area)
            for link, area in spec.srp_area.items()
            if area > 0.0
        }
        from components.space.srp import facet_rows

        self.srp_facets = {link: facet_rows(facets) for link, facets in spec.srp_facets.items() if len(facets)}
        self.has_srp = environment.srp and bool(self.srp_cr_area or self.srp_facets)
        self.tau = np.zeros(self.ndofs)
        self.stops = np.zeros(0, dtype=int)
        self.stop_sides = np.zeros(0)

    def srp_tables(self, links, rotations, offsets):
        """The kernels' SRP tables for the massive ``links`` (names, the kernels' order) whose link
        frames sit in their local axes at rotation ``rotations[k]`` and origin ``offsets[k]`` (m,
        from the link's CoM): per link (Cr A, first facet row, count), and the facets there."""
        per_link = np.zeros((len(links), 3))
        rows: list[np.ndarray] = []
        for k, link in enumerate(links):
            facets = self.srp_facets.get(link, np.zeros((0, 9)))
            per_link[k] = self.srp_cr_area.get(link, 0.0), sum(len(r) for r in rows), len(facets)
            local = facets.copy()
            local[:, 1:4] = facets[:, 1:4] @ rotations[k].T
            local[:, 4:7] = facets[:, 4:7] @ rotations[k].T + offsets[k]
            rows.append(local)
        return per_link, (np.concatenate(rows) if rows else np.zeros((0, 9))).reshape(-1, 9)

    def set_sun(self, sun_eci: np.ndarray, moon_eci: np.ndarray) -> None:
        """The Sun and the Moon from the Earth's centre (m, ECI = W axes) for SRP and the third
        bodies' tidal force, held until set again."""
        self.light[7:10] = sun_eci
        self.light[10:13] = moon_eci

    def joint_positions(self, positions: np.ndarray | None = None) -> np.ndarray:
        """URDF-order joint positions from the coordinates (the body's by default); locked joints at their lock."""
        if not self.locked:  # the joints are the coordinates 6...
            return (self.positions() if positions is None else positions)[6:].copy()
        q = self.locked_q.copy()
        q[self.free] = (self.positions() if positions is None else positions)[self.free_dofs]
        return q

    def joint_velocities(self, velocities: np.ndarray | None = None) -> np.ndarray:
        """URDF-order joint rates from the coordinates' rates (the body's by default); locked joints 0."""
        if not self.locked:
            return (self.velocities() if velocities is None else velocities)[6:].copy()
        qd = np.zeros(len(self.joints))
        qd[self.free] = (self.velocities() if velocities is None else velocities)[self.free_dofs]
        return qd

    # -- what an engine gives (see the module docstring); arrays in the world's coordinates
    def positions(self) -> np.ndarray:
        raise NotImplementedError

    def velocities(self) -> np.ndarray:
        raise NotImplementedError

    def set_state(self, positions: np.ndarray, velocities: np.ndarray) -> None:
        raise NotImplementedError

    def set_stage(self, q0: np.ndarray, xi: np.ndarray, velocities: np.ndarray) -> None:
        """The state q0 (+) xi (see ``manifold_rk4.moved``) with these velocities."""
        raise NotImplementedError

    def set_velocities(self, velocities: np.ndarray) -> None:
        raise NotImplementedError

    # -- the manifold RK4 step (components/dynamics/integration.py), through these three: an
    # engine may form a stage lazily, inside its next evaluation (PinocchioBody: one call)
    def begin_step(self) -> None:
        """A step starts from the current state (q0, v0)."""
        self.step_start = self.positions(), self.velocities()
        self.step_rates = [self.step_start[1]]  # d(xi)/dt of each stage: d1 = v0
        self.step_accelerations: list[np.ndarray] = []

    def next_stage(self, stage: int, c: float, a: np.ndarray) -> None:
        """Stage ``stage`` (2 to 4 of RK4: 1 to 3 here) from the last one's accelerations ``a``:
        q0 (+) c rate, v0 + c a (``manifold_rk4.stage``)."""
        q0, v0 = self.step_start
        xi, v, rate = manifold_rk4.stage(c, v0, self.step_rates[-1], a)
        self.step_rates.append(rate)
        self.step_accelerations.append(a)
        self.set_stage(q0, xi, v)

    def rk4_step(self, h: float, reference) -> None:
        """One RK4 step of h seconds when nothing acts between its stages (no mimic joint, no limit
        stop, no grasp): ``reference`` as ``forward_dynamics``' at the step's start (None: no
        environment). An engine may do it all in fewer calls (PinocchioBody)."""
        point, s = reference if reference is not None else (None, 0.0)
        at = (lambda t: None) if reference is None else (lambda t: (point, t))
        self.begin_step()
        self.next_stage(1, 0.5 * h, self.forward_dynamics(at(s)))
        self.next_stage(2, 0.5 * h, self.forward_dynamics(at(s + 0.5 * h)))
        self.next_stage(3, h, self.forward_dynamics(at(s + 0.5 * h)))
        self.finish_step(h, self.forward_dynamics(at(s + h)))

    def finish_step(self, h: float, a: np.ndarray) -> None:
        """The step's end from the four stages (``a``: the last one's accelerations)."""
        q0, v0 = self.step_start
        xi, v = manifold_rk4.combine(h, v0, *self.step_rates, *self.step_accelerations, a)
        self.set_stage(q0, xi, v)

    def torques_changed(self) -> None:
        """``tau`` was written."""

    def atmosphere_changed(self) -> None:
        """The environment's atmosphere bands (h0, rho0, scale) were written in place."""

    def forward_dynamics(self, reference) -> np.ndarray:
        """Accelerations (the time derivative of v) under ``tau`` and, unless ``reference`` is None,
        the environment with the reference point s seconds after it was at (R, V) (m, m/s, ECI, from
        the Earth's centre), ``reference`` = (point (6,): R then V, s): an engine propagates it
        (``link_forces.propagate_reference``), inside its own compiled call if it likes."""
        raise NotImplementedError

    def inverse_mass(self) -> np.ndarray:
        raise NotImplementedError

    def base_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """(R_W_base, base origin in W)."""
        raise NotImplementedError

    def orientation(self, R: np.ndarray) -> np.ndarray:
        """q_W_base [x, y, z, w], w >= 0, of the base's attitude R (from ``base_pose``)."""
        return matrix_to_quat(R)

    def state_vector(self) -> np.ndarray:
        """``state_outputs``' values in the declaration's order (``signals.BODY``), as one new vector."""
        state = self.state_outputs()
        return np.concatenate([state[key] for key in BODY])

    def state_outputs(self) -> dict[str, np.ndarray]:
        """The body's outputs at the current state (new arrays): position, orientation, twist, q,
        qd, com, momentum (see the component's table)."""
        R_base, position = self.base_pose()
        velocities = self.velocities()
        com = self.com()
        return {
            "position": position,
            "orientation": self.orientation(R_base),
            "twist": velocities[TWIST_ORDER],
            "q": self.joint_positions(self.positions()),
            "qd": self.joint_velocities(velocities),
            "com": com,
            "momentum": self.momentum(com, position),
        }

    def com(self) -> np.ndarray:
        raise NotImplementedError

    def com_velocity(self) -> np.ndarray:
        raise NotImplementedError

    def momentum(self, com: np.ndarray, base_position: np.ndarray) -> np.ndarray:
        """(linear kg m/s, angular kg m^2/s about the CoM), W axes (the CoM and base origin at hand)."""
        raise NotImplementedError

    def link_transforms(self) -> np.ndarray:
        """(links, 4, 4): each URDF link's pose in W, file order."""
        raise NotImplementedError

    def environment_wrenches(self, R: np.ndarray, V: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per URDF link (file order; zero for links without mass), with the reference point at
        (R, V): tidal force, drag force (N), gravity-gradient torque about the CoM (N m), W axes."""
        raise NotImplementedError

    def srp_wrenches(self, R: np.ndarray, V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per URDF link, as ``environment_wrenches``: the SRP force (N) and torque about the CoM
        (N m), W axes, with the Sun last set (``set_sun``)."""
        raise NotImplementedError

    def third_body_forces(self, R: np.ndarray, V: np.ndarray) -> np.ndarray:
        """Per URDF link, as ``environment_wrenches``: the Sun's and the Moon's tidal force (N, W
        axes, at the CoM), with their positions last set (``set_sun``)."""
        raise NotImplementedError

    def link_pose(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """(p, R) of a URDF link in W."""
        raise NotImplementedError

    def point_jacobian(self, link: str, point: np.ndarray) -> np.ndarray:
        """(6, ndofs): the world velocity (angular; linear) of a point fixed in the link (given in
        its frame), over the coordinates' rates."""
        raise NotImplementedError

    def point_bias(self, link: str, point: np.ndarray) -> np.ndarray:
        """(6,): that point's acceleration (angular; linear, classical, W) at zero accelerations."""
        raise NotImplementedError

    def base_coordinates(self, R: np.ndarray, p: np.ndarray) -> np.ndarray:
        """The base's coordinates (rotation vector, origin) of the pose (R, p)."""
        return np.concatenate([manifold_rk4.log_so3(np.ascontiguousarray(R, dtype=float)), p])
