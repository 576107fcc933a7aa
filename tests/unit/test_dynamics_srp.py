"""Solar radiation pressure and the sun sensor in dynamics.dart and dynamics.pinocchio: the per-link
outputs against components/space (srp.py, eclipse.py, ephemeris.py) evaluated on the links' own
poses (the kernels' frames, anchors and tree are not used), the base's non-gravitational
acceleration against F / m, and both engines against each other."""

from __future__ import annotations

import numpy as np
import pytest

from components.robots.urdf import read_urdf
from components.rotations import quat_to_matrix
from components.space import eclipse, ephemeris, srp
from components.testing.harness import Harness
from tests import validation
from tests.unit.test_dynamics_engines import CONFIGS, MODELS, assert_agree, circular, run

EPOCH = "2024-03-20T06:00:00Z"
MS = 1_000_000
FACETS = [
    {"area": 2.0, "normal": [1.0, 0.2, -0.1], "centre": [0.5, 0.1, 0.2], "specular": 0.3, "diffuse": 0.2},
    {"area": 1.5, "normal": [0.0, 1.0, 0.3], "centre": [0.0, 0.6, -0.1], "specular": 0.1, "diffuse": 0.5},
    {"area": 1.5, "normal": [0.0, -1.0, 0.3], "centre": [0.0, -0.6, -0.1], "specular": 0.1, "diffuse": 0.5},
    {"area": 0.7, "normal": [-0.4, 0.3, 1.0], "centre": [-0.3, 0.2, 0.5], "specular": 0.6, "diffuse": 0.3},
]
SERVICER = {
    "urdf": "../models/capture/servicer.urdf",
    "srp_area": {"arm_6_link": 0.3, "arm_2_link": 0.2},
    "srp_cr": {"arm_6_link": 1.4, "arm_2_link": 1.1},
    "locked_joints": ["arm_5_joint"],
    "srp_facets": {"bus": FACETS, "arm_5_link": FACETS[1:]},  # arm_5_link welded to arm_4_link
    "q": {"arm_2_joint": 0.6, "arm_3_joint": 1.0, "arm_5_joint": 0.4},
    "orientation": [0.2, -0.1, 0.3, 0.92],
    "twist": [0, 0, 0, 0.01, -0.02, 0.03],
}


def servicer(engine: str, eclipse_model: str = "conical", **extra) -> Harness:
    params = {
        "srp": True,
        "eclipse": eclipse_model,
        "link_outputs": True,
        "sun_sensor": ["servicer"],
        "bodies": {"servicer": {**SERVICER, **extra}},
    }
    return Harness(f"dynamics.{engine}", params, config_dir=CONFIGS, epoch=EPOCH)


def expected_link_wrenches(out, t_ns, r_eci, model="conical"):
    """Each link's SRP force and torque (W axes) from its pose in the outputs, its URDF CoM, and
    components/space: the Sun and Moon at t_ns, nu at the CoM, the facets turned into W."""
    urdf = read_urdf(MODELS / "capture" / "servicer.urdf")
    tt = ephemeris.Ephemeris(EPOCH).tt(t_ns)
    sun, moon = ephemeris.sun_position_eci(tt), ephemeris.moon_position_eci(tt)
    positions = out["servicer.link_position"].reshape(-1, 3)
    rotations = quat_to_matrix(out["servicer.link_orientation"].reshape(-1, 4))
    forces, torques = np.zeros_like(positions), np.zeros_like(positions)
    for k, link in enumerate(urdf.links):
        com_W = rotations[k] @ np.asarray(link.com)
        x = r_eci + positions[k] + com_W
        nu = eclipse.illumination(x, sun, moon if model == "conical" else None, model)
        s_link = rotations[k].T @ (sun - x)
        f, t = np.zeros(3), np.zeros(3)
        if link.name in SERVICER["srp_facets"]:
            rows = srp.facet_rows(SERVICER["srp_facets"][link.name])
            rows[:, 4:7] -= np.asarray(link.com)  # centres from the CoM
            f, t = srp.facet_wrench(s_link, rows, nu)
        if link.name in SERVICER["srp_area"]:
            f = f + srp.cannonball_force(s_link, SERVICER["srp_cr"][link.name] * SERVICER["srp_area"][link.name], nu)
        forces[k], torques[k] = rotations[k] @ f, rotations[k] @ t
    return forces, torques, sun, moon


@pytest.mark.parametrize("engine", ["dart", "pinocchio"])
def test_link_srp_wrenches_are_the_facets_and_cannonballs_on_the_link_poses(engine):
    h = servicer(engine)
    h.inputs.update(circular(0.0))
    h.initialize()
    for k in range(5):
        h.inputs.update(circular(k * 1e-3))
        out = h.step(MS)
    # the outputs at 5 ms: the reference point there (its Taylor arc from 4 ms: mm off), the Sun and
    # Moon of the step's start (4 ms: held over a step, 30 m along the Earth's orbit)
    forces, torques, _sun, _ = expected_link_wrenches(out, 4 * MS, circular(5e-3)["r_eci"])
    got_f, got_t = out["servicer.srp_force"].reshape(-1, 3), out["servicer.srp_torque"].reshape(-1, 3)
    lit = np.linalg.norm(forces, axis=1) > 0
    assert lit.sum() == 4 and np.linalg.norm(torques, axis=1).max() > 1e-7
    validation.check(
        "srp_links",
        max(np.abs(got_f - forces).max() / np.abs(forces).max(), np.abs(got_t - torques).max() / np.abs(torques).max()),
    )


