"""Free-floating multibodies in orbit, in the free-falling world frame W, on either engine.

``OrbitalWorld`` is the physics of the ``dynamics.dart`` and ``dynamics.pinocchio`` components as
a plain class (no bus, no I/O): several bodies, each a URDF on a free-floating base, in zero
gravity with the orbital environment of :mod:`components.dynamics.environment` (tidal force,
gravity-gradient torque, drag, the Sun's and the Moon's tidal force) and solar radiation pressure
(:mod:`components.space.srp`; the Sun and Moon from ``set_sun``, held over a step) computed per
link from the reference orbit inputs at every integrator stage (:mod:`components.dynamics.link_forces`). The engine (``engine``: ``dart``,
``pinocchio``) computes each body's forward dynamics, mass matrix and kinematics
(:mod:`components.dynamics.dart_body`, :mod:`components.dynamics.pinocchio_body`) in the one set
of coordinates this world integrates (:mod:`components.dynamics.bodies`); everything else (the
integrator, joint stops, mimic joints, the grasp, the outputs, the state) is here, once.

Frames: W has its origin at the reference orbit point r_eci(t), axes parallel to ECI, and falls
freely (it does not rotate). LVLH (Hill): x radial, z orbit normal, y = z x x. Quaternions are
[x, y, z, w]; q_A_B rotates vectors in B into A.

Integrators (``integrator``):

- ``rk4`` (default): classical Runge-Kutta 4 on the configuration manifold (Runge-Kutta-Munthe-
  Kaas, :mod:`components.dynamics.integration`): stages evaluate the forward dynamics at
  q0 (+) xi (for the base: R = exp(xi_w) R0, p = p0 + xi_v with world-frame rates) with an SO(3)
  exponential exact at every angle; the stage derivative of xi maps the angular velocity through
  the inverse left Jacobian of SO(3). Fourth order; momentum drifts ~1e-10 (relative) over 10 s
  at 1 ms. Contacts are not handled; joint position limits act as inelastic stops (a
  momentum-conserving joint impulse).
- ``dart`` (engine dart only): DART's native ``World.step`` (semi-implicit Euler + constraint
  solver): contacts between bodies, joint limits as constraints. First order (momentum drift
  ~1e-3 over 10 s at 1 ms): use it when bodies touch.

Each communication step ``step(h)`` runs ``substeps`` internal steps of h / substeps. Within a
step the orbit inputs are held, but the reference point moves along its Kepler arc
(:func:`link_forces.propagate_reference`) from the time the inputs were sampled (``set_orbit``'s
``age``), so neither a long step, a slower orbit component nor Gauss-Seidel's one-step lead
shifts the tidal field in time.

Per body (see ``BodySpec``): the base pose and twist and the joint positions/rates at
``reset_bodies``, in W or in LVLH (``frame: lvlh``: relative to LVLH, including its rotation:
a zero twist co-rotates with LVLH). ``locked_joints`` are welded at their initial position.
Joint torques are clipped to the URDF effort limits. URDF joint damping/friction is ignored.

Mimic joints (URDF ``<mimic>``: q = multiplier q_followed + offset) are a holonomic constraint.
``rk4``: each stage's accelerations are projected onto it with a joint-space constraint force
(internal, so momentum is kept), and ``reset_bodies`` puts the mimic joint where the constraint
says. ``dart``: DART's own mimic constraint. The mimic joint's q, qd are outputs like any joint's;
a torque on it acts through the constraint.

The state (``get_state``) has one form for both engines: a world continues bit-exactly from its
own engine's state and, to the engines' rounding, from the other's.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from components.constants import MU_EARTH
from components.dynamics import environment as env
from components.dynamics import integration, link_forces
from components.dynamics.bodies import THIRD_BODIES, Body, BodySpec, Environment, ModelError, check_spec
from components.dynamics.capture import CaptureReport, Grasp, GraspSpec
from components.robots.urdf import UrdfModel, read_urdf
from components.rotations import cross3, matrix_to_quat, quat_to_matrix
from components.signals import ORBIT, orbit_signals
from components.space.eclipse import MODELS as ECLIPSE_MODELS
from components.space.srp import SOLAR_FLUX

INTEGRATORS = ("rk4", "dart")
ENGINES = ("dart", "pinocchio")
BODY_STATE = {"position": 3, "rotation_vector": 3, "twist": 6}  # + q, qd, tau, stop_side: one per joint


class OrbitalWorld:
    """Free-floating URDF bodies in the free-falling frame W, with the orbital environment.

    | constructor argument | default | meaning |
    |---|---|---|
    | bodies | - | list of BodySpec (unique names) |
    | engine | dart | dart or pinocchio: who computes the bodies' dynamics |
    | integrator | rk4 | rk4 (manifold RK4 on the engine's forward dynamics) or dart (DART step, contacts; engine dart) |
    | substeps | 1 | internal steps per ``step(h)`` |
    | tidal_force, gravity_gradient, drag | True, True, False | environment terms, per link |
    | mu | 3.986004418e14 m^3/s^2 | Earth's gravitational parameter |
    | atmosphere | None | ExponentialAtmosphere; None = the 0-1000 km table; a LocalExponential (NRLMSISE-00) is updated every step |
    | joint_limits | True | enforce URDF position limits |
    | srp | False | solar radiation pressure per link (components/space/srp.py; the Sun: ``set_sun``) |
    | eclipse | conical | none, cylindrical (the Earth's), conical (Earth and Moon): SRP's and the sun sensor's shadow |
    | solar_flux | 1361 W/m^2 | the solar flux at 1 AU |
    | third_bodies | () | of sun, moon: their tidal force per link, a_3(R + d) - a_3(R) (the positions: ``set_sun``) |

    Use: ``set_orbit(r_eci, v_eci, q_eci_lvlh, w_lvlh)`` then ``reset_bodies()`` (initial state,
    which needs LVLH for ``frame: lvlh`` bodies); per step ``set_orbit(...)``,
    ``set_torques(name, tau)``, ``step(h)``, ``outputs(name)``. ``get_state``/``set_state`` carry
    everything a restart needs to continue bit-exactly.

    r_eci = 0 means "no orbit": the environment forces are then zero (deep space).
    """

    def __init__(
        self,
        bodies: list[BodySpec],
        *,
        integrator: str = "rk4",
        substeps: int = 1,
        tidal_force: bool = True,
        gravity_gradient: bool = True,
        drag: bool = False,
        mu: float = MU_EARTH,
        atmosphere: env.ExponentialAtmosphere | None = None,
        joint_limits: bool = True,
        models: Mapping[str, UrdfModel] | None = None,
        grasp: GraspSpec | None = None,
        engine: str = "dart",
        compile_kernels: bool = True,
        srp: bool = False,
        eclipse: str = "conical",
        solar_flux: float = SOLAR_FLUX,
        third_bodies: tuple[str, ...] = (),
    ):
        if engine not in ENGINES:
            raise ValueError(f"engine: expected one of {', '.join(ENGINES)}, got {engine!r}")
        integrators = INTEGRATORS if engine == "dart" else ("rk4",)  # contacts: DART's own step only
        if integrator not in integrators:
            raise ValueError(
                f"integrator: expected one of {', '.join(integrators)} with engine {engine}, got {integrator!r}"
            )
        if not (isinstance(substeps, int) and substeps >= 1):
            raise ValueError(f"substeps: expected an integer >= 1, got {substeps!r}")
        self.engine, self.integrator, self.substeps = engine, integrator, substeps
        self.tidal, self.gg, self.drag = bool(tidal_force), bool(gravity_gradient), bool(drag)
        self.mu = float(mu)
        self.atmosphere = atmosphere or env.ExponentialAtmosphere()
        if eclipse not in ECLIPSE_MODELS:
            raise ValueError(f"eclipse: expected one of {', '.join(ECLIPSE_MODELS)}, got {eclipse!r}")
        self.srp = bool(srp)
        unknown = [b for b in third_bodies if b not in THIRD_BODIES]
        if unknown or len(set(third_bodies)) < len(third_bodies):
            raise ValueError(
                f"third_bodies: expected distinct names of {', '.join(THIRD_BODIES)}, got {list(third_bodies)}"
            )
        self.third_bodies = tuple(third_bodies)
        self.environment = Environment(
            self.mu,
            self.tidal,
            self.gg,
            self.drag,
            self.atmosphere,
            self.srp,
            eclipse,
            float(solar_flux),
            self.third_bodies,
        )
        self.atmosphere_varies = self.drag and getattr(self.atmosphere, "varies", False)
        self.orbit_time = 0.0  # run time (s since run.epoch) at which the orbit inputs were sampled
        self.sun_eci, self.moon_eci = None, None  # set_sun
        self.joint_limits = bool(joint_limits)
        self.dart_world = None
        if engine == "dart":
            import dartpy as dart

            self.dart_world = dart.simulation.World()
            self.dart_world.setGravity(np.zeros(3))
        self.bodies: dict[str, Body] = {}
        for spec in bodies:
            if spec.name in self.bodies:
                raise ModelError(spec.name, "duplicate body name")
            model = (models or {}).get(spec.name) or read_urdf(spec.urdf)
            check_spec(spec, model)
            self.bodies[spec.name] = self._body(spec, model)
        self.grasp = self._make_grasp(grasp) if grasp is not None else None
        self.r_eci = np.zeros(3)
        self.v_eci = np.zeros(3)
        self.q_eci_lvlh = np.array([0.0, 0.0, 0.0, 1.0])
        self.w_lvlh = np.zeros(3)
        self.elapsed = 0.0  # s since the orbit inputs were sampled (the reference point moved on)
        self.env_now = False  # the environment applies in this step
        self._orbit_changed()  # environment_on: the environment applies (r_eci = 0: no orbit, none)
        if compile_kernels:  # not for a check of the models (orchestrator check stays quick)
            integration.compile_kernels(self)

    def overlaps(self) -> list[tuple[str, str, str, str, float]]:
        """Pairs of bodies whose collision geometry overlaps in their initial poses (DART engine;
        Bullet's narrow phase): (body, link, other body, its link, penetration depth m), the
        deepest contact of each pair. rk4 has no contacts: such bodies pass through each other.
        The skeletons are posed by DART's own conversions (no kernel compiles for a check)."""
        if self.engine != "dart":
            return []
        import dartpy as dart

        R_WL = quat_to_matrix(self.q_eci_lvlh)
        for body in self.bodies.values():
            spec = body.spec
            p, R = np.asarray(spec.position, dtype=float), quat_to_matrix(spec.orientation)
            if spec.frame == "lvlh":
                p, R = R_WL @ p, R_WL @ R
            T = dart.math.Isometry3()
            T.set_rotation(R)
            T.set_translation(p)
            positions = np.zeros(body.ndofs)
            positions[:6] = dart.dynamics.FreeJoint.convertToPositions(T)
            for j, k in zip(body.joints, body.dof_index):
                if k >= 0:
                    positions[k] = spec.q.get(j, 0.0)
            body.set_state(positions, body.velocities())

        detector = dart.collision.BulletCollisionDetector()
        groups = {}
        for name, body in self.bodies.items():
            group = detector.createCollisionGroup()
            for i in range(body.skel.getNumBodyNodes()):
                group.addShapeFramesOf(body.skel.getBodyNode(i))
            groups[name] = group
        names, found = list(groups), []
        option = dart.collision.CollisionOption()
        option.enableContact, option.maxNumContacts = True, 100
        for i, a in enumerate(names):
            for b in names[i + 1 :]:
                result = dart.collision.CollisionResult()
                if not groups[a].collide(groups[b], option, result) or not result.getNumContacts():
                    continue
                deepest = max(
                    (result.getContact(k) for k in range(result.getNumContacts())), key=lambda c: c.penetrationDepth
                )
                found.append(
                    (
                        a,
                        deepest.collisionObject1.getShapeFrame().getBodyNode().getName(),
                        b,
                        deepest.collisionObject2.getShapeFrame().getBodyNode().getName(),
                        float(deepest.penetrationDepth),
                    )
                )
        return found

    def _body(self, spec: BodySpec, model: UrdfModel) -> Body:
        if self.engine == "pinocchio":
            from components.dynamics.pinocchio_body import PinocchioBody

            return PinocchioBody(spec, model, self.environment)
        import dartpy as dart

        from components.dynamics.dart_body import DartBody

        body = DartBody(spec, model, self.environment, dart, self.integrator)
        self.dart_world.addSkeleton(body.skel)
        body.skel.setGravity(np.zeros(3))
        if self.integrator == "dart" and self.joint_limits:
            for i in range(1, body.skel.getNumJoints()):
                joint = body.skel.getJoint(i)
                if joint.getNumDofs() > 0:
                    joint.setLimitEnforcement(True)
        return body

    def _make_grasp(self, spec: GraspSpec) -> Grasp:
        if self.integrator != "rk4":
            raise ModelError(
                "grasp", f"a capture needs integrator rk4 (its weld is solved at every stage), got {self.integrator!r}"
            )
        for key, body_name, link in (
            ("chaser", spec.chaser, spec.end_effector),
            ("target", spec.target, spec.grasp_frame),
        ):
            body = self.bodies.get(body_name)
            if body is None:
                raise ModelError(f"grasp.{key}", f"no body {body_name!r} (bodies: {', '.join(self.bodies)})")
            if link not in body.link_names:
                what = "end_effector" if key == "chaser" else "grasp_frame"
                raise ModelError(
                    f"grasp.{what}", f"{link!r} is not a link of {body_name} (links: {', '.join(body.link_names)})"
                )
        if spec.chaser == spec.target:
            raise ModelError("grasp.target", "the chaser cannot grasp itself")
        return Grasp(spec, self.bodies[spec.chaser], self.bodies[spec.target])

    def capture(self) -> CaptureReport | None:
        """Close the grasp if it is open and E is within the tolerances of G: the impact (see
        :mod:`components.dynamics.capture`); None when it does not close."""
        if self.grasp is None or self.grasp.closed or not self.grasp.armed or not self.grasp.within_tolerance():
            return None
        return self.grasp.close()

    # ----------------------------------------------------------------- inputs

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

    # ----------------------------------------------------------------- environment

    def reference(self, s: float) -> tuple[np.ndarray, np.ndarray]:
        """Reference point (r_eci, v_eci) s seconds after the orbit inputs were set."""
        cached = self._reference_cache.get(s)
        if cached is None:
            if len(self._reference_cache) > 8:
                self._reference_cache.clear()
            cached = self._reference_cache[s] = link_forces.propagate_reference(self.r_eci, self.v_eci, s, self.mu)
        return cached

    def update_atmosphere(self, s: float) -> None:
        """A varying atmosphere (NRLMSISE-00) as the one-band exponential of the reference point s
        seconds after the orbit inputs were sampled (run time ``orbit_time`` + s); ``step`` takes each
        (sub)step's midpoint, and the outputs between steps keep the last step's band."""
        R, _ = self.reference(s)
        self.atmosphere.update(R, self.orbit_time + s)
        for body in self.bodies.values():
            body.atmosphere_changed()

    # ----------------------------------------------------------------- integration

    def step(self, h: float) -> None:
        """Advance every body by h seconds (``substeps`` internal steps), inputs held."""
        if not (h > 0.0 and math.isfinite(h)):
            raise ValueError(f"step: expected a positive duration, got {h} s")
        dt = h / self.substeps
        self.env_now = self.environment_on
        if (self.srp or self.third_bodies) and self.sun_eci is None:
            raise ValueError(
                f"{'srp' if self.srp else 'third_bodies'}: the Sun's and the Moon's positions were not "
                f"set (set_sun) before the step"
            )
        if self.grasp is not None:
            self.grasp.reset_peak()
        for k in range(self.substeps):
            s = self.elapsed + k * dt
            if self.atmosphere_varies and self.env_now:
                self.update_atmosphere(s + 0.5 * dt)
            if self.integrator == "rk4" and self.grasp is not None and self.grasp.closed:
                integration.rk4_welded(self, dt, s)
            elif self.integrator == "rk4":
                for body in self.bodies.values():
                    integration.rk4(self, body, dt, s)
            else:
                for body in self.bodies.values():
                    body.set_forces((self.orbit_point, s) if self.env_now else None)
                self.dart_world.setTimeStep(dt)
                self.dart_world.step()
        self.elapsed += h

    def accelerations(self) -> dict[str, np.ndarray]:
        """Every body's accelerations (coordinates) at the current state, torques, environment,
        limit stops and, when closed, the grasp's weld (whose wrench it leaves in ``grasp.wrench``)."""
        env_now = self.env_now
        self.env_now = self.environment_on
        try:
            a = {name: integration.acceleration(self, body, self.elapsed) for name, body in self.bodies.items()}
            if self.grasp is not None and self.grasp.closed:
                c, t = self.grasp.spec.chaser, self.grasp.spec.target
                a[c], a[t] = self.grasp.constrain(a[c], a[t], 1.0)
        finally:
            self.env_now = env_now
        return a

    def forward_dynamics(self, name: str) -> dict[str, np.ndarray]:
        """Accelerations of body ``name`` at its current state, torques and environment (no
        contacts, no joint stops): ``dv_W_base`` (6: classical linear acceleration of the base
        origin m/s^2, then angular acceleration rad/s^2, W axes) and ``qdd`` (URDF joint order)."""
        body = self.bodies[name]
        a = body.forward_dynamics((self.orbit_point, self.elapsed) if self.environment_on else None)
        if body.mimic:
            a = integration.hold_mimic(body, a)
        qdd = np.zeros(len(body.joints))
        qdd[body.free] = a[body.free_dofs]
        return {"dv_W_base": np.concatenate([a[3:6], a[:3]]), "qdd": qdd}

    # ----------------------------------------------------------------- outputs

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
                    a = a - env.third_body_tidal_acceleration(R, p[None, :], s, THIRD_BODIES[b])[0]
        return {"imu_rate": R_base.T @ body.velocities()[:3], "specific_force": R_base.T @ a}

    # ----------------------------------------------------------------- state

    def get_state(self) -> dict[str, np.ndarray]:
        """Everything needed to continue bit-exactly, in one form for every engine: per body
        ``position`` (m), ``rotation_vector`` (rad: R_W_base = exp of it), ``twist`` (m/s, rad/s:
        the base origin's, W), ``q``, ``qd``, ``tau`` (URDF joint order, locked joints at their
        lock), ``stop_side`` (per joint: +1 resting on its upper stop, -1 on its lower, 0 free);
        the orbit inputs and the time since they were set; the grasp's weld."""
        orbit = (self.r_eci, self.v_eci, self.q_eci_lvlh, self.w_lvlh)
        state = {**{key: value.copy() for key, value in zip(ORBIT, orbit)}, "elapsed": np.float64(self.elapsed)}
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
