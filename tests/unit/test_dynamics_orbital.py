"""Orbital environment of dynamics.dart against closed forms: gravity-gradient pitch libration,
Clohessy-Wiltshire relative motion, drag deceleration, and the environment functions.

The reference orbit is circular and computed here in closed form (radius a, mean motion n):
r = a (cos nt, sin nt, 0), LVLH = Rz(nt) (x radial, y along-track, z orbit normal).
"""
import math
from pathlib import Path

import numpy as np

from components.constants import EARTH_RATE, MU_EARTH, R_EARTH
from components.dynamics import environment as env
from components.dynamics.world import BodySpec, OrbitalWorld
from components.rotations import quat_to_matrix

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


def test_gravity_gradient_pitch_libration_frequency():
    """Rigid box (Ix 33.33 < Iy = Iz 59.33 kg m^2) in a 6778 km circular orbit, started aligned
    with LVLH, co-rotating, pitched 1 deg about the orbit normal: it librates at
    w = n sqrt(3 (Iy - Ix) / Iz). Measured from the zero crossings of the pitch angle over
    ~2.5 libration periods, rk4 with 10 s steps: within 1 %."""
    a = 6778e3
    n = math.sqrt(MU / a**3)
    Ix, Iy, Iz = 200 / 12 * 2.0, 200 / 12 * (1.6**2 + 1.0), 200 / 12 * (1.6**2 + 1.0)
    expected = n * math.sqrt(3 * (Iy - Ix) / Iz)
    half = math.radians(1.0) / 2
    spec = BodySpec("sat", TARGET, frame="lvlh", orientation=np.array([0.0, 0.0, math.sin(half), math.cos(half)]))
    world = OrbitalWorld([spec], tidal_force=True, gravity_gradient=True)
    h = 10.0
    steps = int(2.5 * 2 * math.pi / expected / h)

    def pitch(w, t):
        R_WB = quat_to_matrix(w.outputs("sat")["orientation"])
        R_WL = quat_to_matrix(circular(a, t)[2])
        x_L = R_WL.T @ R_WB[:, 0]
        return math.atan2(x_L[1], x_L[0])

    theta = run(world, a, h, steps, pitch)
    t = np.arange(len(theta)) * h
    crossings = [t[i] - theta[i] * h / (theta[i + 1] - theta[i])
                 for i in range(len(theta) - 1) if theta[i] * theta[i + 1] < 0]
    measured = math.pi / np.mean(np.diff(crossings))
    error = abs(measured / expected - 1)
    print(f"libration: expected {expected:.6e} rad/s, measured {measured:.6e} rad/s "
          f"({len(crossings)} crossings), error {error:.1e}; amplitude {math.degrees(np.abs(theta).max()):.3f} deg")
    assert len(crossings) >= 4
    assert error < 0.01
    assert abs(math.degrees(np.abs(theta).max()) - 1.0) < 0.01


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
    assert error < 0.01


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
    assert error < 0.01
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
    I = np.diag([10.0, 25.0, 30.0])
    rho = r * np.array([[math.cos(th), math.sin(th), 0.0]])
    tau = env.gravity_gradient_torque(rho, I[None], MU)[0]
    assert np.allclose(tau, [0, 0, 3 * MU / r**3 * (25.0 - 10.0) * math.sin(th) * math.cos(th)], rtol=1e-12, atol=1e-20)


def test_reference_propagation_within_a_step():
    """Third-order Taylor series of the two-body motion: 5 mm and 2 mm/s after 10 s in LEO."""
    a = 6778e3
    r0, v0, _, _ = circular(a, 0.0)
    for s in (1.0, 10.0):
        r, v = env.propagate_reference(r0, v0, s)
        r_ref, v_ref, _, _ = circular(a, s)
        assert np.linalg.norm(r - r_ref) < 1e-2 * (s / 10) ** 4 and np.linalg.norm(v - v_ref) < 3e-3 * (s / 10) ** 3


def test_exponential_atmosphere_table():
    atmosphere = env.ExponentialAtmosphere()
    assert atmosphere.density(400e3) == 3.725e-12
    assert atmosphere.density(0.0) == 1.225
    assert math.isclose(atmosphere.density(425e3), 3.725e-12 * math.exp(-25 / 58.515), rel_tol=1e-12)
    single = env.ExponentialAtmosphere(single=(400e3, 4e-12, 60e3))
    assert math.isclose(single.density(460e3), 4e-12 / math.e, rel_tol=1e-12)
