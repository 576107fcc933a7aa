"""Free-floating multibodies in orbit: DART forward dynamics in the free-falling world frame W.

``OrbitalWorld`` is the physics of the ``dynamics.dart`` component as a plain class (no bus, no
I/O): several bodies, each a URDF on a free-floating base (DART FreeJoint), in zero gravity with
the orbital environment of :mod:`components.dynamics.environment` (tidal force, gravity-gradient
torque, drag) computed per link from the reference orbit inputs, at every integrator stage, and
applied as generalized forces (J^T W over the links, through DART's Jacobians).

Frames: W has its origin at the reference orbit point r_eci(t), axes parallel to ECI, and falls
freely (it does not rotate). LVLH (Hill): x radial, z orbit normal, y = z x x. Quaternions are
[x, y, z, w]; q_A_B rotates vectors in B into A.

Integrators (``integrator``):

- ``rk4`` (default): classical Runge-Kutta 4 on the configuration manifold (Runge-Kutta-Munthe-
  Kaas): stages evaluate DART's ``computeForwardDynamics`` at q0 (+) xi, where (+) is DART's
  chart (for the FreeJoint: R = exp(xi_w) R0, p = p0 + xi_v with world-frame rates) with an SO(3)
  exponential exact at every angle (``manifold_rk4.moved``); the stage derivative of xi maps the angular velocity through the inverse left Jacobian
  of SO(3). Fourth order; momentum drifts ~1e-10 (relative) over 10 s at 1 ms. Contacts are not
  handled; joint position limits act as inelastic stops (a momentum-conserving joint impulse).
- ``dart``: DART's native ``World.step`` (semi-implicit Euler + constraint solver): contacts
  between bodies, joint limits as constraints. First order (momentum drift ~1e-3 over 10 s at
  1 ms): use it when bodies touch.

Each communication step ``step(h)`` runs ``substeps`` internal steps of h / substeps. Within a
step the orbit inputs are held, but the reference point moves along its Kepler arc
(:func:`environment.propagate_reference`) from the time the inputs were sampled (``set_orbit``'s
``age``), so neither a long step, a slower orbit component nor Gauss-Seidel's one-step lead
shifts the tidal field in time.

Per body (see ``BodySpec``): the base pose and twist and the joint positions/rates at
``reset_bodies``, in W or in LVLH (``frame: lvlh``: relative to LVLH, including its rotation:
a zero twist co-rotates with LVLH). ``locked_joints`` are welded at their initial position.
Joint torques are clipped to the URDF effort limits. URDF joint damping/friction is ignored.

Mimic joints (URDF ``<mimic>``: q = multiplier q_followed + offset) are a holonomic constraint.
``rk4``: each stage's accelerations are projected onto it with a joint-space constraint force
(``a - M^-1 J^T (J M^-1 J^T)^-1 J a``; internal, so momentum is kept), and ``reset_bodies`` puts
the mimic joint where the constraint says. ``dart``: DART's own mimic constraint (the loader sets
the joint's actuator to MIMIC). The mimic joint's q, qd are outputs like any joint's; a torque on
it acts through the constraint.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np

from components.constants import EARTH_RATE, MU_EARTH, R_EARTH
from components.dynamics import environment as env
from components.dynamics import link_forces, manifold_rk4
from components.dynamics.capture import CaptureReport, Grasp, GraspSpec
from components.robots.urdf import UrdfModel, dart_urdf_text, read_urdf
from components.rotations import cross3, matrix_to_quat, quat_to_matrix, rpy_to_matrix
from components.signals import ORBIT, orbit_signals

INTEGRATORS = ("rk4", "dart")
FRAMES = ("world", "lvlh")
DEFAULT_CD = 2.2
ORIGIN = np.zeros(3)


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
    """
    name: str
    urdf: str | Path
    frame: str = "world"
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    orientation: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))
    twist: np.ndarray = field(default_factory=lambda: np.zeros(6))
    q: Mapping[str, float] = field(default_factory=dict)
    qd: Mapping[str, float] = field(default_factory=dict)
    locked_joints: tuple[str, ...] = ()
    drag_area: Mapping[str, float] = field(default_factory=dict)
    drag_cd: float | Mapping[str, float] = DEFAULT_CD


def check_spec(spec: BodySpec, model: UrdfModel) -> None:
    """Check a spec against its parsed URDF (cheap, no DART); ModelError naming the key."""
    n = spec.name
    if spec.frame not in FRAMES:
        raise ModelError(f"{n}.frame", f"expected one of {', '.join(FRAMES)}, got {spec.frame!r}")
    for key, value, size in (("position", spec.position, 3), ("orientation", spec.orientation, 4),
                             ("twist", spec.twist, 6)):
        array = np.asarray(value, dtype=float)
        if array.shape != (size,) or not np.all(np.isfinite(array)):
            raise ModelError(f"{n}.{key}", f"expected {size} finite numbers, got {value!r}")
    if not 0.5 < np.linalg.norm(spec.orientation) < 2.0:
        raise ModelError(f"{n}.orientation", f"expected a unit quaternion [x, y, z, w], got {list(spec.orientation)}")
    movable = model.movable_joints
    for key in ("q", "qd"):
        for joint, value in getattr(spec, key).items():
            if joint not in movable:
                raise ModelError(f"{n}.{key}.{joint}", f"not a movable joint of {Path(spec.urdf).name} "
                                                       f"(joints: {', '.join(movable) or 'none'})")
            if not math.isfinite(value):
                raise ModelError(f"{n}.{key}.{joint}", f"expected a finite number, got {value!r}")
    for key in ("q", "qd"):
        for joint in getattr(spec, key):
            if joint in model.mimics:
                raise ModelError(f"{n}.{key}.{joint}", f"a mimic joint: it follows {model.mimics[joint][0]!r}; "
                                                       f"set {key} of that joint instead")
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
    for link, cd in cds:
        key = f"{n}.drag_cd" + (f".{link}" if link is not None else "")
        if link is not None and link not in links:
            raise ModelError(key, f"not a link of {Path(spec.urdf).name}")
        if not (cd >= 0.0 and math.isfinite(cd)):
            raise ModelError(key, f"expected a drag coefficient >= 0, got {cd}")


