"""Orbital environment of dynamics.dart against closed forms: gravity-gradient libration in roll,
pitch and yaw, Clohessy-Wiltshire relative motion, drag deceleration, the atmosphere against
USSA-76, and the environment functions.

The reference orbit is circular and computed here in closed form (radius a, mean motion n):
r = a (cos nt, sin nt, 0), LVLH = Rz(nt) (x radial, y along-track, z orbit normal).
"""

import math
from pathlib import Path

import numpy as np

from components.constants import EARTH_RATE, MU_EARTH, R_EARTH
from components.dynamics import environment as env
from components.dynamics import link_forces
from components.dynamics.world import BodySpec, OrbitalWorld
from components.rotations import quat_to_matrix
from tests import validation

ROOT = Path(__file__).resolve().parents[2]
TARGET = ROOT / "models" / "target.urdf"
MU = MU_EARTH


def circular(a: float, t: float):
    """r_eci, v_eci, q_eci_lvlh, w_lvlh of an equatorial circular orbit at time t."""
    n = math.sqrt(MU / a**3)
    th = n * t
    r = a * np.array([math.cos(th), math.sin(th), 0.0])
    v = a * n * np.array([-math.sin(th), math.cos(th), 0.0])
    q = np.array([0.0, 0.0, math.sin(th / 2), math.cos(th / 2)])
    return r, v, q, np.array([0.0, 0.0, n])


def run(world: OrbitalWorld, a: float, h: float, steps: int, sample):
    world.set_orbit(*circular(a, 0.0))
    world.reset_bodies()
    samples = [sample(world, 0.0)]
    for k in range(steps):
        world.set_orbit(*circular(a, k * h))
        world.step(h)
        samples.append(sample(world, (k + 1) * h))
    return np.array(samples)


SATELLITE = """<?xml version="1.0"?>
<robot name="sat"><link name="sat"><inertial><origin xyz="0 0 0" rpy="0 0 0"/><mass value="300"/>
<inertia ixx="{0}" ixy="0" ixz="0" iyy="{1}" iyz="0" izz="{2}"/></inertial></link></robot>
"""


def test_gravity_gradient_libration_in_roll_pitch_and_yaw(tmp_path):
    """A rigid satellite with three distinct principal inertias, 200 (radial), 300 (along-track),
    450 kg m^2 (orbit normal), in a 6778 km circular orbit, started at rest in LVLH with small roll,
    pitch and yaw. Reference: the linearized equations of a gravity-gradient satellite (Wie,
    Space Vehicle Dynamics and Control, Sec. 7.2; x along-track (roll), y negative orbit normal
    (pitch), z nadir (yaw), J1 J2 J3 about them):
        J1 phi''   - n (J1 - J2 + J3) psi' + 4 n^2 (J2 - J3) phi = 0
        J2 theta''                         + 3 n^2 (J1 - J3) theta = 0
        J3 psi''   + n (J1 - J2 + J3) phi' +   n^2 (J2 - J1) psi = 0
    solved exactly (matrix exponential). Roll and yaw are coupled; their frequencies solve
    W^4 - n^2 (1 + 3 k1 + k1 k3) W^2 + 4 n^4 k1 k3 = 0 (k1 = (J2 - J3)/J1, k3 = (J2 - J1)/J3):
    1.840 n and 0.859 n here; pitch librates at n sqrt(3 (J1 - J3)/J2) = 0.816 n.
    Amplitudes of 0.05, 0.04, 0.025 deg keep the nonlinear terms (they grow with the amplitude:
    9 % at 1 deg) well below the 1 % tolerance. rk4, 10 s steps, three orbits: each angle within
    1 % of the largest amplitude of all three (measured 0.5 %)."""
    from scipy.linalg import expm
    from scipy.spatial.transform import Rotation

    radial, along_track, normal = 200.0, 300.0, 450.0
    urdf = tmp_path / "sat.urdf"
    urdf.write_text(SATELLITE.format(radial, along_track, normal))
    J1, J2, J3 = along_track, normal, radial
    a = 6778e3
    n = math.sqrt(MU / a**3)
    c = n * (J1 - J2 + J3)
    A = np.zeros((6, 6))  # state: phi, theta, psi and their rates
    A[:3, 3:] = np.eye(3)
    A[3, 0], A[3, 5] = -4 * n * n * (J2 - J3) / J1, c / J1
    A[4, 1] = -3 * n * n * (J1 - J3) / J2
    A[5, 2], A[5, 3] = -n * n * (J2 - J1) / J3, -c / J3
    k1, k3 = (J2 - J3) / J1, (J2 - J1) / J3
    b = 1 + 3 * k1 + k1 * k3
    coupled = np.sqrt([(b + math.sqrt(b * b - 16 * k1 * k3)) / 2, (b - math.sqrt(b * b - 16 * k1 * k3)) / 2]) * n
    frequencies = np.unique(np.abs(np.linalg.eigvals(A).imag).round(12))
    np.testing.assert_allclose(frequencies, np.sort([*coupled, n * math.sqrt(3 * (J1 - J3) / J2)]), rtol=1e-9)

    x0 = np.radians([0.05, 0.04, 0.025, 0.0, 0.0, 0.0])
    # Wie's axes in LVLH (x radial, y along-track, z orbit normal): roll = y, pitch = -z, yaw = -x
    to_lvlh = np.array([[0, 0, -1], [1, 0, 0], [0, -1, 0]], dtype=float)
    spec = BodySpec("sat", urdf, frame="lvlh", orientation=Rotation.from_rotvec(to_lvlh @ x0[:3]).as_quat())
    world = OrbitalWorld([spec], tidal_force=True, gravity_gradient=True)
    h = 10.0
    steps = int(3 * 2 * math.pi / n / h)

    def angles(w, t):
        R_LB = quat_to_matrix(circular(a, t)[2]).T @ quat_to_matrix(w.outputs("sat")["orientation"])
        return to_lvlh.T @ Rotation.from_matrix(R_LB).as_rotvec()

    simulated = run(world, a, h, steps, angles)
    closed_form = np.array([(expm(A * k * h) @ x0)[:3] for k in range(steps + 1)])
    error = np.abs(simulated - closed_form).max(axis=0) / x0[:3].max()
    print(
        f"libration roll/yaw at {coupled[0] / n:.4f} n and {coupled[1] / n:.4f} n; error (fraction of "
        f"the amplitude) roll {error[0]:.1e}, pitch {error[1]:.1e}, yaw {error[2]:.1e}"
    )
    assert np.abs(simulated).max(axis=0).min() > 0.5 * x0[2]  # every axis moves
    validation.check("libration", error.max())


