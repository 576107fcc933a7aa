"""Free-floating URDF multibodies in orbit: types ``dynamics.dart`` and ``dynamics.pinocchio``
(thin wrappers of :class:`components.dynamics.world.OrbitalWorld`, one per engine).

The two types have the same parameters, inputs, outputs and state; only the engine that computes
the bodies' forward dynamics differs, so a swap from one to the other mid-run hands the state over
(``state_form``). ``dynamics.pinocchio`` has no contact solver: ``integrator: dart`` is refused.

``declare`` reads the URDFs with xml.etree only (joint and link counts); the engine loads at
instantiate. State (``get_state``): the world's (per body base pose and twist, joint positions,
rates, torques and limit stops; orbit inputs; the grasp's weld) and the last output quaternions
(their signs continue).
"""

from __future__ import annotations

from collections.abc import Mapping
from operator import itemgetter
from typing import TYPE_CHECKING, Any

import numpy as np

from components.constants import MU_EARTH, NS_PER_S
from components.dynamics import plots as dynamics_plots
from components.dynamics import ros as dynamics_ros
from components.dynamics.parameters import PARAMETERS
from components.dynamics.specs import body_specs, body_twist, load_models, world_atmosphere
from components.dynamics.variables import dynamics_variables
from components.dynamics.view import DynamicsView
from components.errors import ComponentError, ConfigError
from components.robots.model import body_items
from components.rotations import continuous, opposite
from components.sdk import EPOCH_KEY, Component
from components.signals import BODY as BODY_OUTPUTS
from components.signals import ORBIT as ORBIT_INPUTS
from components.space.ephemeris import moon_position_eci, sun_position_eci
from components.space.parameters import check_atmosphere

if TYPE_CHECKING:
    from components.dynamics.capture import CaptureReport

ORBIT_VALUES = itemgetter(*ORBIT_INPUTS)  # inputs -> the orbit inputs' values, in set_orbit's order

LINK_OUTPUTS = (
    "gg_torque",
    "tidal_force",
    "drag_force",
    "srp_force",
    "srp_torque",
    "link_position",
    "link_orientation",
    "third_body_force",
)
LAST = "last_output."  # state keys of the last output quaternions
MAGNETIC = "magnetic."  # state keys of the magnetic field and magnetorquers (components/dynamics/magnetic.py)

# preflight: the rotation per (sub)step above which a step is too coarse (rk4's error in the
# attitude grows as its fifth power: 60 s at the orbit's rate, 0.07 rad, is right to 1e-6 deg;
# 1 h, 4 rad, ends 174 deg off), and the mean motion of the lowest orbit (at Earth's radius)
MAX_ROTATION_PER_STEP = 0.1
ORBIT_RATE_MAX = float(np.sqrt(MU_EARTH / 6378137.0**3))


def _grasp_spec(grasp: Mapping[str, Any]):
    """The grasp's GraspSpec from its validated parameters."""
    from components.dynamics.capture import GraspSpec, Tolerance

    return GraspSpec(
        chaser=grasp["chaser"],
        end_effector=grasp["end_effector"],
        target=grasp["target"],
        grasp_frame=grasp["grasp_frame"],
        tolerance=Tolerance(**grasp["tolerance"]),
        force_limit=grasp["force_limit"],
        torque_limit=grasp["torque_limit"],
        on_overload=grasp["on_overload"],
    )


