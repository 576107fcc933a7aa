"""Eclipse factor and solar radiation pressure (components/space/eclipse.py, srp.py) against
Basilisk's fixtures (tests/basilisk/srp.json: ``eclipse``, ``radiationPressure``,
``facetSRPDynamicEffector`` on the same Sun and Moon positions) and closed forms."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from components.camera.sun import in_earth_shadow
from components.space import eclipse, srp
from tests import validation

FIXTURE = json.loads((Path(__file__).resolve().parents[1] / "basilisk" / "srp.json").read_text())
K = FIXTURE["constants"]
SUN, MOON = np.array(FIXTURE["sun"]), np.array(FIXTURE["moon"])
RADII = {"r_sun": K["REQ_SUN"], "r_earth": K["REQ_EARTH"], "r_moon": K["REQ_MOON"]}
ANNULAR = "Moon antumbra (annular)"


def relative(got, want):
    got, want = np.asarray(got, dtype=float), np.asarray(want, dtype=float)
    return float(np.linalg.norm(got - want) / np.linalg.norm(want)) if np.any(want) else float(np.max(np.abs(got)))


@pytest.mark.parametrize("case", FIXTURE["eclipse"], ids=lambda c: c["case"])
def test_conical_eclipse_factor_matches_basilisk(case):
    nu = eclipse.illumination(case["r"], SUN, MOON, "conical", **RADII)
    error = abs(nu - case["factor"]) / max(case["factor"], 1e-300) if case["factor"] else abs(nu)
    validation.check("srp_eclipse_basilisk", error)
    assert 0.0 <= nu <= 1.0


def test_fixture_covers_umbra_penumbra_and_sun():
    factors = [c["factor"] for c in FIXTURE["eclipse"]]
    assert factors.count(0.0) >= 2 and factors.count(1.0) >= 2
    assert sum(0.05 < f < 0.95 for f in factors) >= 4


def test_annular_eclipse_is_the_visible_fraction_closed_form():
    """Beyond the Moon's umbra, its disk inside the Sun's: nu = 1 - b^2/a^2 (Basilisk's too)."""
    case = next(c for c in FIXTURE["eclipse"] if c["case"] == ANNULAR)
    r = np.array(case["r"])
    a = math.asin(K["REQ_SUN"] / np.linalg.norm(SUN - r))
    b = math.asin(K["REQ_MOON"] / np.linalg.norm(r - MOON))
    assert b < a
    assert case["factor"] == pytest.approx(1 - b * b / (a * a), rel=1e-12)
    assert eclipse.illumination(r, SUN, MOON, "conical", **RADII) == pytest.approx(1 - b * b / (a * a), rel=1e-12)


def test_partial_disk_fraction_against_numerical_overlap():
    """Two disks' overlap (Sun radius a, occulter b, centres c apart) by a fine grid count."""
    a, b, c = 0.0047, 0.0061, 0.0083
    n = 1601
    x, y = np.meshgrid(np.linspace(-a, a, n), np.linspace(-a, a, n))
    inside_sun = x**2 + y**2 <= a**2
    visible = inside_sun & ((x - c) ** 2 + y**2 > b**2)
    assert eclipse.disk_fraction(a, b, c) == pytest.approx(visible.sum() / inside_sun.sum(), abs=2e-3)


def test_cylindrical_model_is_the_earths_cylinder():
    """nu = 0 behind the Earth (r . u < 0) within R_E of the Sun line, else 1; the camera's default."""
    rng = np.random.default_rng(7)
    sun_hat = SUN / np.linalg.norm(SUN)
    shaded = 0
    for _ in range(400):
        r = rng.normal(size=3) * 7.5e6
        behind = r @ sun_hat < 0 and np.linalg.norm(r - (r @ sun_hat) * sun_hat) < 6378137.0
        nu = eclipse.illumination(r, SUN, None, "cylindrical")
        assert nu == (0.0 if behind else 1.0) and in_earth_shadow(r, sun_hat) == behind
        shaded += behind
    assert 20 < shaded < 380
    inside = -7.0e6 * sun_hat
    assert eclipse.illumination(inside, SUN, None, "cylindrical") == 0.0
    assert eclipse.illumination(inside, SUN, None, "none") == 1.0
    with pytest.raises(ValueError, match="expected one of none, cylindrical, conical, got 'cone'"):
        eclipse.illumination(inside, SUN, None, "cone")


@pytest.mark.parametrize("case", FIXTURE["cannonball"], ids=lambda c: f"nu={c['factor']}")
def test_cannonball_force_matches_basilisk_radiation_pressure(case):
    s = SUN - np.array(case["r"])
    force = srp.cannonball_force(s, case["cr"] * case["area"], case["factor"], flux=K["SOLAR_FLUX_EARTH"], au=K["AU"])
    if case["factor"] == 0.0:
        assert not np.any(force) and not np.any(case["force_N"])
        return
    validation.check("srp_cannonball_basilisk", relative(force, case["force_N"]))
    assert force @ s < 0.0  # away from the Sun


@pytest.mark.parametrize("case", FIXTURE["facet_cases"], ids=lambda c: str(c["sigma_BN"]))
def test_facet_force_and_torque_match_basilisk_facet_srp(case):
    facets = srp.facet_rows(FIXTURE["facets"])
    s_B = np.array(case["dcm_BN"]) @ (SUN - np.array(case["r"]))
    lit = facets[:, 1:4] @ (s_B / np.linalg.norm(s_B)) > 0
    assert 1 <= lit.sum() < len(facets)  # some facets face the Sun, some do not
    force, torque = srp.facet_wrench(s_B, facets, case["factor"], flux=K["facet_flux"], au=K["facet_AU"])
    validation.check("srp_facets_basilisk", max(relative(force, case["force_B"]), relative(torque, case["torque_B"])))


def test_flat_plate_facing_the_sun_closed_form():
    """F = -P A (1 + rho_s + 2 rho_d / 3) n for a plate whose normal n points at the Sun, P = Phi/c
    (AU/d)^2; torque r x F; nothing on its back."""
    s = np.array([2.0e11, -0.7e11, 0.4e11])
    n = s / np.linalg.norm(s)
    area, specular, diffuse, nu = 2.5, 0.3, 0.45, 0.8
    centre = np.array([0.4, -1.1, 0.25])
    plate = srp.facet_rows(
        [{"area": area, "normal": n * 3.0, "centre": centre, "specular": specular, "diffuse": diffuse}]
    )
    force, torque = srp.facet_wrench(s, plate, nu)
    pressure = srp.SOLAR_FLUX / srp.SPEED_OF_LIGHT * (srp.AU / np.linalg.norm(s)) ** 2
    want = -nu * pressure * area * (1 + specular + 2 * diffuse / 3) * n
    assert relative(force, want) < 1e-14
    assert relative(torque, np.cross(centre, want)) < 1e-14
    back = plate.copy()
    back[0, 1:4] *= -1
    assert not np.any(srp.facet_wrench(s, back)[0])
    # an absorbing sphere of cross-section A: Cr = 1
    assert relative(srp.cannonball_force(s, area), -pressure * area * n) < 1e-14


def test_facet_rows_refuse_what_cannot_be_a_facet():
    with pytest.raises(ValueError, match=r"f\[0\].normal: expected a direction"):
        srp.facet_rows(
            [{"area": 1.0, "normal": [0, 0, 0], "centre": [0, 0, 0], "specular": 0.1, "diffuse": 0.1}], where="f"
        )
    with pytest.raises(ValueError, match=r"specular \+ diffuse <= 1"):
        srp.facet_rows([{"area": 1.0, "normal": [0, 0, 1], "centre": [0, 0, 0], "specular": 0.7, "diffuse": 0.5}])