def test_tidal_force_follows_clohessy_wiltshire():
    """A small body released 10 m radially at rest in LVLH (6778 km circular orbit): after a
    quarter orbit its LVLH position matches x = (4 - 3 cos nt) x0, y = 6 (sin nt - nt) x0
    within 1 % of its displacement."""
    a, x0 = 6778e3, 10.0
    n = math.sqrt(MU / a**3)
    spec = BodySpec("probe", TARGET, frame="lvlh", position=np.array([x0, 0.0, 0.0]))
    world = OrbitalWorld([spec], tidal_force=True, gravity_gradient=False)
    h = 5.0
    steps = int(round(math.pi / 2 / n / h))

    def lvlh_position(w, t):
        return quat_to_matrix(circular(a, t)[2]).T @ w.outputs("probe")["position"]

    p = run(world, a, h, steps, lvlh_position)[-1]
    t = steps * h
    cw = np.array([(4 - 3 * math.cos(n * t)) * x0, 6 * (math.sin(n * t) - n * t) * x0, 0.0])
    displacement = np.linalg.norm(cw - [x0, 0, 0])
    error = np.linalg.norm(p - cw) / displacement
    print(f"CW after {t:.0f} s: simulated {p.round(3)}, CW {cw.round(3)}, error {error:.1e} of {displacement:.1f} m")
    validation.check("clohessy_wiltshire", error)


def test_drag_decelerates_along_track():
    """Box of 200 kg with A = 2 m^2, Cd 2.2 at the reference point of a 400 km circular
    equatorial orbit (table density 3.725e-12 kg/m^3 there): over 20 s its velocity in W grows
    along -v_rel at 1/2 rho Cd A |v_rel|^2 / m (v_rel: relative to the co-rotating atmosphere),
    within 1 %; the drag_force output is that force."""
    a = R_EARTH + 400e3
    spec = BodySpec("sat", TARGET, drag_area={"target": 2.0}, drag_cd=2.2)
    world = OrbitalWorld([spec], tidal_force=False, gravity_gradient=False, drag=True)
    h, steps = 1.0, 20
    twists = run(world, a, h, steps, lambda w, t: w.outputs("sat")["twist"][:3])
    r, v, _, _ = circular(a, steps * h / 2)
    v_rel = v - np.cross([0, 0, EARTH_RATE], r)
    expected = 0.5 * 3.725e-12 * 2.2 * 2.0 * (v_rel @ v_rel) / 200.0
    measured = -(twists[-1] - twists[0]) @ (v_rel / np.linalg.norm(v_rel)) / (steps * h)
    error = abs(measured / expected - 1)
    print(f"drag: expected {expected:.4e} m/s^2, measured {measured:.4e} m/s^2, error {error:.1e}")
    validation.check("drag", error)
    world.set_orbit(r, v)
    force = world.outputs("sat")["drag_force"]
    assert abs(np.linalg.norm(force) / (200.0 * expected) - 1) < 0.01


