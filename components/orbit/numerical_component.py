"""The type ``orbit.numerical``: an orbit integrated under the Earth's harmonics, the Sun, the Moon,
drag and SRP (:mod:`components.orbit.numerical`), and its force models' parameters."""

from __future__ import annotations

import math

import numpy as np

from components import extras
from components.constants import NS_PER_S
from components.errors import ConfigError
from components.orbit import plots as orbit_plots
from components.orbit.components import (
    ELEMENTS,
    ORBIT_OUTPUTS,
    OrbitComponent,
    check_element_parameters,
    epoch_mean_anomaly,
    epoch_text,
)
from components.orbit.frames import lvlh_state
from components.rotations import continuous
from components.schema import Float, Int, ListOf, Record, Str
from components.sdk import Parameter, Variable
from components.space.eclipse import MODELS as ECLIPSE_MODELS
from components.space.parameters import ATMOSPHERE, check_atmosphere, exponential_layer
from components.space.srp import SOLAR_FLUX

GRAVITY = Record(
    "Gravity",
    (
        Parameter(
            "degree",
            Int(minimum=0),
            description="highest degree N of the Earth's field kept (0: point mass, 2 with "
            "order 0: J2 only; at most 20, the shipped file's)",
        ),
        Parameter("order", Int(minimum=0), description="highest order M kept, 0 <= M <= N (0: zonal terms only)"),
        Parameter(
            "field",
            Str(("ggm03s",)),
            default="ggm03s",
            description="coefficient file: ggm03s (GGM03S to 20 x 20, components/space/data; its GM and R are used)",
        ),
    ),
    description="the Earth's gravity field in spherical harmonics",
)
DRAG = Record(
    "Drag",
    (
        Parameter("cd", Float(positive=True, plausible=(0.5, 10.0)), description="drag coefficient"),
        Parameter("area", Float("m^2", positive=True, plausible=(1e-3, 1e4)), description="area facing the flow"),
    ),
    description="cannonball drag against an atmosphere turning with the Earth (the atmosphere: ``atmosphere``)",
)
SRP = Record(
    "Srp",
    (
        Parameter(
            "cr",
            Float(positive=True, plausible=(0.5, 2.5)),
            description="reflectivity coefficient (1 absorbs, 2 mirrors)",
        ),
        Parameter("area", Float("m^2", positive=True, plausible=(1e-3, 1e4)), description="area facing the Sun"),
    ),
    description="cannonball solar radiation pressure (components/space/srp.py; the shadow: ``eclipse``)",
)


def _drag(params, rotation):
    """The drag term (cannonball, ``mass``): in NRLMSISE-00 / MSIS 2.1 turning with the Earth
    (``rotation``), or in the exponential table or layer."""
    from components.orbit import numerical
    from components.space.atmosphere import ExponentialAtmosphere, Nrlmsise00

    d, atmosphere = params["drag"], params.get("atmosphere")
    if atmosphere is not None and atmosphere["model"] != "exponential":
        density, needs = (
            numerical.msis_density(
                Nrlmsise00(atmosphere["f107"], atmosphere["f107a"], atmosphere["ap"], model=atmosphere["model"]),
                rotation,
            ),
            frozenset({"earth_rotation"}),
        )
    else:
        density, needs = (
            numerical.exponential_density(ExponentialAtmosphere(exponential_layer(atmosphere))),
            frozenset(),
        )
    return numerical.Drag(density, d["cd"], d["area"], params["mass"], needs=needs)


