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
integrator, joint stops, mimic joints, the grasp, the outputs, the state) is here, once: the
inputs in :mod:`components.dynamics.world_inputs`, the outputs in
:mod:`components.dynamics.world_outputs`, the state in :mod:`components.dynamics.world_state`.

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
from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from components.constants import MU_EARTH
from components.dynamics import environment as env
from components.dynamics import integration
from components.dynamics.bodies import THIRD_BODIES, Body, BodySpec, Environment, ModelError, check_spec
from components.dynamics.capture import CaptureReport, Grasp, GraspSpec
from components.dynamics.world_outputs import WorldOutputs
from components.dynamics.world_state import WorldState
from components.robots.urdf import UrdfModel, read_urdf
from components.space.atmosphere import LocalExponential
from components.space.eclipse import MODELS as ECLIPSE_MODELS
from components.space.srp import SOLAR_FLUX

if TYPE_CHECKING:
    from components.dynamics.dart_body import DartBody

INTEGRATORS = ("rk4", "dart")
ENGINES = ("dart", "pinocchio")


def _check_stepping(engine: str, integrator: str, substeps: int) -> None:
    """ValueError unless the engine, its integrator and the substeps are ones a world takes."""
    if engine not in ENGINES:
        raise ValueError(f"engine: expected one of {', '.join(ENGINES)}, got {engine!r}")
    integrators = INTEGRATORS if engine == "dart" else ("rk4",)  # contacts: DART's own step only
    if integrator not in integrators:
        raise ValueError(
            f"integrator: expected one of {', '.join(integrators)} with engine {engine}, got {integrator!r}"
        )
    if not (isinstance(substeps, int) and substeps >= 1):
        raise ValueError(f"substeps: expected an integer >= 1, got {substeps!r}")


def _check_sky(eclipse: str, third_bodies: tuple[str, ...]) -> None:
    """ValueError unless the eclipse model and the third bodies are known ones (the bodies distinct)."""
    if eclipse not in ECLIPSE_MODELS:
        raise ValueError(f"eclipse: expected one of {', '.join(ECLIPSE_MODELS)}, got {eclipse!r}")
    unknown = [b for b in third_bodies if b not in THIRD_BODIES]
    if unknown or len(set(third_bodies)) < len(third_bodies):
        raise ValueError(
            f"third_bodies: expected distinct names of {', '.join(THIRD_BODIES)}, got {list(third_bodies)}"
        )


class OrbitalWorld(WorldOutputs, WorldState):
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
        _check_stepping(engine, integrator, substeps)
        self.engine, self.integrator, self.substeps = engine, integrator, substeps
        self.tidal, self.gg, self.drag = bool(tidal_force), bool(gravity_gradient), bool(drag)
        self.mu = float(mu)
        self.atmosphere = atmosphere or env.ExponentialAtmosphere()
        _check_sky(eclipse, third_bodies)
        self.srp = bool(srp)
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
        self.dart_world: Any = None  # engine dart: its dartpy World (no stubs)
        self.bodies: dict[str, Body] = {}
        self._make_bodies(bodies, models)
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

    def _make_bodies(self, bodies: list[BodySpec], models: Mapping[str, UrdfModel] | None) -> None:
        """The engine's bodies into ``bodies`` (and, engine dart, its world first)."""
        if self.engine == "dart":
            import dartpy as dart

            self.dart_world = dart.simulation.World()
            self.dart_world.setGravity(np.zeros(3))
        for spec in bodies:
            if spec.name in self.bodies:
                raise ModelError(spec.name, "duplicate body name")
            model = (models or {}).get(spec.name) or read_urdf(spec.urdf)
            check_spec(spec, model)
            self.bodies[spec.name] = self._body(spec, model)

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

    # ----------------------------------------------------------------- environment

    def update_atmosphere(self, s: float) -> None:
        """A varying atmosphere (NRLMSISE-00) as the one-band exponential of the reference point s
        seconds after the orbit inputs were sampled (run time ``orbit_time`` + s); ``step`` takes each
        (sub)step's midpoint, and the outputs between steps keep the last step's band."""
        R, _ = self.reference(s)
        assert isinstance(self.atmosphere, LocalExponential)  # the one atmosphere that varies
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
                for body in cast("Iterable[DartBody]", self.bodies.values()):  # integrator dart: engine dart
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