class OrbitalDynamics(Component):
    """What both dynamics types share: everything but the engine (``engine``)."""

    engine = ""
    state_form = "dynamics"
    bodies_parameter = "bodies"
    plots = (dynamics_plots.BODIES, dynamics_plots.CAPTURE, dynamics_plots.MAGNETIC)
    view = DynamicsView
    rosbag = dynamics_ros.ROS_EXPORT
    parameters = PARAMETERS

    @classmethod
    def declare(cls, params, run):
        return dynamics_variables(params, run)

    @classmethod
    def validate(cls, params, run):
        models = load_models(params, run)
        body_specs(params, models)
        check_atmosphere(params["atmosphere"], run.epoch)
        for key in ("imu", "sun_sensor"):
            for i, name in enumerate(params[key]):
                if name not in models:
                    raise ConfigError(f"{key}[{i}]", f"expected a body name ({', '.join(models)}), got {name!r}")
        if (params["srp"] or params["sun_sensor"]) and not run.epoch:
            raise ConfigError(EPOCH_KEY, "SRP and a sun sensor need the run's epoch (run.epoch) for the Sun")
        if params["third_bodies"] and not run.epoch:
            raise ConfigError(
                EPOCH_KEY,
                f"third_bodies ({', '.join(params['third_bodies'])}) need the run's epoch "
                f"(run.epoch) for their positions, got none",
            )
        for name in params["magnetorquers"]:
            if name not in models:
                raise ConfigError(f"magnetorquers.{name}", f"expected a body name ({', '.join(models)}), got {name!r}")
            if params["magnetic_field"] is None:
                raise ConfigError(
                    f"magnetorquers.{name}",
                    "magnetorquers act on the Earth's magnetic field: expected "
                    "magnetic_field (model: wmm or dipole), got none",
                )
        grasp = params["grasp"]
        if grasp is not None:
            if params["integrator"] != "rk4":
                raise ConfigError(
                    "grasp",
                    f"a capture needs integrator: rk4 (its weld is solved at every "
                    f"integrator stage), got {params['integrator']!r}",
                )
            for key, link_key in (("chaser", "end_effector"), ("target", "grasp_frame")):
                model = models.get(grasp[key])
                if model is None:
                    raise ConfigError(f"grasp.{key}", f"expected a body name ({', '.join(models)}), got {grasp[key]!r}")
                if grasp[link_key] not in model.link_names:
                    raise ConfigError(
                        f"grasp.{link_key}",
                        f"expected a link of {grasp[key]} ({', '.join(model.link_names)}), got {grasp[link_key]!r}",
                    )
            if grasp["chaser"] == grasp["target"]:
                raise ConfigError("grasp.target", f"expected another body than the chaser, got {grasp['target']!r}")
        return params

    @classmethod
    def preflight(cls, params, run, step_s, full=False):
        """Zero-mass links a joint moves; a step too coarse for the rotation the bodies see (the
        largest of: a body's initial angular rate, its joints' rates, and the orbit's mean motion
        when the body co-rotates with LVLH or the environment is on, taken at the lowest orbit,
        ORBIT_RATE_MAX) against MAX_ROTATION_PER_STEP. ``full``: DART loads every body."""
        models = load_models(params, run)
        notes = [f"bodies.{name}: {note}" for name, model in models.items() for note in model.notes()]
        h = step_s / params["substeps"]
        environment = params["tidal_force"] or params["gravity_gradient"] or params["third_bodies"]
        for name, body in body_items(params["bodies"]):
            model = models[name]
            figures = [
                (float(np.linalg.norm(np.asarray(body_twist(name, body), dtype=float)[3:])), "its initial angular rate")
            ]
            revolute = [abs(float(v)) for j, v in body["qd"].items() if model.joint(j).type != "prismatic"]
            if revolute:
                figures.append((max(revolute), "its fastest joint's initial rate"))
            if body["frame"] == "lvlh" or environment:
                figures.append((ORBIT_RATE_MAX, "the orbit's rate (mean motion at the lowest orbit)"))
            rate, what = max(figures)
            if rate * h > MAX_ROTATION_PER_STEP:
                notes.append(
                    f"bodies.{name}: the step is too coarse for the dynamics: {what}, {rate:.3g} rad/s, turns it "
                    f"{rate * h:.3g} rad ({np.degrees(rate * h):.3g} deg) per step of {h:g} s; above "
                    f"{MAX_ROTATION_PER_STEP:g} rad ({np.degrees(MAX_ROTATION_PER_STEP):.2g} deg) per step the "
                    f"integration is wrong by whole degrees: use a step of at most {MAX_ROTATION_PER_STEP / rate:.3g} s "
                    f"(or substeps)"
                )
        if full:  # the engine loads every body: what it refuses is an error now, not at the start
            from components.dynamics.world_contacts import initial_overlaps

            world = cls(params, run, compile_kernels=False).world  # (the kernels compile at the run's instantiate)
            notes += [
                f"bodies.{name}: {note}"
                for name, body in world.bodies.items()
                for note in getattr(body, "engine_notes", ())
            ]
            notes += [
                f"bodies.{a} and bodies.{b} overlap at the start: {a}'s link {la!r} and {b}'s link {lb!r} "
                f"by {depth * 1e3:.3g} mm (their collision geometry); the rk4 integrator has no contacts: "
                f"they pass through each other"
                for a, la, b, lb, depth in initial_overlaps(world)
            ]
        return notes

    def __init__(self, params, run, *, compile_kernels: bool = True):
        super().__init__(params, run)
        from components.dynamics.world import ModelError, OrbitalWorld

        models = load_models(params, run)
        specs = body_specs(params, models)
        grasp = params["grasp"]
        self.grasp = grasp is not None and _grasp_spec(grasp)
        try:
            self.world = OrbitalWorld(
                specs,
                engine=self.engine,
                integrator=params["integrator"],
                substeps=params["substeps"],
                tidal_force=params["tidal_force"],
                gravity_gradient=params["gravity_gradient"],
                drag=params["drag"],
                mu=params["mu"],
                atmosphere=world_atmosphere(params["atmosphere"], run.epoch),
                joint_limits=params["joint_limits"],
                models=models,
                grasp=self.grasp or None,
                compile_kernels=compile_kernels,
                srp=params["srp"],
                eclipse=params["eclipse"],
                solar_flux=params["solar_flux"],
                third_bodies=tuple(params["third_bodies"]),
            )
        except ModelError as e:
            raise ConfigError(f"bodies.{e.key}", e.message) from None
        self.names = [spec.name for spec in specs]
        self.links = params["link_outputs"]
        self.torque_inputs = [(name, f"{name}.tau") for name in self.names]
        self.output_names = {name: {key: f"{name}.{key}" for key in BODY_OUTPUTS + LINK_OUTPUTS} for name in self.names}
        self.frames = params["frame_outputs"]
        self.imu = list(params["imu"])
        self.sun_sensors = list(params["sun_sensor"])
        self.ephemeris = None
        if params["srp"] or self.sun_sensors or params["third_bodies"]:  # the Sun and Moon at each step's start
            from components.space.ephemeris import Ephemeris

            self.ephemeris = Ephemeris(run.epoch)
        self.quaternion_outputs = [
            f"{name}.{key}"
            for name in self.names
            for key in ("orientation", "link_orientation")[: 2 if self.links else 1]
        ]
        self.quaternion_outputs += [f"{name}.q_lvlh_body" for name in self.names if self.frames]
        self.quaternion_outputs += ["grasp.q_ee_grasp", "grasp.q_c_t"] if self.grasp else []
        self.magnetics = self._magnetics(params, run)  # the field and magnetorquers, else None: nothing per step
        self.state_vector = StateVector.of(self.declare(params, run), self.names)  # None: outputs by name
        self.capture_report: CaptureReport | None = None  # the last step's capture, for the event
        self.last_quaternions: dict[str, np.ndarray] = {}

    def _magnetics(self, params, run):
        """The geomagnetic field and the magnetorquers (``magnetic_field``), or None without a field."""
        field = params["magnetic_field"]
        if field is None:
            return None
        from components.dynamics.magnetic import Magnetics
        from components.space.geomagnetic import GeomagneticField

        if not run.epoch:
            raise ConfigError(EPOCH_KEY, "the magnetic field needs the run's epoch (run.epoch)")
        dipole = {key: field[key] for key in ("g10", "g11", "h11", "radius")}
        return Magnetics(
            self.world,
            GeomagneticField(field["model"], run.epoch, dipole),
            {
                name: np.broadcast_to(np.asarray(m["max_dipole"], dtype=float), (3,))
                for name, m in params["magnetorquers"].items()
            },
        )

    def _inputs(self, inputs: Mapping[str, np.ndarray], torques: bool, t_ns: int) -> None:
        age = (t_ns - self.input_times_ns.get("r_eci", t_ns)) / NS_PER_S  # < 0 under Gauss-Seidel
        if self.ephemeris is not None:
            tt = self.ephemeris.tt(t_ns)
            self.world.set_sun(sun_position_eci(tt), moon_position_eci(tt))
        try:
            r_eci, v_eci, q_eci_lvlh, w_lvlh = ORBIT_VALUES(inputs)
            self.world.set_orbit(r_eci, v_eci, q_eci_lvlh, w_lvlh, age=age)
            if self.world.atmosphere_varies:  # NRLMSISE-00 needs the time the orbit point is at
                self.world.orbit_time = self.input_times_ns.get("r_eci", t_ns) / NS_PER_S
            if torques:
                for name, key in self.torque_inputs:
                    self.world.set_torques(name, inputs[key])
        except ValueError as e:
            raise ComponentError(str(e)) from None

    def _outputs(self, t_ns: int) -> dict[str, np.ndarray | np.float64] | np.ndarray:
        if self.state_vector is not None:
            return self.state_vector.build(self.world.bodies, self.last_quaternions)
        out: dict[str, np.ndarray | np.float64] = {}
        for name in self.names:
            output_names = self.output_names[name]
            for key, value in self.world.outputs(name, links=self.links).items():
                out[output_names[key]] = value
            if self.frames:
                out.update({f"{name}.{k}": v for k, v in self.world.frame_outputs(name).items()})
        for name in self.sun_sensors:
            out.update({f"{name}.{k}": v for k, v in self.world.sun_outputs(name).items()})
        grasp = self.world.grasp
        if self.imu or (grasp is not None and grasp.closed):
            accelerations = self.world.accelerations()  # also the weld's wrench, for grasp.wrench
            for name in self.imu:
                out.update({f"{name}.{k}": v for k, v in self.world.imu_outputs(name, accelerations[name]).items()})
        if grasp is not None:
            out.update({f"grasp.{k}": v for k, v in grasp.relative().items()})
            out.update(
                {f"grasp.{k}": v for k, v in self.world.relative_frames(grasp.spec.chaser, grasp.spec.target).items()}
            )
            out["grasp.closed"] = np.float64(grasp.closed)
            out["grasp.wrench"] = grasp.wrench_on_target() if grasp.closed else np.zeros(6)
        if self.magnetics is not None:
            try:
                out.update(self.magnetics.outputs(t_ns))
            except ValueError as e:  # the WMM outside its years
                raise ComponentError(f"magnetic_field: {e}") from None
        for key in self.quaternion_outputs:
            out[key] = self.last_quaternions[key] = continuous(out[key], self.last_quaternions.get(key))
        return out

    def initialize(self, t0_ns, inputs):
        self._inputs(inputs, torques=False, t_ns=t0_ns)
        self.world.reset_bodies()
        if self.world.atmosphere_varies and self.world.environment_on:  # (the steps update it at their midpoints)
            self.world.update_atmosphere(self.world.elapsed)
        self.last_quaternions = {}
        return self._outputs(t0_ns)

    def do_step(self, t_ns, h_ns, inputs):
        self._inputs(inputs, torques=True, t_ns=t_ns)
        if self.magnetics is not None:
            self.magnetics.apply(inputs)
        self.world.step(h_ns / NS_PER_S)
        grasp = self.world.grasp
        if grasp is not None:
            overload = grasp.check_overload()
            if overload is not None:
                self.emit("grasp_overload", time=(t_ns + h_ns) / NS_PER_S, **overload)
            grasp.rearm(inputs["grasp.close"] >= 0.5)
        if self.grasp and inputs["grasp.close"] >= 0.5:
            report = self.world.capture()
            if report is not None:
                self.capture_report = report
                self.emit(
                    "capture",
                    time=(t_ns + h_ns) / NS_PER_S,
                    relative_twist=report.relative_twist.tolist(),
                    impulse=report.impulse.tolist(),
                    errors=report.errors,
                )
        return self._outputs(t_ns + h_ns)

    def get_state(self):
        magnetic = self.magnetics.get_state() if self.magnetics is not None else {}
        return {**self.world.get_state(), **{LAST + k: v.copy() for k, v in self.last_quaternions.items()}, **magnetic}

    def set_state(self, state):
        try:
            self.world.set_state({k: v for k, v in state.items() if not k.startswith((LAST, MAGNETIC))})
            if self.magnetics is not None:
                self.magnetics.set_state(state)
        except ValueError as e:
            raise ComponentError(str(e)) from None
        except KeyError as e:
            raise ComponentError(f"state: missing {e.args[0]!r}") from None
        self.last_quaternions = {
            k[len(LAST) :]: np.array(v, dtype=np.float64) for k, v in state.items() if k.startswith(LAST)
        }