class NumericalComponent(OrbitComponent):
    """An orbit integrated under the Earth's harmonics, the Sun, the Moon, drag and SRP (type ``orbit.numerical``).

    Cowell's method by fixed-step RK4 on a grid of ``step`` from run.epoch
    (:class:`components.orbit.numerical.CowellPropagator`), from osculating elements at run.epoch.
    Gravity: GGM03S to (``gravity.degree``, ``gravity.order``) with the file's GM and R
    (3.986004415e14 m^3/s^2, 6378136.3 m), in ITRF by :class:`components.space.earth.EarthRotation`
    (IAU 2006/2000A, UT1 = UTC, no polar motion). ``third_bodies``: the Sun's and the Moon's
    pull (JPL DE440 GMs) at positions from ``ephemeris``. ``drag``: cannonball, with ``mass``, in
    ``atmosphere`` (the exponential table by default, one exponential layer, or NRLMSISE-00 / MSIS 2.1
    for given F10.7, F10.7a, Ap) turning with the Earth. ``srp``: cannonball, with ``mass``, in the
    shadow of ``eclipse`` at ``solar_flux``. Besides the four orbit outputs, each term's acceleration ``a_<term>_eci`` (m/s^2, ECI);
    w_lvlh uses their sum. Equations, frames, agreement with Basilisk: docs/environment/gravity.md.
    """

    type_name = "orbit.numerical"
    variables = None
    plots = (orbit_plots.TRACK, orbit_plots.ACCELERATIONS)
    parameters = ELEMENTS + (
        Parameter(
            "step",
            Float("s", positive=True, plausible=(0.01, 600.0)),
            description="the integrator's fixed step (RK4); the state lives on this grid from run.epoch",
        ),
        Parameter("gravity", GRAVITY, description="the Earth's field"),
        Parameter(
            "third_bodies",
            ListOf(Str(("sun", "moon")), unique=True),
            default=[],
            description="bodies whose pull is added: sun, moon",
        ),
        Parameter(
            "ephemeris",
            Str(("erfa", "de440")),
            default="erfa",
            description="positions of the Sun and the Moon: erfa (epv00, moon98) or de440 "
            "(JPL DE440; pip install 'zenorbit[ephemeris]')",
        ),
        Parameter("drag", DRAG, default=None, description="cannonball drag (off when absent)"),
        Parameter(
            "atmosphere",
            ATMOSPHERE,
            default=None,
            description="drag's atmosphere (model: exponential, nrlmsise00, msis21); null (default): the "
            "piecewise exponential table 0-1000 km",
        ),
        Parameter("srp", SRP, default=None, description="cannonball solar radiation pressure (off when absent)"),
        Parameter(
            "eclipse",
            Str(tuple(ECLIPSE_MODELS)),
            default="conical",
            description="SRP's shadow: conical (Earth and Moon, penumbra), cylindrical (the Earth's), none",
        ),
        Parameter(
            "solar_flux",
            Float("kg/s^3", positive=True, plausible=(1300.0, 1420.0)),
            default=SOLAR_FLUX,
            description="SRP's solar flux at 1 AU, W/m^2 (= kg/s^3; 1361: IAU 2015 nominal total solar irradiance)",
        ),
        Parameter(
            "mass",
            Float("kg", positive=True, plausible=(0.1, 1e6)),
            default=None,
            description="spacecraft mass (required with drag or srp)",
        ),
    )
    MAX_DEGREE = 20

    @classmethod
    def terms(cls, params) -> tuple[str, ...]:
        """The acceleration terms ``params`` turn on, in the order they are summed."""
        degree = params["gravity"]["degree"]
        names = ["point_mass"] + (["harmonics"] if degree >= 2 else [])
        names += [b for b in ("sun", "moon") if b in params["third_bodies"]]
        return tuple(names + [k for k in ("drag", "srp") if params.get(k) is not None])

    @classmethod
    def declare(cls, params, run):
        return list(ORBIT_OUTPUTS) + [
            Variable(f"a_{term}_eci", "output", (3,), "m/s^2", [0.0, 0.0, 0.0], f"acceleration by {term}, ECI")
            for term in cls.terms(params)
        ]

    @classmethod
    def validate(cls, params, run):
        check_element_parameters(params)
        degree, order = params["gravity"]["degree"], params["gravity"]["order"]
        if degree > cls.MAX_DEGREE:
            raise ConfigError(
                "gravity.degree", f"expected at most {cls.MAX_DEGREE} (the shipped GGM03S file), got {degree}"
            )
        if order > degree:
            raise ConfigError("gravity.order", f"expected 0 <= order <= degree ({degree}), got {order}")
        if (params.get("drag") is not None or params.get("srp") is not None) and params.get("mass") is None:
            raise ConfigError("mass", "expected the spacecraft mass (kg) with drag or srp, got none")
        if params.get("atmosphere") is not None and params.get("drag") is None:
            raise ConfigError("atmosphere", "an atmosphere is for drag: expected drag: {cd, area} with it, got no drag")
        check_atmosphere(params.get("atmosphere"), run.epoch)
        if params.get("srp") is None:
            for key, default in (("eclipse", "conical"), ("solar_flux", SOLAR_FLUX)):
                if params[key] != default:
                    raise ConfigError(key, f"{key} is for SRP: expected srp: {{cr, area}} with it, got no srp")
        if params["ephemeris"] == "de440" and cls._bodies(params):
            extras.require("ephemeris", "ephemeris de440 (JPL DE440)", "ephemeris")
        return params

    @staticmethod
    def _bodies(params) -> set[str]:
        """The bodies whose positions a term needs: the third bodies, and the Sun (and for a conical
        shadow the Moon) for SRP."""
        bodies = set(params["third_bodies"])
        if params.get("srp") is not None:
            bodies |= {"sun", "moon"} if params["eclipse"] == "conical" else {"sun"}
        return bodies

    def __init__(self, params, run):
        from components.constants import NS_PER_S
        from components.orbit import numerical
        from components.orbit.kepler import coe_to_rv, solve_kepler, true_from_eccentric
        from components.space import ephemeris, gravity
        from components.space.earth import EarthRotation

        super().__init__(params, run)
        g = params["gravity"]
        field = gravity.GravityField(g["degree"], g["order"], gravity.GGM03S_20)
        terms: list[numerical.AccelerationTerm] = [numerical.PointMass(field.mu)] + (
            [numerical.Harmonics(field)] if g["degree"] >= 2 else []
        )
        a, e = params["semi_major_axis"], params["eccentricity"]
        m0 = epoch_mean_anomaly(params, run, math.sqrt(field.mu / a**3))
        nu = true_from_eccentric(solve_kepler(m0, e), e)
        r0, v0 = coe_to_rv(
            a * (1.0 - e * e), e, params["inclination"], params["raan"], params["arg_perigee"], nu, field.mu
        )
        rotation = EarthRotation(epoch_text(run))
        terms += [
            numerical.ThirdBody(b, gravity.MU_SUN if b == "sun" else gravity.MU_MOON)
            for b in ("sun", "moon")
            if b in params["third_bodies"]
        ]
        if params.get("drag") is not None:
            terms.append(_drag(params, rotation))
        if params.get("srp") is not None:
            s = params["srp"]
            terms.append(
                numerical.CannonballSrp(
                    s["cr"], s["area"], params["mass"], params["eclipse"], flux=params["solar_flux"]
                )
            )
        bodies = self._bodies(params)
        sun = moon = None
        if bodies:
            sun, moon = ephemeris.positions(params["ephemeris"])
            sun, moon = (sun if "sun" in bodies else None), (moon if "moon" in bodies else None)
        step_ns = int(round(params["step"] * NS_PER_S))
        rotate = any("earth_rotation" in term.needs for term in terms)
        surroundings = numerical.Surroundings(rotation, sun, moon, rotate)
        self.propagator = numerical.CowellPropagator(r0, v0, terms, step_ns, surroundings)

    def _outputs_at(self, t_ns):
        r, v = self.propagator.state_at(t_ns)
        terms = self.propagator.accelerations(t_ns / NS_PER_S, r, v)
        a = sum(terms.values())
        q, w = lvlh_state(r, v, a)
        q = continuous(q, self._q_previous)
        self._q_previous = q
        out = {"r_eci": r, "v_eci": v, "q_eci_lvlh": q, "w_lvlh": w}
        out.update((f"a_{name}_eci", value) for name, value in terms.items())
        return out

    def get_state(self):
        p = self.propagator
        return {**super().get_state(), "t_ns": np.array([float(p.t_ns)]), "r": p.r.copy(), "v": p.v.copy()}

    def set_state(self, state):
        super().set_state(state)
        p = self.propagator
        p.t_ns = int(np.asarray(state["t_ns"]).ravel()[0])
        p.r = np.array(state["r"], dtype=np.float64)
        p.v = np.array(state["v"], dtype=np.float64)