@pytest.mark.parametrize("engine", ["dart", "pinocchio"])
def test_sun_sensor_reads_the_sun_direction_in_base_axes_and_the_eclipse(engine):
    h = servicer(engine)
    tt = ephemeris.Ephemeris(EPOCH).tt(0)
    sun, moon = ephemeris.sun_position_eci(tt), ephemeris.moon_position_eci(tt)
    sun_hat = sun / np.linalg.norm(sun)
    day = {**circular(0.0), "r_eci": 6778e3 * sun_hat}
    # in the Earth's shadow: behind it, 5 km inside its penumbra's outer edge at 700 km altitude
    w = np.cross(sun_hat, [0.0, 0.0, 1.0])
    w /= np.linalg.norm(w)
    for r_eci, expect in (
        (day["r_eci"], "lit"),
        (-7078e3 * sun_hat, "umbra"),
        (-7078e3 * sun_hat + (6378137.0 + 700e3 * 0.00465 - 5e3) * w, "penumbra"),
    ):
        h.inputs.update({**day, "r_eci": r_eci})
        out = h.initialize()
        R = quat_to_matrix(out["servicer.orientation"])
        x = r_eci + out["servicer.position"]
        s = sun - x
        assert np.abs(out["servicer.sun_body"] - R.T @ s / np.linalg.norm(s)).max() < 1e-15
        nu = eclipse.illumination(x, sun, moon, "conical")
        assert out["servicer.sunlit"] == pytest.approx(nu, abs=1e-15)
        assert {"lit": nu == 1.0, "umbra": nu == 0.0, "penumbra": 0.0 < nu < 1.0}[expect]


def test_srp_accelerates_a_free_body_by_force_over_mass(tmp_path):
    """One rigid link, CoM at its origin, a cannonball: the base's specific force (IMU) is
    R^T F / m with F = -P Cr A s_hat (no tidal force: W's gravity only), each engine."""
    urdf = tmp_path / "plate.urdf"
    urdf.write_text(
        '<robot name="plate"><link name="plate"><inertial><mass value="12.5"/><origin xyz="0 0 0"/>'
        '<inertia ixx="1.1" iyy="2.3" izz="3.1" ixy="0.1" ixz="0" iyz="0"/></inertial></link></robot>'
    )
    tt = ephemeris.Ephemeris(EPOCH).tt(0)
    sun = ephemeris.sun_position_eci(tt)
    r_eci = np.array([4.1e6, -5.2e6, 1.3e6])
    for engine in ("dart", "pinocchio"):
        params = {
            "srp": True,
            "tidal_force": False,
            "gravity_gradient": False,
            "imu": ["plate"],
            "bodies": {
                "plate": {"urdf": str(urdf), "srp_area": 3.0, "srp_cr": 1.3, "orientation": [0.3, -0.2, 0.1, 0.93]}
            },
        }
        h = Harness(f"dynamics.{engine}", params, epoch=EPOCH)
        h.inputs.update({**circular(0.0), "r_eci": r_eci})
        out = h.initialize()
        s = sun - (r_eci + out["plate.position"])
        P = srp.SOLAR_FLUX / srp.SPEED_OF_LIGHT * (srp.AU / np.linalg.norm(s)) ** 2
        F = -P * 1.3 * 3.0 * s / np.linalg.norm(s)
        R = quat_to_matrix(out["plate.orientation"])
        got = out["plate.specific_force"]
        assert np.abs(got - R.T @ F / 12.5).max() <= 1e-9 * np.linalg.norm(F / 12.5), engine


def test_engines_agree_with_srp_on():
    params = {"srp": True, "link_outputs": True, "sun_sensor": ["servicer"], "bodies": {"servicer": SERVICER}}
    dart = run(Harness("dynamics.dart", params, config_dir=CONFIGS, epoch=EPOCH), 500)
    pinocchio = run(Harness("dynamics.pinocchio", params, config_dir=CONFIGS, epoch=EPOCH), 500)
    assert np.abs(dart[-1]["servicer.srp_force"]).max() > 1e-6
    validation.check("pinocchio_dart", assert_agree(pinocchio, dart, "servicer with SRP"))


def test_srp_settings_are_checked():
    from components.errors import ConfigError

    with pytest.raises(ConfigError, match=r"srp_facets.ee: a link without mass|srp_facets.nothing: not a link"):
        servicer("dart", srp_facets={"nothing": FACETS})
    with pytest.raises(ConfigError, match=r"specular \+ diffuse <= 1"):
        servicer("dart", srp_facets={"bus": [{**FACETS[0], "specular": 0.8, "diffuse": 0.4}]})
    with pytest.raises(ConfigError, match="eclipse"):
        servicer("dart", eclipse_model="umbra")
