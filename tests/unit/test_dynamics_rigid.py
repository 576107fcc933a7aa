"""A rigid body's (no joints) RK4 step in one compiled call (``pinocchio_kernels.rk4_rigid``) against the
step through Pinocchio's ABA (``PinocchioBody.rigid = None``, the reference) and against DART.

The two solve the same equations in other orders: their accelerations agree to rounding and their
steps, over a tumbling, gravity-gradient-driven run, to ~1e-12 (relative; the bound below). The
rigid bodies: the libration config's box (CoM at the link origin, principal axes) and an
off-centre one (CoM 0.3 m from the base origin, a full inertia tensor, a second link on a fixed
joint: Pinocchio merges it into the base, the environment acts on both links). And both against
Basilisk's (tests/basilisk/rigid_body.json): configs/gravity_gradient_libration.yaml's box at 1 s
steps, its orbit from orbit.kepler, against Basilisk's spacecraft with the same start."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from components.dynamics.world import BodySpec, OrbitalWorld
from components.rotations import quat_to_matrix
from components.testing.harness import Harness

ROOT = Path(__file__).resolve().parents[2]
OFF_CENTRE = """<?xml version="1.0"?>
<robot name="lopsided">
  <link name="bus">
    <inertial>
      <origin xyz="0.3 -0.1 0.05" rpy="0.2 -0.3 0.5"/>
      <mass value="150"/>
      <inertia ixx="40" ixy="2" ixz="-1.5" iyy="55" iyz="0.8" izz="62"/>
    </inertial>
  </link>
  <link name="boom">
    <inertial>
      <origin xyz="1.2 0 0" rpy="0 0 0"/>
      <mass value="8"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="3" iyz="0" izz="3"/>
    </inertial>
  </link>
  <joint name="boom_mount" type="fixed">
    <parent link="bus"/><child link="boom"/>
    <origin xyz="0.8 0.2 0" rpy="0 0.4 0"/>
  </joint>
</robot>
"""
R0 = 6778e3
N = np.sqrt(3.986004418e14 / R0**3)


def world(urdf, engine: str = "pinocchio", rigid: bool = True) -> OrbitalWorld:
    spec = BodySpec(
        "sat",
        urdf,
        frame="lvlh",
        position=np.array([0.4, -0.2, 0.1]),
        orientation=np.array([0.1, -0.2, 0.3, 0.9]) / np.linalg.norm([0.1, -0.2, 0.3, 0.9]),
        twist=np.array([0.01, -0.02, 0.005, 0.02, -0.01, 0.03]),
    )
    w = OrbitalWorld([spec], engine=engine, integrator="rk4")
    if not rigid:
        w.bodies["sat"].rigid = None  # Pinocchio's ABA: the reference
    w.set_orbit([R0, 0.0, 0.0], [0.0, R0 * N, 0.0], [0.0, 0.0, 0.0, 1.0], [0.0, 0.0, N])
    w.reset_bodies()
    return w


@pytest.fixture(params=["box", "off_centre"])
def urdf(request, tmp_path):
    if request.param == "box":
        return ROOT / "models" / "target.urdf"
    path = tmp_path / "lopsided.urdf"
    path.write_text(OFF_CENTRE)
    return path


def test_a_rigid_body_steps_in_one_call(urdf):
    assert world(urdf).bodies["sat"].rigid is not None
    assert world(ROOT / "models" / "humanoid_torso.urdf").bodies["sat"].rigid is None  # joints: Pinocchio's ABA


def test_rigid_acceleration_is_pinocchios_aba(urdf):
    """At random states and forces the compiled rigid body's accelerations are ABA's to 1e-13
    (relative to their largest)."""
    from components.dynamics import pinocchio_kernels as kernels

    body = world(urdf).bodies["sat"]
    rng = np.random.default_rng(7)
    for _ in range(50):
        x = np.concatenate([rng.uniform(-3.0, 3.0, 3), rng.normal(size=3)])
        v = rng.normal(size=6)
        body.set_state(x, v)
        body.tau[:] = rng.normal(size=6) * 10.0
        reference = body.forward_dynamics(None)  # Pinocchio's ABA
        a = np.empty(6)
        kernels.rigid_acceleration(body.rigid, x, v, body.tau, a)
        np.testing.assert_allclose(a, reference, rtol=0, atol=1e-13 * np.abs(reference).max())


@pytest.mark.parametrize("h", [0.1, 1.0])
def test_rigid_steps_agree_with_pinocchios(urdf, h):
    """2000 steps of a tumbling body in orbit (tidal force, gravity gradient): the one-call steps
    and the steps through Pinocchio's ABA end within 1e-12 (relative) of each other, in the state
    and in every output; DART's, stepped alike, within 1e-11."""
    fast, slow, dart = world(urdf), world(urdf, rigid=False), world(urdf, engine="dart")
    for w in (fast, slow, dart):
        for _ in range(2000):
            w.step(h)
    for key, value in slow.get_state().items():
        scale = np.abs(value).max(initial=1.0)
        np.testing.assert_allclose(fast.get_state()[key], value, rtol=0, atol=1e-12 * scale, err_msg=key)
        np.testing.assert_allclose(dart.get_state()[key], value, rtol=0, atol=1e-11 * scale, err_msg=key)
    for key, value in slow.outputs("sat").items():
        scale = np.abs(value).max(initial=1.0)
        np.testing.assert_allclose(fast.outputs("sat")[key], value, rtol=0, atol=1e-12 * scale, err_msg=key)