class DartDynamics(OrbitalDynamics):
    """Free-floating URDF multibodies in orbit, their dynamics by DART.

    Zero gravity in the free-falling, non-rotating world frame W (origin at the reference orbit
    point r_eci(t), axes parallel to ECI), plus per link and each switchable: tidal force,
    gravity-gradient torque, atmospheric drag, solar radiation pressure (docs/environment/sun.md),
    the Sun's and the Moon's tidal force (``third_bodies``, docs/environment/gravity.md). ``integrator: rk4`` (default) is fourth-order
    Runge-Kutta on the configuration manifold over DART's forward dynamics (no contacts);
    ``integrator: dart`` is DART's own step with its constraint solver (contacts between bodies).
    Quaternions [x, y, z, w]. Takes the state of ``dynamics.pinocchio`` (a swap hands it over).
    """

    type_name = "dynamics.dart"
    engine = "dart"


class PinocchioDynamics(OrbitalDynamics):
    """Free-floating URDF multibodies in orbit, their dynamics by Pinocchio (ABA).

    The same world, environment, integrator, joint stops, mimic joints, grasp, outputs and state as
    ``dynamics.dart`` (components/dynamics/world.py); Pinocchio computes the forward dynamics
    (components/dynamics/pinocchio_body.py). No contacts: ``integrator`` must be rk4. Takes the
    state of ``dynamics.dart`` (a swap hands it over). Quaternions [x, y, z, w].
    """

    type_name = "dynamics.pinocchio"
    engine = "pinocchio"

    @classmethod
    def validate(cls, params, run):
        if params["integrator"] != "rk4":
            raise ConfigError(
                "integrator",
                f"dynamics.pinocchio has no contact solver: expected rk4 (DART's own "
                f"step with contacts is dynamics.dart's), got {params['integrator']!r}",
            )
        return super().validate(params, run)


