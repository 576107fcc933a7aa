"""The Sun's and the Moon's tidal force on every link (``third_bodies``) in dynamics.dart and
dynamics.pinocchio: each link's force against ``environment.third_body_tidal_acceleration`` and the
subtraction of the two pulls in extended precision, both evaluated on the links' output poses (the
kernels' frames, anchors and tree are not used); the base's acceleration against the closed forms
along and across the Sun line; the IMU; both engines against each other; off by default."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from components.dynamics.environment import third_body_tidal_acceleration
from components.errors import ConfigError
from components.robots.urdf import read_urdf
from components.rotations import quat_to_matrix
from components.space import ephemeris
from components.space.gravity import MU_MOON, MU_SUN
from components.testing.harness import Harness
from tests import validation
from tests.unit.test_dynamics_engines import CONFIGS, MODELS, assert_agree, circular, run
from tests.unit.test_space_gravity import exact_third_body_difference

EPOCH = "2024-03-20T06:00:00Z"
MS = 1_000_000
MU = {"sun": MU_SUN, "moon": MU_MOON}
# the servicer off the orbit point (no link at a symmetric place), a welded link, a tumble
SERVICER = {
    "urdf": "../models/capture/servicer.urdf",
    "position": [3.0, -2.0, 1.5],
    "locked_joints": ["arm_5_joint"],
    "q": {"arm_2_joint": 0.6, "arm_3_joint": 1.0, "arm_5_joint": 0.4},
    "orientation": [0.2, -0.1, 0.3, 0.92],
    "twist": [0, 0, 0, 0.01, -0.02, 0.03],
}
PLATE = (
    '<robot name="plate"><link name="plate"><inertial><mass value="12.5"/><origin xyz="0 0 0"/>'
    '<inertia ixx="1.1" iyy="2.3" izz="3.1" ixy="0.1" ixz="0" iyz="0"/></inertial></link></robot>'
)


def servicer(engine: str, third_bodies=("sun", "moon"), **params) -> Harness:
    return Harness(
        f"dynamics.{engine}",
        {"third_bodies": list(third_bodies), "link_outputs": True, "bodies": {"servicer": SERVICER}, **params},
        config_dir=CONFIGS,
        epoch=EPOCH,
    )


def sun_and_moon(t_ns: int) -> dict[str, np.ndarray]:
    tt = ephemeris.Ephemeris(EPOCH).tt(t_ns)
    return {"sun": ephemeris.sun_position_eci(tt), "moon": ephemeris.moon_position_eci(tt)}


def relative(a, b) -> float:
    return float(np.linalg.norm(np.asarray(a) - b) / np.linalg.norm(b))


@pytest.mark.parametrize("engine", ["dart", "pinocchio"])
def test_link_third_body_forces_are_the_tidal_form_on_the_link_poses(engine):
    """After 5 steps of 1 ms (joint torques on): per link, m (a_3(R + d) - a_3(R)) summed over the
    Sun and the Moon, d the link's CoM from its output pose and URDF CoM, R the world's reference
    point then, the bodies at the step's start (held over a step)."""
    h = servicer(engine)
    out = run(h, 5)[-1]
    world = h.component.world
    R = world.reference(world.elapsed)[0]
    bodies = sun_and_moon(4 * MS)
    assert np.array_equal(world.sun_eci, bodies["sun"]) and np.array_equal(world.moon_eci, bodies["moon"])
    urdf = read_urdf(MODELS / "capture" / "servicer.urdf")
    positions = out["servicer.link_position"].reshape(-1, 3)
    rotations = quat_to_matrix(out["servicer.link_orientation"].reshape(-1, 4))
    got = out["servicer.third_body_force"].reshape(-1, 3)
    massive = [k for k, link in enumerate(urdf.links) if link.mass > 0.0]
    assert len(massive) >= 10 and not got[[k for k in range(len(urdf.links)) if k not in massive]].any()
    d = np.array([positions[k] + rotations[k] @ np.asarray(urdf.links[k].com) for k in massive])
    mass = np.array([urdf.links[k].mass for k in massive])
    expected = sum(third_body_tidal_acceleration(R, d, bodies[b], MU[b]) for b in MU) * mass[:, None]
    exact = (
        np.array(
            [
                sum(
                    exact_third_body_difference([Fraction(x) + Fraction(y) for x, y in zip(R, dk)], R, bodies[b], MU[b])
                    for b in MU
                )
                for dk in d
            ]
        )
        * mass[:, None]
    )  # R + d unrounded
    for n, k in enumerate(massive):
        validation.check("third_body_links", relative(got[k], expected[n]))
        validation.check("third_body_links", relative(got[k], exact[n]))
    assert np.linalg.norm(got, axis=1).max() > 1e-10  # the bus, 2 t at 4 m: ~3e-10 N