# --------------------------------------------------------------------------- bodies

class _Body:
    """A body's DART skeleton and the index maps between it and the URDF's variable layout."""

    def __init__(self, spec: BodySpec, model: UrdfModel, dart, integrator: str = "rk4"):
        self.spec, self.model, self.name = spec, model, spec.name
        self.joints = model.movable_joints                     # URDF order: layout of q, qd, tau
        self.locked = {j: float(spec.q.get(j, 0.0)) for j in spec.locked_joints}
        loader = dart.utils.DartLoader()
        options = dart.utils.DartLoader.Options()
        options.mDefaultRootJointType = dart.utils.DartLoader.RootJointType.FLOATING
        frames = model.frame_links()
        if any(not link.has_inertial and link.name not in frames for link in model.links):
            massless = dart.dynamics.Inertia()                  # links without <inertial>: 0 kg, as in URDF
            massless.setMass(0.0)                               # (DART's default is 1 kg; it warns on 0)
            massless.setMoment(np.zeros((3, 3)))
            options.mDefaultInertia = massless
        loader.setOptions(options)
        uri = dart.common.Uri.createFromPath(str(Path(spec.urdf).resolve()))
        skel = loader.parseSkeletonString(dart_urdf_text(model, self.locked), uri)
        if skel is None:
            raise ModelError(f"{spec.name}.urdf", f"DART could not load {spec.urdf}")
        skel.setName(spec.name)
        skel.setGravity(np.zeros(3))
        skel.disableSelfCollisionCheck()
        self.skel = skel
        if skel.getRootJoint().getType() != "FreeJoint":
            raise ModelError(f"{spec.name}.urdf", f"expected a free-floating base, DART made a {skel.getRootJoint().getType()}")
        self.ndofs = skel.getNumDofs()
        dof_names = [skel.getDof(i).getName() for i in range(self.ndofs)]
        # joints: URDF order -> DART dof index (-1 when locked)
        self.dof_index = np.array([-1 if j in self.locked else dof_names.index(j) for j in self.joints], dtype=int)
        self.free = self.dof_index >= 0
        self.free_dofs = self.dof_index[self.free]
        self.effort = np.array([model.joint(j).effort for j in self.joints])
        self.negative_effort = -self.effort
        self.locked_q = np.array([self.locked.get(j, 0.0) for j in self.joints])
        for i in range(6, self.ndofs):                         # no joint friction, springs or damping
            dof = skel.getDof(i)
            dof.setDampingCoefficient(0.0)
            dof.setCoulombFriction(0.0)
            dof.setSpringStiffness(0.0)
        lower = np.full(self.ndofs, -np.inf)
        upper = np.full(self.ndofs, np.inf)
        for j, k in zip(self.joints, self.dof_index):
            if k >= 0:
                lower[k], upper[k] = model.joint(j).lower, model.joint(j).upper
        self.lower, self.upper = lower, upper
        self.limited = bool(np.any(np.isfinite(lower) | np.isfinite(upper)))
        # mimic joints: rows of J (J a = 0) over DART's dofs; both joints free (a locked one
        # holds the other through the weld, or the mimic joint is locked itself)
        dof_of = dict(zip(self.joints, self.dof_index.tolist()))
        self.mimic = []                                        # (mimic dof, followed dof, multiplier, offset)
        for j, (followed, multiplier, offset) in model.mimics.items():
            if dof_of.get(j, -1) >= 0 and dof_of.get(followed, -1) >= 0:
                self.mimic.append((dof_of[j], dof_of[followed], multiplier, offset))
        self.mimic_J = np.zeros((len(self.mimic), self.ndofs))
        for row, (k, f, multiplier, _) in enumerate(self.mimic):
            self.mimic_J[row, k], self.mimic_J[row, f] = 1.0, -multiplier
        mimic_joints = {j for j in model.mimics if dof_of.get(j, -1) >= 0}
        for joint in (skel.getJoint(j) for j in mimic_joints):  # rk4 projects; dart keeps DART's MIMIC actuator
            if joint.getActuatorType() == dart.dynamics.ActuatorType.MIMIC and integrator == "rk4":
                joint.setActuatorType(dart.dynamics.ActuatorType.FORCE)
        # links: DART body nodes with mass (environment), URDF link order (outputs)
        nodes = {skel.getBodyNode(i).getName(): skel.getBodyNode(i) for i in range(skel.getNumBodyNodes())}
        self.nodes = [bn for bn in nodes.values() if bn.getMass() > 0.0]
        self.has_massless = len(self.nodes) < len(nodes)
        self.mass = np.array([bn.getMass() for bn in self.nodes])
        self.local_com = np.array([bn.getLocalCOM() for bn in self.nodes]).reshape(-1, 3)
        self.local_inertia = np.array([bn.getInertia().getMoment() for bn in self.nodes]).reshape(-1, 3, 3)
        self.total_mass = float(self.mass.sum())
        # A link welded to its parent (fixed URDF joint, locked joint) moves with its anchor, the
        # nearest ancestor that is not welded (or itself). The environment needs one DART call per
        # anchor: its Jacobian, which gives the anchor's pose (see _anchor_frames) and maps the
        # wrench of its links to generalized forces (J^T W: no DART call per link and wrench).
        anchor_index: dict[str, int] = {}
        self.anchors = []
        slots, com_in_anchor, inertia_in_anchor = [], [], []
        for bn, com, inertia in zip(self.nodes, self.local_com, self.local_inertia):
            anchor, T = bn, np.eye(4)
            while anchor.getParentJoint().getType() == "WeldJoint":
                T = anchor.getParentJoint().getRelativeTransform().matrix() @ T
                anchor = anchor.getParentBodyNode()
            if anchor.getName() not in anchor_index:
                anchor_index[anchor.getName()] = len(self.anchors)
                self.anchors.append(anchor)
            slots.append(anchor_index[anchor.getName()])
            com_in_anchor.append(T[:3, :3] @ com + T[:3, 3])
            inertia_in_anchor.append(T[:3, :3] @ inertia @ T[:3, :3].T)
        self.anchor_slot = np.array(slots, dtype=int)
        self.com_in_anchor = np.array(com_in_anchor).reshape(-1, 3)
        self.inertia_in_anchor = np.array(inertia_in_anchor).reshape(-1, 3, 3)
        # columns of the anchors' Jacobians side by side: their dof, their anchor; and the
        # columns of the base rotation (the FreeJoint's first three dofs come first in each)
        dofs = [[anchor.getDependentGenCoordIndex(i) for i in range(anchor.getNumDependentGenCoords())]
                for anchor in self.anchors]
        self.jacobian_dofs = np.array([dof for anchor_dofs in dofs for dof in anchor_dofs], dtype=int)
        self.jacobian_anchor = np.repeat(np.arange(len(self.anchors)), [len(anchor_dofs) for anchor_dofs in dofs]).astype(int)
        starts = np.cumsum([0] + [len(anchor_dofs) for anchor_dofs in dofs[:-1]])
        self.base_rotation_columns = (starts[:, None] + np.arange(3)).astype(int)
        self.root = skel.getRootBodyNode()
        node_slot = {bn.getName(): i for i, bn in enumerate(self.nodes)}
        self.link_names = model.link_names
        self.link_source = []                                  # (node or None, env slot or -1, fixed offset)
        for link in self.link_names:
            if link in frames:
                joint = frames[link]
                T = np.eye(4)
                T[:3, :3], T[:3, 3] = rpy_to_matrix(joint.rpy), joint.xyz
                self.link_source.append((nodes[joint.parent], -1, T))
            else:
                self.link_source.append((nodes[link], node_slot.get(link, -1), None))
        self.massive_links = np.array([i for i, (_, slot, _) in enumerate(self.link_source) if slot >= 0], dtype=int)
        self.massive_slots = np.array([slot for _, slot, _ in self.link_source if slot >= 0], dtype=int)
        cd = spec.drag_cd
        self.drag_area = np.array([float(spec.drag_area.get(bn.getName(), 0.0)) for bn in self.nodes])
        self.drag_cd = np.array([float(cd.get(bn.getName(), DEFAULT_CD)) if isinstance(cd, Mapping) else float(cd)
                                 for bn in self.nodes])
        self.has_drag = bool(np.any(self.drag_area * self.drag_cd > 0.0))
        self.drag_k = 0.5 * self.drag_cd * self.drag_area
        self.force = np.zeros((len(self.nodes), 3))            # environment per link, anchor axes
        self.torque = np.zeros((len(self.nodes), 3))
        self.tau = np.zeros(self.ndofs)                        # generalized forces, DART order
        self.stops = np.zeros(0, dtype=int)                    # rk4: dofs resting on a limit stop
        self.stop_sides = np.zeros(0)                          # +1 upper, -1 lower

    def inverse_mass(self) -> np.ndarray:
        """M^-1 at the skeleton's state. DART's getInvMassMatrix is wrong (off by O(1)) when a body
        node has zero mass (a URDF's massless flange between two links, say): then M is inverted."""
        if self.has_massless:
            return np.linalg.inv(self.skel.getMassMatrix())
        return self.skel.getInvMassMatrix()

    # -- state in variable layout
    def joint_positions(self, positions: np.ndarray | None = None) -> np.ndarray:
        """URDF-order joint positions from DART's (the skeleton's by default); locked joints at their lock."""
        q = self.locked_q.copy()
        q[self.free] = (self.skel.getPositions() if positions is None else positions)[self.free_dofs]
        return q

    def joint_velocities(self, velocities: np.ndarray | None = None) -> np.ndarray:
        """URDF-order joint rates from DART's (the skeleton's by default); locked joints 0."""
        qd = np.zeros(len(self.joints))
        qd[self.free] = (self.skel.getVelocities() if velocities is None else velocities)[self.free_dofs]
        return qd