class StateVector:
    """The outputs of a dynamics whose outputs are its bodies' states alone (no link outputs,
    frames, sensors, grasp or magnetics: a rigid spacecraft) as one vector in declaration order,
    the orientations sign-continuous as ``continuous`` makes them: one array a step, no dict."""

    def __init__(self, names: list[str], orientations: list[tuple[str, int]]):
        self.names, self.orientations = names, orientations

    @classmethod
    def of(cls, variables, names: list[str]) -> StateVector | None:
        """For these declared variables and bodies, or None when there are outputs besides the states."""
        outputs = [v for v in variables if v.causality == "output"]
        if [v.name for v in outputs] != [f"{name}.{key}" for name in names for key in BODY_OUTPUTS]:
            return None
        offsets = np.cumsum([0] + [v.size for v in outputs])
        return cls(names, [(v.name, int(at)) for v, at in zip(outputs, offsets) if v.name.endswith(".orientation")])

    def build(self, bodies, last: dict[str, np.ndarray]) -> np.ndarray:
        """The vector at the bodies' current state; ``last``: each orientation's previous value, updated."""
        names = self.names
        out = (
            bodies[names[0]].state_vector()
            if len(names) == 1
            else np.concatenate([bodies[n].state_vector() for n in names])
        )
        for key, at in self.orientations:
            q, previous = out[at : at + 4], last.get(key)
            if previous is not None and opposite(q.tolist(), previous.tolist()):
                q *= -1.0
            last[key] = q.copy()
        return out
