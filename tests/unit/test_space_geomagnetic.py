"""The geomagnetic field (components/space/geomagnetic.py), the Earth's rotation
(components/space/earth.py) and the magnetorquer torque, against Basilisk's
magneticFieldCenteredDipole, magneticFieldWMM and MtbEffector (fixtures tests/basilisk/geomagnetic.json,
remade by ``python -m tests.basilisk geomagnetic``) and closed forms."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from components.space.earth import EarthRotation, gcrf_to_itrf
from components.space.geomagnetic import (
    BASILISK_DIPOLE,
    GeomagneticField,
    WorldMagneticModel,
    decimal_year,
    dipole_field_ecef,
    wmm_coefficients,
)
from components.timescales import parse_utc
from tests import validation

FIXTURES = json.loads((Path(__file__).resolve().parents[1] / "basilisk" / "geomagnetic.json").read_text())
NT = 1e-9


def test_the_wmm_coefficients_are_the_file_basilisk_reads():
    import hashlib

    assert hashlib.md5(wmm_coefficients().read_bytes()).hexdigest() == "a1b6402dd23658d15affb0f31babccc7"


def test_dipole_field_matches_basilisk():
    assert FIXTURES["dipole_coefficients"] == pytest.approx(BASILISK_DIPOLE, rel=1e-15)
    worst = 0.0
    for case in FIXTURES["dipole"]:
        C = np.array(case["C_ecef_eci"])
        b = dipole_field_ecef(C @ np.array(case["r_eci"]), **BASILISK_DIPOLE) @ C
        worst = max(worst, float(np.linalg.norm(b - np.array(case["b_eci"]))) / NT)
    validation.check("geomagnetic_dipole", worst)


def test_wmm_field_matches_basilisk():
    wmm = WorldMagneticModel()
    worst = 0.0
    for case in FIXTURES["wmm"]:
        C = np.array(case["C_ecef_eci"])
        b = wmm.field_ecef(C @ np.array(case["r_eci"]), decimal_year(parse_utc(case["epoch"]))) @ C
        expected = np.array(case["b_eci"])
        assert np.linalg.norm(expected) > 50 * NT  # (GEO: ~100 nT; LEO: 18-50 uT)
        worst = max(worst, float(np.linalg.norm(b - expected)) / NT)
    validation.check("geomagnetic_wmm", worst)


def test_magnetorquer_torque_matches_basilisk_mtb_effector():
    """MtbEffector: tau_B = (Gt clip(mu)) x B_B, B_B = [BN] B_N; ours: m x b_body with the same
    saturation, from the MRP's rotation by Zenorbit's own quaternion code."""
    from components.rotations import quat_to_matrix

    case = FIXTURES["mtb"]
    s = np.array(case["sigma_BN"])
    s2 = s @ s
    q_N_B = np.append(2 * s, 1 - s2) / (1 + s2)  # the MRP's quaternion [x, y, z, w]
    b_body = quat_to_matrix(q_N_B).T @ np.array(case["b_N"])
    limit = np.array(case["max_dipoles"])
    m = np.array(case["gt_B"]) @ np.clip(case["dipoles"], -limit, limit)
    torque = np.cross(m, b_body)
    expected = np.array(case["torque_B"])
    validation.check("mtb_torque", float(np.linalg.norm(torque - expected) / np.linalg.norm(expected)))


def test_dipole_field_at_its_pole_is_twice_the_equators():
    """A pure dipole: |B| at the pole of its axis is 2 (a/r)^3 |d|, at its equator (a/r)^3 |d|."""
    d = np.array([BASILISK_DIPOLE["g11"], BASILISK_DIPOLE["h11"], BASILISK_DIPOLE["g10"]])
    axis = d / np.linalg.norm(d)
    equator = np.cross(axis, [0.3, -0.8, 0.5])
    equator /= np.linalg.norm(equator)
    r = 6878137.0
    scale = (BASILISK_DIPOLE["radius"] / r) ** 3 * np.linalg.norm(d)
    pole_field = dipole_field_ecef(r * axis, **BASILISK_DIPOLE)
    equator_field = dipole_field_ecef(r * equator, **BASILISK_DIPOLE)
    assert np.linalg.norm(pole_field) == pytest.approx(2 * scale, rel=1e-14)
    assert np.linalg.norm(equator_field) == pytest.approx(scale, rel=1e-14)
    assert pole_field == pytest.approx(2 * scale * axis, rel=1e-14)  # along the axis, outwards
    assert equator_field == pytest.approx(-scale * axis, rel=1e-13)  # antiparallel to it
    # g10 < 0: the field points down into the Earth near the north geographic pole
    assert dipole_field_ecef([0.0, 0.0, r], **BASILISK_DIPOLE)[2] < 0


def test_wmm_falls_as_the_dipole_far_away():
    """Far away the degree-1 terms dominate: the WMM's field tends to the dipole of its own g10,
    g11, h11 (the WMM2025 file's first lines), the rest falling one power of a/r faster (the
    quadrupole): the relative difference halves when r doubles."""
    wmm = WorldMagneticModel()
    rows = [line.split() for line in wmm_coefficients().read_text().splitlines()[1:3]]
    g10, g11, h11 = float(rows[0][2]) * NT, float(rows[1][2]) * NT, float(rows[1][3]) * NT
    direction = np.array([0.48, -0.6, 0.64])
    differences = []
    for radii in (20, 40):
        r = radii * 6371.2e3 * direction
        dipole = dipole_field_ecef(r, g10, g11, h11, 6371.2e3)
        differences.append(np.linalg.norm(wmm.field_ecef(r, 2025.0) - dipole) / np.linalg.norm(dipole))
    assert differences[0] < 0.5 / 20
    assert differences[0] / differences[1] == pytest.approx(2.0, rel=0.05)


def test_decimal_year_counts_days_as_the_wmm_does():
    assert decimal_year(parse_utc("2026-07-02T12:00:00Z")) == 2026.5  # day 183 of 365, noon
    assert decimal_year(parse_utc("2028-01-01T00:00:00Z")) == 2028.0
    assert decimal_year(parse_utc("2028-12-31T12:00:00Z")) == pytest.approx(2028 + 365.5 / 366, abs=1e-12)


def test_wmm_refuses_a_date_outside_its_years():
    with pytest.raises(ValueError, match=r"2025 to 2030.*2024"):
        GeomagneticField("wmm", "2024-06-01T00:00:00Z").b_eci(np.array([7e6, 0.0, 0.0]), 0)


def test_earth_rotation_is_the_earth_rotation_angle_at_j2000():
    """At J2000.0 precession-nutation is only the frame bias and nutation (~1e-4 rad): C_ecef_eci
    is R3(ERA) to that, ERA = 2 pi (0.7790572732640 + 1.00273781191135448 Du) (IERS 2010, eq. 5.15),
    and it turns at the ERA's rate."""
    rotation = EarthRotation("2000-01-01T12:00:00Z")
    utc, _ = rotation.dates(0)
    du = utc[0] + utc[1] - 2451545.0
    era = 2 * math.pi * ((0.7790572732640 + 1.00273781191135448 * du) % 1.0)
    c, s = math.cos(era), math.sin(era)
    r3 = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    C = rotation.ecef_from_eci(0)
    assert np.abs(C - r3).max() < 1e-4
    dt = 600.0
    turn = rotation.ecef_from_eci(int(dt * 1e9)) @ C.T  # R3(omega dt)
    omega = 2 * math.pi * 1.00273781191135448 / 86400.0
    assert math.atan2(turn[0, 1], turn[0, 0]) == pytest.approx(omega * dt, rel=1e-6)
    assert np.linalg.det(C) == pytest.approx(1.0, abs=1e-14)


def test_field_in_eci_rotates_the_ecef_field_back():
    """b_eci = C^T B(C r): the same field seen from ECEF at the same instant."""
    field = GeomagneticField("dipole", "2026-03-14T05:26:53Z")
    r = np.array([4123456.0, -3210987.0, -4876543.0])
    t_ns = 1234 * 10**9
    utc, tt = field.rotation.dates(t_ns)
    C = field.rotation.ecef_from_eci(t_ns)
    assert np.abs(C - gcrf_to_itrf(tt, utc)).max() < 1e-9  # at t itself (C_cirs_gcrf a minute old)
    assert field.b_eci(r, t_ns) == pytest.approx(C.T @ dipole_field_ecef(C @ r, **BASILISK_DIPOLE), rel=1e-14)
    assert field.b_eci(np.array([r, 2 * r]), t_ns)[1] == pytest.approx(field.b_eci(r, t_ns) / 8, rel=1e-13)