class OrbitalWorld:
    """Free-floating URDF bodies in the free-falling frame W, with the orbital environment.

    | constructor argument | default | meaning |
    |---|---|---|
    | bodies | - | list of BodySpec (unique names) |
    | integrator | rk4 | rk4 (manifold RK4 on DART forward dynamics) or dart (DART step, contacts) |
    | substeps | 1 | internal steps per ``step(h)`` |
    | tidal_force, gravity_gradient, drag | True, True, False | environment terms, per link |
    | mu | 3.986004418e14 m^3/s^2 | Earth's gravitational parameter |
    | atmosphere | None | ExponentialAtmosphere; None = the 0-1000 km table |
    | joint_limits | True | enforce URDF position limits |

    Use: ``set_orbit(r_eci, v_eci, q_eci_lvlh, w_lvlh)`` then ``reset_bodies()`` (initial state,
    which needs LVLH for ``frame: lvlh`` bodies); per step ``set_orbit(...)``,
    ``set_torques(name, tau)``, ``step(h)``, ``outputs(name)``. ``get_state``/``set_state`` carry
    everything a restart needs to continue bit-exactly.

    r_eci = 0 means "no orbit": the environment forces are then zero (deep space).
    """

    def __init__(self, bodies: list[BodySpec], *, integrator: str = "rk4", substeps: int = 1,
                 tidal_force: bool = True, gravity_gradient: bool = True, drag: bool = False,
                 mu: float = MU_EARTH, atmosphere: env.ExponentialAtmosphere | None = None,
                 joint_limits: bool = True, models: Mapping[str, UrdfModel] | None = None,
                 grasp: GraspSpec | None = None):
        import dartpy as dart

        if integrator not in INTEGRATORS:
            raise ValueError(f"integrator: expected one of {', '.join(INTEGRATORS)}, got {integrator!r}")
        if not (isinstance(substeps, int) and substeps >= 1):
            raise ValueError(f"substeps: expected an integer >= 1, got {substeps!r}")
        self.integrator, self.substeps = integrator, substeps
        self.tidal, self.gg, self.drag = bool(tidal_force), bool(gravity_gradient), bool(drag)
        self.mu = float(mu)
        self.atmosphere = atmosphere or env.ExponentialAtmosphere()
        self.joint_limits = bool(joint_limits)
        self.world = dart.simulation.World()
        self.world.setGravity(np.zeros(3))
        self.bodies: dict[str, _Body] = {}
        for spec in bodies:
            if spec.name in self.bodies:
                raise ModelError(spec.name, "duplicate body name")
            model = (models or {}).get(spec.name) or read_urdf(spec.urdf)
            check_spec(spec, model)
            body = _Body(spec, model, dart, integrator)
            self.world.addSkeleton(body.skel)
            body.skel.setGravity(np.zeros(3))
            if integrator == "dart" and joint_limits:
                for i in range(1, body.skel.getNumJoints()):
                    joint = body.skel.getJoint(i)
                    if joint.getNumDofs() > 0:
                        joint.setLimitEnforcement(True)
            self.bodies[spec.name] = body
        self._dart = dart
        self.grasp = self._make_grasp(grasp) if grasp is not None else None
        self.r_eci = np.zeros(3)
        self.v_eci = np.zeros(3)
        self.q_eci_lvlh = np.array([0.0, 0.0, 0.0, 1.0])
        self.w_lvlh = np.zeros(3)
        self.elapsed = 0.0          # s since the orbit inputs were sampled (the reference point moved on)
        self._env_now = False
        self._reference_cache: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self._compile_kernels()

    def _compile_kernels(self) -> None:
        """Compile the numba kernels a step calls (or load them from numba's on-disk cache), now.

        A cold compile takes seconds (~6 s on one idle core): done inside step 0 it counted against
        ``run.step_timeout``; here, at construction (the component's instantiate), it counts against
        ``run.start_timeout``. The calls pass the argument types the steps pass (the same
        expressions: DART's Jacobians are Fortran-ordered), so no step compiles another signature;
        the machine code is the one a first step would have compiled: the numbers do not change.
        The world's state is untouched: the environment call only fills the per-link scratch arrays
        (``body.force``, ``body.torque``) that every later use fills again first, and the rk4
        kernels get zeros and return new arrays."""
        R, V = np.array([R_EARTH + 400e3, 0.0, 0.0]), np.zeros(3)     # any point off the Earth's centre
        for body in self.bodies.values():
            self._environment(body, R, V, self.tidal, self.drag)
            if self.integrator == "rk4":
                zeros = np.zeros(body.ndofs)
                xi, v, rate = manifold_rk4.stage(0.5, zeros, zeros, zeros)
                xi, v = manifold_rk4.combine(1.0, zeros, rate, rate, rate, rate, zeros, zeros, zeros, zeros)
                manifold_rk4.moved(zeros, xi)

    def _make_grasp(self, spec: GraspSpec) -> Grasp:
        if self.integrator != "rk4":
            raise ModelError("grasp", f"a capture needs integrator rk4 (its weld is solved at every stage), "
                                      f"got {self.integrator!r}")
        for key, body_name, link in (("chaser", spec.chaser, spec.end_effector),
                                     ("target", spec.target, spec.grasp_frame)):
            body = self.bodies.get(body_name)
            if body is None:
                raise ModelError(f"grasp.{key}", f"no body {body_name!r} (bodies: {', '.join(self.bodies)})")
            if link not in body.link_names:
                what = "end_effector" if key == "chaser" else "grasp_frame"
                raise ModelError(f"grasp.{what}", f"{link!r} is not a link of {body_name} "
                                                  f"(links: {', '.join(body.link_names)})")
        if spec.chaser == spec.target:
            raise ModelError("grasp.target", "the chaser cannot grasp itself")
        return Grasp(spec, self.bodies[spec.chaser], self.bodies[spec.target], self._dart.dynamics.Frame.World())

    def capture(self) -> CaptureReport | None:
        """Close the grasp if it is open and E is within the tolerances of G: the impact (see
        :mod:`components.dynamics.capture`); None when it does not close."""
        if self.grasp is None or self.grasp.closed or not self.grasp.within_tolerance():
            return None
        return self.grasp.close()

    # ----------------------------------------------------------------- inputs

    def set_orbit(self, r_eci, v_eci, q_eci_lvlh=(0.0, 0.0, 0.0, 1.0), w_lvlh=(0.0, 0.0, 0.0), age: float = 0.0) -> None:
        """Reference orbit point (m, m/s, ECI), LVLH attitude q_ECI_LVLH and rate (rad/s, ECI axes),
        sampled ``age`` seconds before the current time (negative: after it, as a Gauss-Seidel run
        gives the next step's): the reference point is propagated from its own time."""
        values = (r_eci, v_eci, q_eci_lvlh, w_lvlh)
        orbit = np.concatenate(values, axis=None, dtype=float)
        if orbit.size != 13 or not np.isfinite(orbit).all():
            for signal, value in zip(orbit_signals("input"), values):
                value = np.asarray(value, dtype=float)
                if value.size != signal.size or not np.isfinite(value).all():
                    raise ValueError(f"input {signal.name}: expected {signal.size} finite values, got {value.tolist()}")
        self.r_eci, self.v_eci, self.q_eci_lvlh, self.w_lvlh = orbit[0:3], orbit[3:6], orbit[6:10], orbit[10:13]
        self.elapsed = float(age)
        self._reference_cache = {}

    def set_torques(self, name: str, tau) -> None:
        """Joint torques/forces (N m or N) of body ``name`` in URDF joint order; clipped to the
        URDF effort limits; ignored on locked joints."""
        body = self.bodies[name]
        tau = np.asarray(tau, dtype=float).ravel()
        if tau.size != len(body.joints):
            raise ValueError(f"input {name}.tau: expected {len(body.joints)} values, got {tau.size}")
        if not np.isfinite(tau).all():
            k = int(np.argmax(~np.isfinite(tau)))
            raise ValueError(f"input {name}.tau: expected finite values, got {tau[k]} for {body.joints[k]}")
        body.tau[:] = 0.0
        body.tau[body.free_dofs] = np.minimum(np.maximum(tau, body.negative_effort), body.effort)[body.free]

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
                v = R_WL @ v + np.cross(self.w_lvlh, p)
            self._set_base(body, p, R, v, w, spec.q, spec.qd)

    def set_body_state(self, name: str, p_W_base, q_W_base, twist_W, q=None, qd=None) -> None:
        """Set a body's base pose and twist (W) and its joint positions/rates (URDF order)."""
        body = self.bodies[name]
        q = {} if q is None else dict(zip(body.joints, np.asarray(q, dtype=float)))
        qd = {} if qd is None else dict(zip(body.joints, np.asarray(qd, dtype=float)))
        twist = np.asarray(twist_W, dtype=float)
        self._set_base(body, np.asarray(p_W_base, dtype=float), quat_to_matrix(q_W_base), twist[:3], twist[3:], q, qd)

    def _set_base(self, body: _Body, p, R, v, w, q: Mapping, qd: Mapping) -> None:
        T = self._dart.math.Isometry3()
        T.set_rotation(R)
        T.set_translation(p)
        positions = np.zeros(body.ndofs)
        velocities = np.zeros(body.ndofs)
        positions[:6] = self._dart.dynamics.FreeJoint.convertToPositions(T)
        velocities[:3], velocities[3:6] = w, v
        for j, k in zip(body.joints, body.dof_index):
            if k >= 0:
                positions[k] = q.get(j, 0.0)
                velocities[k] = qd.get(j, 0.0)
        for k, f, multiplier, offset in body.mimic:          # where the constraint puts them
            positions[k] = multiplier * positions[f] + offset
            velocities[k] = multiplier * velocities[f]
        body.skel.setPositions(positions)
        body.skel.setVelocities(velocities)

    # ----------------------------------------------------------------- environment

    @property
    def environment_on(self) -> bool:
        return (self.tidal or self.gg or self.drag) and bool(np.any(self.r_eci != 0.0))

    def reference(self, s: float) -> tuple[np.ndarray, np.ndarray]:
        """Reference point (r_eci, v_eci) s seconds after the orbit inputs were set."""
        cached = self._reference_cache.get(s)
        if cached is None:
            if len(self._reference_cache) > 8:
                self._reference_cache.clear()
            cached = self._reference_cache[s] = env.propagate_reference(self.r_eci, self.v_eci, s, self.mu)
        return cached

    def _environment(self, body: _Body, R: np.ndarray, V: np.ndarray, tidal: bool, drag: bool):
        """The body's generalized forces, its joint torques and the environment with the reference
        point at (R, V) (``link_forces.generalized_forces``, which also fills ``body.force`` and
        ``body.torque``), and the anchors' Jacobians side by side."""
        J = np.concatenate([anchor.getJacobian(ORIGIN) for anchor in body.anchors], axis=1)
        drag = drag and body.has_drag
        v_com = np.array([bn.getCOMLinearVelocity() for bn in body.nodes]).reshape(-1, 3) if drag else body.force
        atmosphere = self.atmosphere
        forces = link_forces.generalized_forces(
            J, body.base_rotation_columns, body.jacobian_anchor, body.jacobian_dofs, body.anchor_slot,
            body.com_in_anchor, body.inertia_in_anchor, body.mass, R, V, body.skel.getPositions()[3:6], self.mu,
            tidal, self.gg, drag, body.drag_k, v_com, atmosphere.h0, atmosphere.rho0, atmosphere.scale,
            EARTH_RATE, R_EARTH, body.tau, body.force, body.torque)
        return forces, J

    def link_wrenches(self, body: _Body, R: np.ndarray, V: np.ndarray):
        """Environment on each massive link at the skeleton's current state, with the reference
        point at (R, V): (tidal force, drag force, gravity-gradient torque), each (n_nodes, 3), N
        and N m, W axes, about the CoM."""
        R, V = np.asarray(R, dtype=float), np.asarray(V, dtype=float)
        _, J = self._environment(body, R, V, self.tidal, False)
        tidal, torque = body.force.copy(), body.torque.copy()
        drag = np.zeros_like(tidal)
        if self.drag and body.has_drag:
            self._environment(body, R, V, False, True)
            drag = body.force.copy()
        # R_a^T: the angular rows of each anchor's base rotation columns
        rotation_T = J[:3].take(body.base_rotation_columns, axis=1).transpose(1, 0, 2).take(body.anchor_slot, axis=0)
        return tuple(np.einsum("nji,nj->ni", rotation_T, local) for local in (tidal, drag, torque))

    def _apply_environment(self, body: _Body, s: float) -> None:
        """Sets the body's generalized forces: its joint torques and the environment."""
        R, V = self.reference(s)
        forces, _ = self._environment(body, R, V, self.tidal, self.drag)
        body.skel.setForces(forces)

    # ----------------------------------------------------------------- integration

    def _acceleration(self, body: _Body, s: float) -> np.ndarray:
        """Accelerations (DART order) at the skeleton's current state, torques and environment."""
        skel = body.skel
        if self._env_now:
            self._apply_environment(body, s)
        skel.computeForwardDynamics()
        a = skel.getAccelerations()
        if body.mimic:
            a = self._hold_mimic(body, a)
        if body.stops.size:
            a = self._hold_stops(body, a)
        return a

    @staticmethod
    def _hold_mimic(body: _Body, a: np.ndarray) -> np.ndarray:
        """Accelerations that keep the mimic constraints (J a = 0; J is constant, so J qd stays 0
        too): the joint-space constraint force M^-1 J^T lambda, internal to the body."""
        Minv = body.inverse_mass()
        J = body.mimic_J
        MJ = Minv @ J.T
        return a - MJ @ np.linalg.solve(J @ MJ, J @ a)

    @staticmethod
    def _set_stage(skel, q0, xi, v) -> None:
        skel.setPositions(manifold_rk4.moved(q0, xi))
        skel.setVelocities(v)

    @staticmethod
    def _hold_stops(body: _Body, a: np.ndarray) -> np.ndarray:
        """Joints resting on a limit stop: a joint-space constraint torque (internal, momentum-
        free) cancels their outward acceleration; a stop that would have to pull lets go."""
        Minv = body.inverse_mass()
        dofs, sides = body.stops, body.stop_sides
        keep = np.ones(dofs.size, dtype=bool)
        for _ in range(dofs.size):
            S = dofs[keep]
            if S.size == 0:
                return a
            torque = np.linalg.solve(Minv[np.ix_(S, S)], -a[S])
            pulling = sides[keep] * torque > 0.0
            if not np.any(pulling):
                return a + Minv[:, S] @ torque
            keep[np.flatnonzero(keep)[pulling]] = False
        return a

    def _rk4(self, body: _Body, h: float, s: float) -> None:
        skel = body.skel
        q0, v0 = skel.getPositions(), skel.getVelocities()
        if not self._env_now:
            skel.setForces(body.tau)               # forward dynamics leaves them: set once for all stages
        a1 = self._acceleration(body, s)           # at (q0, v0), the current state
        d1 = v0
        xi2, v2, d2 = manifold_rk4.stage(0.5 * h, v0, d1, a1)
        self._set_stage(skel, q0, xi2, v2)
        a2 = self._acceleration(body, s + 0.5 * h)
        xi3, v3, d3 = manifold_rk4.stage(0.5 * h, v0, d2, a2)
        self._set_stage(skel, q0, xi3, v3)
        a3 = self._acceleration(body, s + 0.5 * h)
        xi4, v4, d4 = manifold_rk4.stage(h, v0, d3, a3)
        self._set_stage(skel, q0, xi4, v4)
        a4 = self._acceleration(body, s + h)
        xi, v = manifold_rk4.combine(h, v0, d1, d2, d3, d4, a1, a2, a3, a4)
        self._set_stage(skel, q0, xi, v)
        if self.joint_limits and body.limited:
            self._joint_stops(body)

    def _rk4_welded(self, h: float, s: float) -> None:
        """One RK4 step of every body, stage by stage, with the grasp's weld wrench in each stage's
        accelerations (the welded pair is one assembly; the others step as in ``_rk4``)."""
        grasp = self.grasp
        bodies = list(self.bodies.values())
        chaser, target = grasp.ee.body, grasp.grasp.body
        start = {b.name: (b.skel.getPositions(), b.skel.getVelocities()) for b in bodies}
        if not self._env_now:
            for body in bodies:
                body.skel.setForces(body.tau)

        def accelerations(t: float) -> dict:
            a = {b.name: self._acceleration(b, t) for b in bodies}
            a[chaser.name], a[target.name] = grasp.constrain(a[chaser.name], a[target.name], h)
            return a

        a1 = accelerations(s)
        d1 = {b.name: start[b.name][1] for b in bodies}
        stages = [(a1, d1)]
        for c, t in ((0.5 * h, s + 0.5 * h), (0.5 * h, s + 0.5 * h), (h, s + h)):
            a_prev, d_prev = stages[-1]
            d = {}
            for b in bodies:
                q0, v0 = start[b.name]
                xi, v, d[b.name] = manifold_rk4.stage(c, v0, d_prev[b.name], a_prev[b.name])
                self._set_stage(b.skel, q0, xi, v)
            stages.append((accelerations(t), d))
        for b in bodies:
            q0, v0 = start[b.name]
            (a1, d1), (a2, d2), (a3, d3), (a4, d4) = [(a[b.name], d[b.name]) for a, d in stages]
            xi, v = manifold_rk4.combine(h, v0, d1, d2, d3, d4, a1, a2, a3, a4)
            self._set_stage(b.skel, q0, xi, v)
        stopped = False
        if self.joint_limits:
            for b in bodies:
                if b.limited:
                    self._joint_stops(b)
                    stopped = stopped or b.stops.size > 0
        if stopped:
            grasp.project()   # a stop's impulse moved one side of the weld: the other follows, momentum kept

    def accelerations(self) -> dict[str, np.ndarray]:
        """Every body's accelerations (DART order) at the current state, torques, environment, limit
        stops and, when closed, the grasp's weld (whose wrench it leaves in ``grasp.wrench``)."""
        env_now = self._env_now
        self._env_now = self.environment_on
        try:
            for body in self.bodies.values():
                if not self._env_now:
                    body.skel.setForces(body.tau)
            a = {name: self._acceleration(body, self.elapsed) for name, body in self.bodies.items()}
            if self.grasp is not None and self.grasp.closed:
                c, t = self.grasp.spec.chaser, self.grasp.spec.target
                a[c], a[t] = self.grasp.constrain(a[c], a[t], 1.0)
        finally:
            self._env_now = env_now
        return a

    @staticmethod
    def _joint_stops(body: _Body) -> None:
        """Inelastic joint stops, for rk4. A joint found past a limit has its outward rate
        cancelled by a joint-space impulse and rests on the stop (``_hold_stops``) until its
        acceleration points back inside. Joint impulses and torques are internal: the body's
        momentum is unchanged. The joint stays past the limit by at most one step's travel
        (positions are not projected, which would change the momentum)."""
        skel = body.skel
        q = skel.getPositions()
        over, under = q >= body.upper, q <= body.lower
        stops = np.flatnonzero(over | under)
        body.stops, body.stop_sides = stops, np.where(over[stops], 1.0, -1.0)
        if stops.size == 0:
            return
        v = skel.getVelocities()
        outward = stops[body.stop_sides * v[stops] > 0.0]
        if outward.size:
            Minv = body.inverse_mass()
            impulse = np.linalg.solve(Minv[np.ix_(outward, outward)], -v[outward])
            skel.setVelocities(v + Minv[:, outward] @ impulse)

    def step(self, h: float) -> None:
        """Advance every body by h seconds (``substeps`` internal steps), inputs held."""
        if not (h > 0.0 and math.isfinite(h)):
            raise ValueError(f"step: expected a positive duration, got {h} s")
        dt = h / self.substeps
        self._env_now = self.environment_on
        for k in range(self.substeps):
            s = self.elapsed + k * dt
            if self.integrator == "rk4" and self.grasp is not None and self.grasp.closed:
                self._rk4_welded(dt, s)
            elif self.integrator == "rk4":
                for body in self.bodies.values():
                    self._rk4(body, dt, s)
            else:
                for body in self.bodies.values():
                    if self._env_now:
                        self._apply_environment(body, s)
                    else:
                        body.skel.setForces(body.tau)
                self.world.setTimeStep(dt)
                self.world.step()
        self.elapsed += h

    def forward_dynamics(self, name: str) -> dict[str, np.ndarray]:
        """Accelerations of body ``name`` at its current state, torques and environment (no
        contacts, no joint stops): ``dv_W_base`` (6: classical linear acceleration of the base
        origin m/s^2, then angular acceleration rad/s^2, W axes) and ``qdd`` (URDF joint order)."""
        body = self.bodies[name]
        skel = body.skel
        if self.environment_on:
            self._apply_environment(body, self.elapsed)
        else:
            skel.setForces(body.tau)
        skel.computeForwardDynamics()
        a = np.array(skel.getAccelerations())
        if body.mimic:
            a = self._hold_mimic(body, a)
        qdd = np.zeros(len(body.joints))
        qdd[body.free] = a[body.free_dofs]
        return {"dv_W_base": np.concatenate([a[3:6], a[:3]]), "qdd": qdd}

    # ----------------------------------------------------------------- outputs

    def momentum(self, name: str) -> np.ndarray:
        """(linear kg m/s, angular kg m^2/s about the body's CoM), W axes."""
        body = self.bodies[name]
        skel = body.skel
        return self._momentum(skel, skel.getVelocities(), skel.getCOM(), body.root.getTransform().translation())

    @staticmethod
    def _momentum(skel, velocities: np.ndarray, com: np.ndarray, base_position: np.ndarray) -> np.ndarray:
        """The base rows of M(q) v are the momentum conjugate to DART's FreeJoint velocity
        (omega_W, v_W): total angular momentum about the base origin p, then linear momentum L;
        about the CoM c: H_c = H_p - (c - p) x L. (DART builds M in C++ faster than the link
        sum could gather each link's pose and velocity through Python.)"""
        h = skel.getMassMatrix()[:6] @ velocities
        linear = h[3:6]
        return np.concatenate([linear, h[:3] - cross3(com - base_position, linear)])

    def outputs(self, name: str, links: bool = True) -> dict[str, np.ndarray]:
        """Every output of body ``name`` at the current state (see the component's table);
        ``links=False`` leaves out the per-link ones (poses and environment wrenches)."""
        body = self.bodies[name]
        skel = body.skel
        root = body.root.getTransform()
        position = root.translation()
        velocities = skel.getVelocities()
        com = skel.getCOM()
        out = {
            "position": position,
            "orientation": matrix_to_quat(root.rotation()),
            "twist": np.concatenate([velocities[3:6], velocities[:3]]),
            "q": body.joint_positions(skel.getPositions()),
            "qd": body.joint_velocities(velocities),
            "com": com,
            "momentum": self._momentum(skel, velocities, com, position),
        }
        if links:
            out.update(self.link_outputs(name))
        return out

    def link_outputs(self, name: str) -> dict[str, np.ndarray]:
        """Per URDF link (file order), W axes: environment wrenches at the current state
        (``gg_torque``, ``tidal_force``, ``drag_force``) and ``link_position``, ``link_orientation``."""
        body = self.bodies[name]
        n_links = len(body.link_names)
        T = np.array([bn.getTransform().matrix() for bn, _, _ in body.link_source])
        for i, (_, _, offset) in enumerate(body.link_source):
            if offset is not None:
                T[i] = T[i] @ offset
        gg = np.zeros((n_links, 3))
        tidal = np.zeros((n_links, 3))
        drag = np.zeros((n_links, 3))
        if self.environment_on:
            R, V = self.reference(self.elapsed)
            f_tidal, f_drag, t_gg = self.link_wrenches(body, R, V)
            links, slots = body.massive_links, body.massive_slots
            tidal[links], drag[links], gg[links] = f_tidal[slots], f_drag[slots], t_gg[slots]
        return {
            "gg_torque": gg.ravel(),
            "tidal_force": tidal.ravel(),
            "drag_force": drag.ravel(),
            "link_position": T[:, :3, 3].ravel(),
            "link_orientation": matrix_to_quat(T[:, :3, :3]).ravel(),
        }

    def lvlh(self) -> tuple[np.ndarray, np.ndarray]:
        """R_W_LVLH and LVLH's angular velocity (rad/s, W axes) now, from the reference point as
        propagated to the current time (the orbit inputs may be a step old)."""
        R, V = self.reference(self.elapsed)
        h = np.cross(R, V)
        x, z = R / np.linalg.norm(R), h / np.linalg.norm(h)
        return np.column_stack([x, np.cross(z, x), z]), h / np.dot(R, R)

    def frame_outputs(self, name: str) -> dict[str, np.ndarray]:
        """The body's CoM frame (origin at the CoM, base axes: the paper's F_c / F_t) relative to
        LVLH: ``p_lvlh_com`` (m), ``q_lvlh_body``, ``v_lvlh_com`` (m/s, the rate seen in LVLH),
        ``w_lvlh_body`` (rad/s), LVLH axes. Without an orbit (r_eci = 0) LVLH is W."""
        body = self.bodies[name]
        skel = body.skel
        c, v_c = skel.getCOM(), skel.getCOMLinearVelocity()
        R_base = body.root.getTransform().rotation()
        w = skel.getVelocities()[:3]
        R_WL, w_L = self.lvlh() if np.any(self.r_eci != 0.0) else (np.eye(3), np.zeros(3))
        return {"p_lvlh_com": R_WL.T @ c, "q_lvlh_body": matrix_to_quat(R_WL.T @ R_base),
                "v_lvlh_com": R_WL.T @ (v_c - np.cross(w_L, c)), "w_lvlh_body": R_WL.T @ (w - w_L)}

    def relative_frames(self, chaser: str, target: str) -> dict[str, np.ndarray]:
        """Target's CoM frame F_t relative to the chaser's F_c, in F_c axes: ``p_c_t`` (m),
        ``q_c_t`` (q_Fc_Ft), ``v_c_t`` (m/s, the rate of p_c_t seen in F_c), ``w_c_t`` (rad/s)."""
        c, t = self.bodies[chaser], self.bodies[target]
        R_c, R_t = c.root.getTransform().rotation(), t.root.getTransform().rotation()
        w_c, w_t = c.skel.getVelocities()[:3], t.skel.getVelocities()[:3]
        d = t.skel.getCOM() - c.skel.getCOM()
        v = t.skel.getCOMLinearVelocity() - c.skel.getCOMLinearVelocity() - np.cross(w_c, d)
        return {"p_c_t": R_c.T @ d, "q_c_t": matrix_to_quat(R_c.T @ R_t), "v_c_t": R_c.T @ v,
                "w_c_t": R_c.T @ (w_t - w_c)}

    def imu_outputs(self, name: str, accelerations: np.ndarray) -> dict[str, np.ndarray]:
        """An IMU at the base origin: ``imu_rate`` (rad/s) and ``specific_force`` (m/s^2: the
        origin's acceleration minus the gravity the world applies there, i.e. the tidal
        acceleration when tidal_force is on), base axes. ``accelerations``: DART order, from
        ``accelerations()``."""
        body = self.bodies[name]
        T = body.root.getTransform()
        R_base, p = T.rotation(), T.translation()
        a = np.array(accelerations[3:6], dtype=float)     # classical acceleration of the base origin, W
        if self.tidal and self.environment_on:
            R, _ = self.reference(self.elapsed)
            a = a - env.tidal_acceleration(R, p[None, :], self.mu)[0]
        return {"imu_rate": R_base.T @ body.skel.getVelocities()[:3], "specific_force": R_base.T @ a}

    # ----------------------------------------------------------------- state

    def get_state(self) -> dict[str, np.ndarray]:
        """Everything needed to continue bit-exactly: per body positions/velocities (DART order),
        torques and the joints resting on a limit stop (rk4) with their side, the orbit inputs
        and the time since they were set."""
        orbit = (self.r_eci, self.v_eci, self.q_eci_lvlh, self.w_lvlh)
        state = {**{key: value.copy() for key, value in zip(ORBIT, orbit)}, "elapsed": np.float64(self.elapsed)}
        for name, body in self.bodies.items():
            state[f"{name}.positions"] = np.array(body.skel.getPositions())
            state[f"{name}.velocities"] = np.array(body.skel.getVelocities())
            state[f"{name}.tau"] = body.tau.copy()
            state[f"{name}.stops"] = body.stops.astype(np.int64)
            state[f"{name}.stop_sides"] = body.stop_sides.astype(np.float64)
        if self.grasp is not None:
            state.update(self.grasp.get_state())
        return state

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        for key in ORBIT + ("elapsed",):
            if key not in state:
                raise ValueError(f"state: missing {key!r}")
        for name, body in self.bodies.items():
            for key in ("positions", "velocities", "tau"):
                value = state.get(f"{name}.{key}")
                if value is None or np.asarray(value).shape != (body.ndofs,):
                    raise ValueError(f"state: {name}.{key} expected {body.ndofs} values, "
                                     f"got {None if value is None else np.asarray(value).shape}")
            stops, sides = state.get(f"{name}.stops"), state.get(f"{name}.stop_sides")
            if stops is None or sides is None or np.shape(stops) != np.shape(sides) or np.ndim(stops) != 1 \
                    or not np.all((0 <= np.asarray(stops)) & (np.asarray(stops) < body.ndofs)):
                raise ValueError(f"state: {name}.stops and {name}.stop_sides expected two equal lists of "
                                 f"dof indices (< {body.ndofs}) and sides, got {stops!r}, {sides!r}")
        self.r_eci, self.v_eci, self.q_eci_lvlh, self.w_lvlh = (np.array(state[key], dtype=float) for key in ORBIT)
        self.elapsed = float(state["elapsed"])
        self._reference_cache = {}
        for name, body in self.bodies.items():
            body.skel.setPositions(np.array(state[f"{name}.positions"], dtype=float))
            body.skel.setVelocities(np.array(state[f"{name}.velocities"], dtype=float))
            body.tau[:] = np.array(state[f"{name}.tau"], dtype=float)
            body.stops = np.array(state[f"{name}.stops"], dtype=int)
            body.stop_sides = np.array(state[f"{name}.stop_sides"], dtype=float)
        if self.grasp is not None:
            self.grasp.set_state(state)