def test_tidal_acceleration_against_direct_and_linear_forms():
    R = np.array([6778e3, 1200e3, -300e3])
    r = np.linalg.norm(R)
    u = R / r
    tensor = MU / r**3 * (3 * np.outer(u, u) - np.eye(3))
    rng = np.random.default_rng(0)
    # far offsets: the direct difference is accurate, the forms agree to 1e-12
    d = rng.normal(size=(5, 3)) * 1e4
    direct = env.gravity(R + d) - env.gravity(R)
    assert np.allclose(env.tidal_acceleration(R, d), direct, rtol=1e-9, atol=0)
    # close offsets: the linear tidal tensor is exact to O(|d|/r); 1 mm offsets: 1e-9 relative
    for scale in (1.0, 1e-3):
        d = rng.normal(size=(5, 3)) * scale
        linear = d @ tensor.T
        rel = np.abs(env.tidal_acceleration(R, d) - linear).max() / np.abs(linear).max()
        assert rel < 1e-5 * scale + 1e-10


def test_gravity_gradient_torque_textbook():
    """Principal inertia, rho at angle th in the x-y plane: tau_z = 3 mu/r^3 (Iy - Ix) sin th cos th."""
    r, th = 7e6, 0.3
    inertia = np.diag([10.0, 25.0, 30.0])
    rho = r * np.array([[math.cos(th), math.sin(th), 0.0]])
    tau = env.gravity_gradient_torque(rho, inertia[None], MU)[0]
    assert np.allclose(tau, [0, 0, 3 * MU / r**3 * (25.0 - 10.0) * math.sin(th) * math.cos(th)], rtol=1e-12, atol=1e-20)


def test_reference_propagation_within_a_step():
    """Third-order Taylor series of the two-body motion: 5 mm and 2 mm/s after 10 s in LEO."""
    a = 6778e3
    r0, v0, _, _ = circular(a, 0.0)
    for s in (1.0, 10.0):
        r, v = link_forces.propagate_reference(r0, v0, s, MU)
        r_ref, v_ref, _, _ = circular(a, s)
        assert np.linalg.norm(r - r_ref) < 1e-2 * (s / 10) ** 4 and np.linalg.norm(v - v_ref) < 3e-3 * (s / 10) ** 3


def test_exponential_atmosphere_table():
    atmosphere = env.ExponentialAtmosphere()
    assert atmosphere.density(400e3) == 3.725e-12
    assert atmosphere.density(0.0) == 1.225
    assert math.isclose(atmosphere.density(425e3), 3.725e-12 * math.exp(-25 / 58.515), rel_tol=1e-12)
    single = env.ExponentialAtmosphere(single=(400e3, 4e-12, 60e3))
    assert math.isclose(single.density(460e3), 4e-12 / math.e, rel_tol=1e-12)


# U.S. Standard Atmosphere 1976 (NOAA, NASA, USAF), tabulated density (kg/m^3) by geometric
# altitude (km), as reprinted in Curtis, Orbital Mechanics for Engineering Students, Appendix.
US_STANDARD_ATMOSPHERE_1976 = {
    0: 1.225,
    25: 4.008e-2,
    30: 1.841e-2,
    40: 3.996e-3,
    50: 1.027e-3,
    60: 3.097e-4,
    70: 8.283e-5,
    80: 1.846e-5,
    90: 3.416e-6,
    100: 5.606e-7,
    110: 9.708e-8,
    120: 2.222e-8,
    130: 8.152e-9,
    140: 3.831e-9,
    150: 2.076e-9,
    180: 5.194e-10,
    200: 2.541e-10,
    250: 6.073e-11,
    300: 1.916e-11,
    350: 7.014e-12,
    400: 2.803e-12,
    450: 1.184e-12,
    500: 5.215e-13,
    600: 1.137e-13,
    700: 3.070e-14,
    800: 1.136e-14,
    900: 5.759e-15,
    1000: 3.561e-15,
}


def test_atmosphere_density_against_the_us_standard_atmosphere():
    """The exponential model (Vallado Table 8-4, from CIRA-72) against USSA-76, an independent
    model: within 12 % up to 200 km (measured 10 %, at 120 and 200 km) and 40 % above, where the
    two models assume different thermospheres (measured 36 %, at 350 km). A wrong band, a scale
    height in the wrong unit or an extrapolation error is a factor of e or more."""
    atmosphere = env.ExponentialAtmosphere()
    low, high = [], []
    for km, rho in US_STANDARD_ATMOSPHERE_1976.items():
        (low if km <= 200 else high).append(abs(atmosphere.density(km * 1e3) / rho - 1))
    print(f"density vs USSA-76: up to 200 km {max(low):.3f}, above {max(high):.3f} (relative)")
    validation.check("atmosphere_low", max(low))
    validation.check("atmosphere_high", max(high))