def libration(rigid: bool) -> tuple[dict, np.ndarray]:
    """The libration config's box (dynamics.pinocchio) driven by its orbit.kepler for Basilisk's
    case: (the start as Basilisk's case gives it, q_W_base every ``sample_every`` steps)."""
    case = json.loads((ROOT / "tests" / "basilisk" / "rigid_body.json").read_text())["case"]
    config_path = ROOT / "configs" / "gravity_gradient_libration.yaml"
    config = yaml.safe_load(config_path.read_text())
    epoch = str(config["run"]["epoch"])
    orbit = Harness("orbit.kepler", config["components"]["orbit"]["parameters"], epoch=epoch)
    dynamics = Harness(
        "dynamics.pinocchio", config["components"]["dynamics"]["parameters"], epoch=epoch, config_dir=config_path.parent
    )
    if not rigid:
        dynamics.component.world.bodies["target"].rigid = None
    h = case["step_ns"]
    dynamics.inputs.update(orbit.initialize())
    out = dynamics.initialize()
    twist, q = out["target.twist"], out["target.orientation"]
    start = {
        "r": dynamics.inputs["r_eci"],
        "v": dynamics.inputs["v_eci"] + twist[:3],
        "q": q,
        "w": quat_to_matrix(q).T @ twist[3:],
    }
    samples = [q.copy()]
    for k in range(case["steps"]):
        out = dynamics.step(h)
        dynamics.inputs.update(orbit.step(h))
        if (k + 1) % case["sample_every"] == 0:
            samples.append(out["target.orientation"].copy())
    return start, np.array(samples)


def angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation (rad) between matching rows of two arrays of quaternions [x, y, z, w]:
    2 asin |vec(a^-1 b)| (exact for small angles)."""
    vec = a[:, 3:] * b[:, :3] - b[:, 3:] * a[:, :3] - np.cross(a[:, :3], b[:, :3])
    return 2.0 * np.arcsin(np.minimum(np.linalg.norm(vec, axis=1), 1.0))


def test_rigid_steps_agree_with_basilisk():
    """Over 20 min of the libration (1200 steps of 1 s; the box turns 77 deg in ECI) both steps
    stay within 1e-12 rad of Basilisk's attitude (measured: 7e-15), and of each other."""
    basilisk = json.loads((ROOT / "tests" / "basilisk" / "rigid_body.json").read_text())
    case = basilisk["case"]
    start, fast = libration(rigid=True)
    _, reference = libration(rigid=False)
    for key in ("r", "v", "q", "w"):  # Basilisk started where Zenorbit starts
        np.testing.assert_allclose(start[key], case[key], rtol=0, atol=1e-12 * np.abs(case[key]).max(), err_msg=key)
    q = np.array(basilisk["q"])
    assert len(q) == len(fast)
    assert angles(fast, q).max() < 1e-12
    assert angles(reference, q).max() < 1e-12
    assert angles(fast, reference).max() < 1e-12
    assert angles(q[:1], q[-1:])[0] > 0.5  # (the box did turn)


def test_the_rigid_kernel_is_compiled_at_construction(monkeypatch):
    """As the other kernels (tests/component/test_dynamics_component.py): a fresh dispatcher holds
    its signature once the world is built, and steps with and without the environment compile
    nothing more."""
    import numba

    from components.dynamics import pinocchio_kernels

    kernel = numba.njit(cache=True)(pinocchio_kernels.rk4_rigid.py_func)
    monkeypatch.setattr(pinocchio_kernels, "rk4_rigid", kernel)
    w = world(ROOT / "models" / "target.urdf")
    compiled = list(kernel.signatures)
    assert compiled
    w.step(1.0)
    w.set_orbit(np.zeros(3), np.zeros(3))  # no orbit: no environment
    w.step(1.0)
    assert list(kernel.signatures) == compiled