def test_base_accelerates_by_the_closed_forms_along_and_across_the_third_body_line(tmp_path):
    """One rigid link, CoM at its origin, no Earth terms: at d along the Sun line (x = R - s, from
    the Sun) the base's acceleration is 2 mu d / |x|^3 away from the Sun (toward it at -d); across
    it, -mu d / |x|^3 (toward the line); the Moon's likewise. The closed forms are first order in
    d / |x|: their own error 3/2 d / |x| (5e-11 for the Sun, 2e-8 for the Moon at 5 m)."""
    urdf = tmp_path / "plate.urdf"
    urdf.write_text(PLATE)
    r_eci = np.array([4.1e6, -5.2e6, 1.3e6])
    bodies = sun_and_moon(0)
    for engine in ("dart", "pinocchio"):
        for body, tolerance in (("sun", 1e-9), ("moon", 1e-7)):
            x = r_eci - bodies[body]
            u = x / np.linalg.norm(x)
            across = np.cross(u, [0.3, -0.4, 0.8])
            across /= np.linalg.norm(across)
            k = MU[body] / np.linalg.norm(x) ** 3
            for d, closed_form in (
                (5.0 * u, 2.0 * k * 5.0 * u),
                (-5.0 * u, -2.0 * k * 5.0 * u),
                (5.0 * across, -k * 5.0 * across),
            ):
                h = Harness(
                    f"dynamics.{engine}",
                    {
                        "third_bodies": [body],
                        "tidal_force": False,
                        "gravity_gradient": False,
                        "imu": ["plate"],
                        "bodies": {
                            "plate": {"urdf": str(urdf), "position": d.tolist(), "orientation": [0.3, -0.2, 0.1, 0.93]}
                        },
                    },
                    epoch=EPOCH,
                )
                h.inputs.update({**circular(0.0), "r_eci": r_eci})
                out = h.initialize()
                a = h.component.world.forward_dynamics("plate")["dv_W_base"][:3]
                assert relative(a, closed_form) < tolerance, (engine, body, d)
                # the IMU senses no gravity: the world's third-body pull at the base origin is taken out
                assert np.linalg.norm(out["plate.specific_force"]) <= 1e-9 * np.linalg.norm(a), (engine, body)


def test_engines_agree_with_third_bodies_on():
    dart = run(servicer("dart"), 300)
    pinocchio = run(servicer("pinocchio"), 300)
    force_d, force_p = dart[-1]["servicer.third_body_force"], pinocchio[-1]["servicer.third_body_force"]
    assert np.abs(force_d).max() > 1e-10
    validation.check("third_body_links", np.abs(force_p - force_d).max() / np.abs(force_d).max())
    validation.check("pinocchio_dart", assert_agree(pinocchio, dart, "servicer with the Sun and the Moon"))


def test_third_bodies_move_the_bodies_and_are_off_by_default():
    """Off by default: no output, the kernels' GMs zero. On (the Earth's terms off): the linear
    momentum changes by the sum of the links' third-body forces over time (the term is in every
    stage, not only in the outputs); off, it stays."""
    default = Harness("dynamics.dart", {"link_outputs": True, "bodies": {"servicer": SERVICER}}, config_dir=CONFIGS)
    assert default.params["third_bodies"] == [] and not default.component.world.environment.third().any()
    assert "servicer.third_body_force" not in [v.name for v in default.output_layout.variables]
    earth_off = {"tidal_force": False, "gravity_gradient": False}
    change = {}
    for name, bodies in (("off", ()), ("on", ("sun", "moon"))):
        h = servicer("pinocchio", third_bodies=bodies, **earth_off)
        history = run(h, 100)
        momentum = np.array([out["servicer.momentum"][:3] for out in history])
        change[name] = momentum[-1] - momentum[0]
        if bodies:
            forces = np.array([out["servicer.third_body_force"].reshape(-1, 3).sum(axis=0) for out in history])
            impulse = 0.5 * (forces[:-1] + forces[1:]).sum(axis=0) * 1e-3  # over the same 99 steps
    assert np.abs(change["off"]).max() < 1e-13
    assert relative(change["on"], impulse) < 1e-3, (change, impulse)


def test_third_bodies_settings_are_checked():
    with pytest.raises(ConfigError, match=r"third_bodies\[1\]: expected one of sun, moon, got 'jupiter'"):
        servicer("dart", third_bodies=("sun", "jupiter"))
    with pytest.raises(ConfigError, match="listed twice"):
        servicer("dart", third_bodies=("moon", "moon"))
    with pytest.raises(ConfigError, match=r"third_bodies \(moon\) need the run's epoch"):
        Harness(
            "dynamics.dart",
            {"third_bodies": ["moon"], "bodies": {"servicer": SERVICER}},
            config_dir=CONFIGS,
            epoch=None,
        )
