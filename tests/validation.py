"""The validation table: each physics module against an independent reference.

    python -m tests.validation            # run the checks, print the table (Markdown), ~2 min
    python -m tests.validation --readme   # and write it into docs/reference/validation.md

Each row is declared once, here: what is compared, against what, and the tolerance. The tests
that measure a row call :func:`check`, which records the figure and fails the test when it is
above the tolerance; so ``pytest`` enforces the table and this command reproduces its numbers
by running exactly those tests. A row that several tests (or parametrized cases) measure shows
the worst figure.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README_START = "<!-- validation table: python -m tests.validation --readme -->"
README_END = "<!-- end of validation table -->"


@dataclass(frozen=True)
class Row:
    module: str
    quantity: str
    reference: str
    tolerance: float
    unit: str
    tests: tuple[str, ...]  # pytest node ids (file::test) that measure the row


ROWS: dict[str, Row] = {
    "kepler_vallado": Row(
        "orbit.kepler",
        "r, v from classical elements (largest position error)",
        "Vallado, Fundamentals (4th ed.), Example 2-6",
        0.5,
        "m",
        (
            "tests/unit/test_orbit_kepler.py::test_vallado_example_2_6_coe2rv",
            "tests/unit/test_orbit_kepler.py::test_kepler_orbit_reproduces_vallado_example_at_true_anomaly",
        ),
    ),
    "kepler_two_body": Row(
        "orbit.kepler",
        "position over one day: LEO, e = 0.7, GEO",
        "scipy DOP853 on r'' = -mu r/|r|^3 (rtol 1e-12)",
        1.0,
        "m",
        ("tests/unit/test_orbit_kepler.py::test_kepler_matches_dop853_two_body_over_one_day",),
    ),
    "kepler_j2_raan": Row(
        "orbit.kepler (j2)",
        "ISS node drift rate, relative error",
        "DOP853 integration of the J2 force model",
        1e-2,
        "",
        (
            "tests/unit/test_orbit_kepler.py::test_j2_raan_drift_of_iss_matches_closed_form_and_numerical_j2_integration",
        ),
    ),
    "sgp4_vectors": Row(
        "orbit.sgp4",
        "TEME position, every sample of 33 satellites",
        "SGP4-VER verification vectors (tcppver.out, Vallado et al. 2006)",
        1e-3,
        "m",
        ("tests/unit/test_orbit_tle.py::test_teme_output_matches_sgp4_verification_vectors",),
    ),
    "teme_gcrf": Row(
        "orbit.sgp4 frames",
        "TEME -> GCRF position",
        "Vallado, Fundamentals (4th ed.), Example 3-15",
        1e-2,
        "m",
        ("tests/unit/test_orbit_tle.py::test_teme_to_gcrf_reproduces_vallado_example_3_15",),
    ),
    "dart_aba": Row(
        "dynamics.dart",
        "free-floating forward dynamics (humanoid, servicer), relative",
        "Pinocchio ABA, random states and torques",
        1e-8,
        "",
        (
            "tests/unit/test_dynamics_pinocchio.py::test_free_floating_accelerations_match_pinocchio",
            "tests/unit/test_dynamics_pinocchio.py::test_environment_wrenches_match_pinocchio_external_forces",
        ),
    ),
    "dart_arm_trajectory": Row(
        "dynamics.dart",
        "the demo's humanoid under its recorded torques, 3 s: base and joints",
        "Pinocchio ABA + scipy DOP853 (rtol 1e-12), own tidal and gravity-gradient model",
        1e-9,
        "m, rad",
        (
            "tests/unit/test_dynamics_pinocchio.py::test_demo_humanoid_under_recorded_torques_matches_pinocchio_aba_and_dop853",
        ),
    ),
    "rk4_attitude": Row(
        "dynamics.dart (rk4)",
        "tumbling body (I = 2, 3, 4.5), attitude error at h = 1 ms over 3.2 s",
        "scipy DOP853 on Euler's equations (rtol 1e-13)",
        1e-11,
        "rad",
        ("tests/unit/test_dynamics_world.py::test_rk4_attitude_converges_at_fourth_order_down_to_small_steps",),
    ),
    "rk4_momentum": Row(
        "dynamics.dart (rk4)",
        "same body: angular momentum drift, h = 4 ... 0.25 ms, relative",
        "conservation (torque-free)",
        1e-9,
        "",
        ("tests/unit/test_dynamics_world.py::test_rk4_attitude_converges_at_fourth_order_down_to_small_steps",),
    ),
    "libration": Row(
        "dynamics.dart (gravity gradient)",
        "roll, pitch, yaw libration (I = 200, 300, 450), 3 orbits, fraction of the amplitude",
        "linearized closed form (Wie, Space Vehicle Dynamics, Sec. 7.2)",
        1e-2,
        "",
        ("tests/unit/test_dynamics_orbital.py::test_gravity_gradient_libration_in_roll_pitch_and_yaw",),
    ),
    "libration_schedules": Row(
        "dynamics.dart + orbit.kepler",
        "pitch libration (box, Ix < Iy = Iz, 1 deg), Jacobi and Gauss-Seidel, "
        "orbit at the dynamics' rate and 6x slower: period and amplitude, relative",
        "closed form w = n sqrt(3 (Iy - Ix) / Iz)",
        1e-2,
        "",
        ("tests/component/test_dynamics_component.py::test_libration_matches_the_closed_form_under_every_schedule",),
    ),
    "clohessy_wiltshire": Row(
        "dynamics.dart (tidal force)",
        "body released 10 m radially, quarter orbit, fraction of displacement",
        "Clohessy-Wiltshire closed form",
        1e-2,
        "",
        ("tests/unit/test_dynamics_orbital.py::test_tidal_force_follows_clohessy_wiltshire",),
    ),
    "cw_schedules": Row(
        "dynamics.dart + orbit.kepler",
        "the same under Jacobi and Gauss-Seidel, orbit at the dynamics' rate and 6x slower (inclined orbit)",
        "Clohessy-Wiltshire closed form",
        1e-4,
        "",
        ("tests/component/test_dynamics_component.py::test_clohessy_wiltshire_under_every_schedule",),
    ),
    "drag": Row(
        "dynamics.dart (drag)",
        "deceleration at 400 km, relative",
        "1/2 rho Cd A |v_rel|^2 / m",
        1e-2,
        "",
        ("tests/unit/test_dynamics_orbital.py::test_drag_decelerates_along_track",),
    ),
    "atmosphere_low": Row(
        "dynamics.dart (atmosphere)",
        "density 0-200 km, relative",
        "U.S. Standard Atmosphere 1976 tables",
        0.12,
        "",
        ("tests/unit/test_dynamics_orbital.py::test_atmosphere_density_against_the_us_standard_atmosphere",),
    ),
    "atmosphere_high": Row(
        "dynamics.dart (atmosphere)",
        "density 250-1000 km, relative (CIRA-72 vs USSA-76)",
        "U.S. Standard Atmosphere 1976 tables",
        0.4,
        "",
        ("tests/unit/test_dynamics_orbital.py::test_atmosphere_density_against_the_us_standard_atmosphere",),
    ),
    "geodetic_wgs84": Row(
        "space.earth",
        "WGS 84 geodetic height from ECEF, 5000 points 6200-43000 km from the centre",
        "ERFA gc2gd (WGS 84)",
        1e-7,
        "m",
        ("tests/unit/test_space_earth.py::test_geodetic_from_ecef_matches_erfa_gc2gd",),
    ),
    "atmosphere_exponential_basilisk": Row(
        "space.atmosphere (exponential)",
        "density: 5 bands of the table and 1 layer, relative",
        "Basilisk exponentialAtmosphere",
        1e-13,
        "",
        ("tests/unit/test_space_atmosphere.py::test_exponential_matches_basilisk",),
    ),
    "atmosphere_msis_basilisk": Row(
        "space.atmosphere (NRLMSISE-00)",
        "total mass density, 14 points 200-800 km (latitudes, local times, seasons, F10.7 65-300, Ap 2-207), relative",
        "Basilisk msisAtmosphere (NRLMSISE-00, C, double)",
        5e-5,
        "",
        ("tests/unit/test_space_atmosphere.py::test_nrlmsise00_matches_basilisk",),
    ),
    "atmosphere_msis_drag": Row(
        "dynamics drag (nrlmsise00)",
        "density over a 10 s step as rk4 weights its stages (one evaluation "
        "per step at its midpoint, local scale height), links 30 m apart, ISS orbit, relative",
        "NRLMSISE-00 at each link and stage",
        5e-5,
        "",
        ("tests/unit/test_space_atmosphere.py::test_local_exponential_against_the_model_per_link_per_stage",),
    ),
    "generalized_jacobian": Row(
        "controller.computed_torque",
        "Generalized Jacobian J_g (entries of order 1), largest error",
        "finite differences of the end effector under zero momentum (DART)",
        1e-7,
        "",
        ("tests/unit/test_controller_model.py::test_generalized_jacobian_by_finite_differences_under_zero_momentum",),
    ),
    "generalized_inertia": Row(
        "controller.computed_torque",
        "generalized inertia M* and drift, relative",
        "DART's forward dynamics of the same humanoid",
        1e-8,
        "",
        ("tests/unit/test_controller_model.py::test_generalized_inertia_and_coriolis_match_dart",),
    ),
    "capture_momentum": Row(
        "dynamics.dart (grasp)",
        "total momentum through the capture impact and 1-2 s welded (arm free, wheels spinning), relative",
        "conservation (no environment)",
        1e-11,
        "",
        (
            "tests/unit/test_grasp.py::test_impact_and_weld_conserve_momentum",
            "tests/unit/test_grasp.py::test_capture_with_spinning_wheels_conserves_momentum",
        ),
    ),
    "capture_rate": Row(
        "dynamics.dart (grasp)",
        "assembly rate and CoM velocity after the impact (arm locked)",
        "I_sys^-1 H and L / m from the momentum before it and the links' inertias",
        1e-12,
        "rad/s, m/s",
        ("tests/unit/test_grasp.py::test_post_capture_rate_is_momentum_over_assembly_inertia",),
    ),
    "capture_wrench": Row(
        "dynamics.dart (grasp)",
        "wrist wrench on a welded payload, relative",
        "Newton-Euler m a, I alpha + w x I w (central differences of the payload's motion)",
        1e-6,
        "",
        ("tests/unit/test_grasp.py::test_wrist_wrench_is_the_payloads_inertial_wrench",),
    ),
    "pinocchio_dart": Row(
        "dynamics.pinocchio",
        "every output, 1-3 s in orbit: the demo's humanoid (links, LVLH frame, IMU), the "
        "servicer (wheels, drag), prismatic and mimic joints, a joint on its stop, a capture's weld; relative",
        "dynamics.dart (DART's forward dynamics, the same integrator)",
        1e-9,
        "",
        tuple(
            f"tests/unit/test_dynamics_engines.py::{t}"
            for t in (
                "test_demo_humanoid_every_output_agrees",
                "test_servicer_with_wheels_and_drag_agrees",
                "test_prismatic_joints_and_a_mimic_finger_agree",
                "test_a_joint_resting_on_its_limit_agrees",
                "test_capture_grasp_and_weld_agree",
            )
        )
        + (
            "tests/unit/test_dynamics_srp.py::test_engines_agree_with_srp_on",
            "tests/unit/test_dynamics_third_body.py::test_engines_agree_with_third_bodies_on",
        ),
    ),
    "imu_specific_force": Row(
        "dynamics.dart (imu)",
        "specific force at the base origin, in orbit and not, relative",
        "central differences of the base velocity minus the tidal gravity there",
        1e-6,
        "",
        ("tests/unit/test_grasp.py::test_imu_reads_the_base_rate_and_non_gravitational_acceleration",),
    ),
    "fiducial_position": Row(
        "estimator.fiducial",
        "grasp frame's position in E from a 640x480 image, 0.1-1 m, pixel noise 2/255",
        "the pose the pictures were drawn at (OpenCV homography warp; ray cast of the target's marker meshes)",
        4e-3,
        "m",
        tuple(
            f"tests/unit/test_fiducial_estimator.py::{t}"
            for t in (
                "test_pose_from_warped_marker_pictures",
                "test_pose_from_the_committed_marker_meshes",
                "test_a_distorted_lens_is_solved_with_its_distortion",
            )
        ),
    ),
    "fiducial_attitude": Row(
        "estimator.fiducial",
        "grasp frame's attitude in E, the same images",
        "the pose the pictures were drawn at",
        0.6,
        "deg",
        tuple(
            f"tests/unit/test_fiducial_estimator.py::{t}"
            for t in (
                "test_pose_from_warped_marker_pictures",
                "test_pose_from_the_committed_marker_meshes",
                "test_a_distorted_lens_is_solved_with_its_distortion",
            )
        ),
    ),
    "gravity_harmonics_basilisk": Row(
        "space.gravity",
        "harmonic field (J2, J2-J6, 20 x 20 GGM03S) at 5 ITRF points, whole and less the point mass, relative",
        "Basilisk SphericalHarmonicsGravityModel, same coefficient file",
        1e-12,
        "",
        ("tests/unit/test_space_gravity.py::test_harmonic_field_matches_basilisk",),
    ),
    "gravity_j2_closed_form": Row(
        "space.gravity",
        "degree-2 zonal sum vs the closed-form J2 acceleration, relative",
        "textbook J2 formula (Vallado eq. 8-30)",
        1e-14,
        "",
        ("tests/unit/test_space_gravity.py::test_j2_term_equals_the_closed_form",),
    ),
    "gravity_third_body_exact": Row(
        "space.gravity",
        "Sun and Moon acceleration (Battin's form) at LEO, GEO, HEO, relative",
        "the direct difference in rational arithmetic",
        1e-14,
        "",
        ("tests/unit/test_space_gravity.py::test_third_body_matches_extended_precision_and_basilisk",),
    ),
    "gravity_third_body_tidal_exact": Row(
        "dynamics.environment",
        "Sun's and Moon's differential pull on links 1-100 m from the orbit point, relative",
        "the subtraction of the two pulls in rational arithmetic",
        1e-12,
        "",
        (
            "tests/unit/test_space_gravity.py::test_third_body_tidal_term_per_link_matches_a_direct_subtraction_in_extended_precision",
        ),
    ),
    "gravity_third_body_basilisk": Row(
        "space.gravity",
        "Sun and Moon acceleration, relative, over max(1, Basilisk's own cancellation bound / 1e-12)",
        "Basilisk GravityEffector's sum of PointMassGravityModel pulls, same positions",
        1e-12,
        "",
        ("tests/unit/test_space_gravity.py::test_third_body_matches_extended_precision_and_basilisk",),
    ),
    "gravity_trajectory_basilisk": Row(
        "orbit.numerical",
        "one-day LEO position, J2-J6 + Sun + Moon + drag (one exponential layer) + SRP (conical "
        "eclipse), RK4 10 s, drag's and SRP's inputs held over each step as Basilisk's modules give them (largest error)",
        "Basilisk Spacecraft (RK4 10 s) with DragDynamicEffector, exponentialAtmosphere, zeroWindModel, "
        "radiationPressure, eclipse; same field, rotation, Sun/Moon and constants",
        1e-3,
        "m",
        ("tests/unit/test_space_gravity.py::test_one_day_trajectory_matches_basilisk",),
    ),
    "numerical_trajectory_step": Row(
        "orbit.numerical",
        "the same day with drag and SRP evaluated at every RK4 stage (orbit.numerical's way), "
        "RK4 10 s (largest distance)",
        "itself at RK4 5 s (16x smaller error)",
        1.0,
        "m",
        (
            "tests/unit/test_space_gravity.py::test_drag_and_srp_at_every_stage_keep_rk4s_accuracy_that_held_inputs_lose",
        ),
    ),
    "numerical_two_body": Row(
        "orbit.numerical",
        "point mass (degree 0) over 93 min, e = 0.02, RK4 5 s (largest position error)",
        "the Kepler ellipse of the same elements (orbit.kepler's closed form)",
        0.01,
        "m",
        ("tests/unit/test_space_gravity.py::test_point_mass_orbit_equals_the_kepler_ellipse",),
    ),
    "ephemeris_sun_de440": Row(
        "space.ephemeris",
        "Earth -> Sun (ERFA epv00), 2023-2033 (largest error)",
        "JPL DE440 (jplephem)",
        1e4,
        "m",
        ("tests/unit/test_space_gravity.py::test_ephemeris_erfa_agrees_with_de440",),
    ),
    "ephemeris_moon_de440": Row(
        "space.ephemeris",
        "Earth -> Moon (ERFA moon98), 2023-2033 (largest error)",
        "JPL DE440 (jplephem)",
        3.2e4,
        "m",
        ("tests/unit/test_space_gravity.py::test_ephemeris_erfa_agrees_with_de440",),
    ),
    "srp_eclipse_basilisk": Row(
        "space.eclipse (conical)",
        "illumination factor: Earth and Moon umbra, penumbra (LEO, GEO, lunar), full sun, relative",
        "Basilisk eclipse (the same Sun, Moon positions and radii)",
        1e-9,
        "",
        ("tests/unit/test_space_srp.py::test_conical_eclipse_factor_matches_basilisk",),
    ),
    "srp_cannonball_basilisk": Row(
        "space.srp (cannonball)",
        "SRP force, LEO to cislunar, eclipse factor 1 and 0.37, relative",
        "Basilisk radiationPressure (cannonball; its flux and AU)",
        1e-9,
        "",
        ("tests/unit/test_space_srp.py::test_cannonball_force_matches_basilisk_radiation_pressure",),
    ),
    "srp_facets_basilisk": Row(
        "space.srp (facets)",
        "SRP force and torque of 6 facets, 4 attitudes, relative",
        "Basilisk facetSRPDynamicEffector (its flux and AU)",
        1e-9,
        "",
        ("tests/unit/test_space_srp.py::test_facet_force_and_torque_match_basilisk_facet_srp",),
    ),
    "srp_links": Row(
        "dynamics.dart, dynamics.pinocchio (srp)",
        "SRP force and torque per link (servicer: facets on the bus and "
        "a welded link, cannonballs on two arm links), relative",
        "space.srp and space.eclipse on each link's output pose (no kernel frames)",
        1e-9,
        "",
        tuple(
            f"tests/unit/test_dynamics_srp.py::{t}"
            for t in ("test_link_srp_wrenches_are_the_facets_and_cannonballs_on_the_link_poses",)
        ),
    ),
    "third_body_links": Row(
        "dynamics.dart, dynamics.pinocchio (third_bodies)",
        "Sun's and Moon's tidal force per link (servicer: a "
        "welded link, a tumble, 3-5 m off the orbit point), relative; and the two engines' after 0.3 s",
        "environment.third_body_tidal_acceleration and the subtraction of the two pulls in extended precision, "
        "on each link's output pose (no kernel frames)",
        1e-9,
        "",
        tuple(
            f"tests/unit/test_dynamics_third_body.py::{t}"
            for t in (
                "test_link_third_body_forces_are_the_tidal_form_on_the_link_poses",
                "test_engines_agree_with_third_bodies_on",
            )
        ),
    ),
    "geomagnetic_dipole": Row(
        "space.geomagnetic (dipole)",
        "field vector, 8 points 400 km to GEO, 2025-2029, general Earth orientations",
        "Basilisk magneticFieldCenteredDipole (its Earth coefficients; the same ECI -> ECEF matrix)",
        1e-6,
        "nT",
        ("tests/unit/test_space_geomagnetic.py::test_dipole_field_matches_basilisk",),
    ),
    "geomagnetic_wmm": Row(
        "space.geomagnetic (wmm)",
        "field vector, the same 8 points and dates",
        "Basilisk magneticFieldWMM (WMM2025.COF; the same ECI -> ECEF matrix)",
        1.0,
        "nT",
        ("tests/unit/test_space_geomagnetic.py::test_wmm_field_matches_basilisk",),
    ),
    "mtb_torque": Row(
        "dynamics (magnetorquers)",
        "torque m x B of four saturating rods, general attitude, relative",
        "Basilisk MtbEffector",
        1e-12,
        "",
        ("tests/unit/test_space_geomagnetic.py::test_magnetorquer_torque_matches_basilisk_mtb_effector",),
    ),
    "mtb_dynamics": Row(
        "dynamics.dart, dynamics.pinocchio (magnetorquers)",
        "angular acceleration m x B adds to a tumbling rigid body (y saturated), relative",
        "I^-1 (m x B), B from the field model at the base, R_W_base m",
        1e-9,
        "",
        ("tests/component/test_magnetic_dynamics.py::test_magnetorquer_torque_drives_both_engines",),
    ),
}

_measured: dict[str, list[float]] = {}


def check(key: str, measured: float) -> None:
    """Record ``measured`` for the row ``key`` and fail (AssertionError) above its tolerance."""
    row = ROWS[key]
    _measured.setdefault(key, []).append(float(measured))
    assert measured <= row.tolerance, (
        f"{key}: measured {_figure(measured, row.unit)}, expected at most "
        f"{_figure(row.tolerance, row.unit)} ({row.quantity}; against {row.reference})"
    )


def _figure(value: float, unit: str) -> str:
    """2 significant digits; exponent form (``1e-4``, ``7.6e-5``) below 0.01."""
    if value != 0 and abs(value) < 1e-2:
        mantissa, exponent = f"{value:.1e}".split("e")
        text = f"{mantissa.removesuffix('.0')}e{int(exponent)}"
    else:
        text = f"{value:.2g}"
    return f"{text} {unit}".strip()


def table(measured: dict[str, list[float]]) -> str:
    lines = ["| module | quantity | reference | tolerance | measured |", "|---|---|---|---|---|"]
    for key, row in ROWS.items():
        got = _figure(max(measured[key]), row.unit) if key in measured else "not run"
        cells = [row.module, row.quantity, row.reference, _figure(row.tolerance, row.unit), got]
        lines.append("| " + " | ".join(cell.replace("|", "\\|") for cell in cells) + " |")
    return "\n".join(lines)


def write_readme(text: str, readme: Path = ROOT / "docs" / "reference" / "validation.md") -> None:
    content = readme.read_text()
    if README_START not in content or README_END not in content:
        raise SystemExit(f"{readme}: no '{README_START}' ... '{README_END}' markers to write the table between")
    head, rest = content.split(README_START, 1)
    tail = rest.split(README_END, 1)[1]
    readme.write_text(f"{head}{README_START}\n{text}\n{README_END}{tail}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tests.validation", description=__doc__.splitlines()[0])
    parser.add_argument("--readme", action="store_true", help="write the table into docs/reference/validation.md")
    args = parser.parse_args(argv)
    import pytest

    from tests import validation  # the module the tests record into (this file runs as __main__)

    tests = sorted({t for row in ROWS.values() for t in row.tests})
    start = time.monotonic()
    status = pytest.main(["-q", "-p", "no:cacheprovider", "--rootdir", str(ROOT), *[str(ROOT / t) for t in tests]])
    text = table(validation._measured)
    print(
        f"\n{text}\n\n{len(tests)} tests in {time.monotonic() - start:.0f} s"
        + ("" if status == 0 else f"; pytest exit status {int(status)}: a check failed (above)")
    )
    missing = [k for k in ROWS if k not in validation._measured]
    if missing:
        print(f"rows not measured: {', '.join(missing)}", file=sys.stderr)
    if args.readme and status == 0 and not missing:
        write_readme(text)
        print("written into docs/reference/validation.md")
    return 0 if status == 0 and not missing else 1


if __name__ == "__main__":
    sys.exit(main())
