"""The grasp of a capture (components/dynamics/capture.py) in OrbitalWorld: the inelastic impact,
the weld, and the quantities the sensors read, against conservation laws, closed forms and finite
differences. No environment (r_eci = 0) unless said. Tolerances are stated per test."""

from pathlib import Path

import numpy as np
import pytest

from components.dynamics.capture import GraspSpec, Tolerance
from components.dynamics.environment import tidal_acceleration
from components.dynamics.world import BodySpec, ModelError, OrbitalWorld
from components.rotations import quat_to_matrix
from components.testing.harness import Harness
from tests import validation

ROOT = Path(__file__).resolve().parents[2]
SERVICER, TARGET = ROOT / "models" / "servicer.urdf", ROOT / "models" / "target.urdf"
ARM = {f"arm_{i}_joint": v for i, v in zip(range(1, 7), [0.3, 0.5, 0.9, -0.2, 0.4, 0.1])}
ANYWHERE = Tolerance(10.0, 4.0, 10.0, 10.0)
R_ORBIT = np.array([6778e3, 0.0, 0.0])
V_ORBIT = np.array([0.0, 7668.6, 0.0])


def unit(q):
    q = np.asarray(q, dtype=float)
    return q / np.linalg.norm(q)


def world(
    *,
    locked=False,
    target_twist=(0.01, -0.02, 0.005, 0.03, -0.02, 0.04),
    tolerance=ANYWHERE,
    target_position=(1.6, 0.3, 2.6),
    target_orientation=(0.1, 0.2, 0.05, 1.0),
    **kw,
) -> OrbitalWorld:
    w = OrbitalWorld(
        [
            BodySpec("servicer", SERVICER, q=ARM, locked_joints=tuple(ARM) if locked else ()),
            BodySpec(
                "target",
                TARGET,
                position=np.array(target_position),
                orientation=unit(target_orientation),
                twist=np.array(target_twist, dtype=float),
            ),
        ],
        grasp=GraspSpec("servicer", "arm_tool_link", "target", "target", tolerance),
        **{"tidal_force": False, "gravity_gradient": False, **kw},
    )
    w.reset_bodies()
    return w


def total_momentum(w: OrbitalWorld) -> np.ndarray:
    """Linear, then angular momentum about W's origin, summed over the bodies."""
    linear, angular = np.zeros(3), np.zeros(3)
    for name, body in w.bodies.items():
        m = w.momentum(name)
        linear += m[:3]
        angular += m[3:] + np.cross(body.skel.getCOM(), m[:3])
    return np.concatenate([linear, angular])


def links(w: OrbitalWorld):
    """(mass, CoM in W, inertia about the link CoM in W) of every massive link of every body."""
    for body in w.bodies.values():
        for bn, m, inertia in zip(body.nodes, body.mass, body.local_inertia):
            R = bn.getTransform().rotation()
            yield m, np.asarray(bn.getCOM()), R @ inertia @ R.T


def test_impact_and_weld_conserve_momentum():
    """Closing on a target that moves and turns relative to the end effector (30 mm/s, 3 deg/s):
    total momentum unchanged by the impact to 1e-13 relative, and through 2 s welded with the arm
    free to 1e-11; the weld holds to 1e-10 m and rad; the relative twist at the weld point is gone."""
    w = world()
    before = total_momentum(w)
    report = w.grasp.close()
    assert np.linalg.norm(report.relative_twist[:3]) > 0.03  # a real impact, not a touch
    scale = np.abs(before).max()
    assert np.abs(total_momentum(w) - before).max() < 1e-13 * scale
    assert np.abs(w.grasp.relative()["twist_ee_grasp"]).max() < 1e-12
    for _ in range(2000):
        w.step(1e-3)
    validation.check("capture_momentum", np.abs(total_momentum(w) - before).max() / scale)
    assert np.abs(w.grasp.pose_error()).max() < 1e-10


def test_capture_with_spinning_wheels_conserves_momentum():
    """The capture models (wheels off the arm's chain, spinning at 50, -30, 20 rad/s, the arm and
    wheels torqued): momentum through the impact to 1e-13 and over 1 s welded to 1e-11 relative."""
    capture = ROOT / "models" / "capture"
    w = OrbitalWorld(
        [
            BodySpec(
                "servicer",
                capture / "servicer.urdf",
                q={"arm_2_joint": 0.6, "arm_3_joint": 1.0},
                qd={"wheel_x_joint": 50.0, "wheel_y_joint": -30.0, "wheel_z_joint": 20.0},
            ),
            BodySpec(
                "target",
                capture / "target.urdf",
                position=np.array([1.9, 0.2, 1.7]),
                orientation=unit([0.3, -0.1, 0.2, 1.0]),
                twist=np.array([0.0, 0.01, 0.0, 0.02, 0.04, -0.03]),
            ),
        ],
        grasp=GraspSpec("servicer", "ee", "target", "grapple", ANYWHERE),
        tidal_force=False,
        gravity_gradient=False,
    )
    w.reset_bodies()
    before = total_momentum(w)
    w.grasp.close()
    scale = np.abs(before).max()
    assert np.abs(total_momentum(w) - before).max() < 1e-13 * scale
    w.set_torques("servicer", [3.0, -2.0, 1.0, 0.5, -0.5, 0.2, 0.8, -0.6, 0.4])
    for _ in range(1000):
        w.step(1e-3)
    validation.check("capture_momentum", np.abs(total_momentum(w) - before).max() / scale)
    assert np.abs(w.grasp.pose_error()).max() < 1e-10


def test_post_capture_rate_is_momentum_over_assembly_inertia():
    """With the arm locked the assembly is rigid: after the impact every part turns at
    omega = I_sys^-1 H_sys (about the system CoM, from the links' inertias) and the CoM moves at
    L / m, both computed from the momentum before the impact. To 1e-12 rad/s and m/s."""
    w = world(locked=True)
    momentum = total_momentum(w)
    w.grasp.close()
    mass = sum(m for m, _, _ in links(w))
    c = sum(m * x for m, x, _ in links(w)) / mass
    inertia = sum(I_b + m * (np.dot(x - c, x - c) * np.eye(3) - np.outer(x - c, x - c)) for m, x, I_b in links(w))
    H = momentum[3:] - np.cross(c, momentum[:3])
    omega = np.linalg.solve(inertia, H)
    v_com = sum(w.momentum(n)[:3] for n in w.bodies) / mass
    errors = [np.abs(w.outputs(name, links=False)["twist"][3:] - omega).max() for name in ("servicer", "target")]
    validation.check("capture_rate", max(*errors, np.abs(v_com - momentum[:3] / mass).max()))
    assert np.linalg.norm(omega) > 1e-3


def central_difference(samples, h):
    return (samples[2] - samples[0]) / (2 * h)


def test_wrist_wrench_is_the_payloads_inertial_wrench():
    """Welded, the arm driven by joint torques: the wrench the end effector applies to the target
    (its only force, no environment) equals m a_c and I alpha + w x I w + (c - P) x m a_c about the
    weld point P, with a_c and alpha from central differences of the target's own motion (O(h^2):
    agreement to 1e-6 of the wrench's size)."""
    w = world(locked=False)
    w.grasp.close()
    w.set_torques("servicer", [8.0, -6.0, 5.0, 2.0, -1.5, 1.0])
    h = 1e-4
    for _ in range(200):
        w.step(h)
    target = w.bodies["target"]
    m_t = target.total_mass
    v, omega, wrench = [], [], None
    for i in range(3):
        v.append(w.momentum("target")[:3] / m_t)
        omega.append(w.outputs("target", links=False)["twist"][3:].copy())
        if i == 1:
            w.accelerations()
            wrench = w.grasp.wrench_on_target()
            p_E, R_E = w.grasp.ee.pose()
            P = R_E @ w.grasp.p_in_chaser + p_E
            c = np.asarray(target.skel.getCOM())
            R_t = target.root.getTransform().rotation()
            I_t = R_t @ target.local_inertia[0] @ R_t.T
            w_now = omega[1]
        w.step(h)
    a_c = central_difference(v, h)
    alpha = central_difference(omega, h)
    force = m_t * a_c
    torque = I_t @ alpha + np.cross(w_now, I_t @ w_now) + np.cross(c - P, force)
    expected = np.concatenate([R_E.T @ force, R_E.T @ torque])
    assert np.linalg.norm(force) > 1.0
    validation.check("capture_wrench", np.abs(wrench - expected).max() / np.abs(expected).max())


@pytest.mark.parametrize("environment", [False, True])
def test_imu_reads_the_base_rate_and_non_gravitational_acceleration(environment):
    """The IMU at the servicer's base origin: rate = R^T w; specific force = R^T (a - g_tidal(p)),
    a from central differences of the base origin's velocity (O(h^2)), under joint torques and, in
    orbit, the tidal field (which the IMU must not sense). To 1e-6 of the acceleration's size."""
    w = OrbitalWorld(
        [
            BodySpec(
                "servicer",
                SERVICER,
                q=ARM,
                position=np.array([3.0, -2.0, 1.0]),
                twist=np.array([0.0, 0.0, 0.0, 0.01, 0.02, -0.01]),
            )
        ],
        tidal_force=environment,
        gravity_gradient=environment,
    )
    w.set_orbit(R_ORBIT if environment else np.zeros(3), V_ORBIT if environment else np.zeros(3))
    w.reset_bodies()
    w.set_torques("servicer", [20.0, -15.0, 10.0, 2.0, 1.0, 0.5])
    h = 1e-4
    v = []
    for i in range(3):
        out = w.outputs("servicer", links=False)
        v.append(out["twist"][:3].copy())
        if i == 1:
            w._env_now = w.environment_on
            imu = w.imu_outputs("servicer", w.accelerations()["servicer"])
            R = quat_to_matrix(out["orientation"])
            rate, p = out["twist"][3:], out["position"]
        w.step(h)
    a = central_difference(v, h)
    gravity = tidal_acceleration(w.reference(w.elapsed - h)[0], p[None, :])[0] if environment else np.zeros(3)
    expected = R.T @ (a - gravity)
    assert np.allclose(imu["imu_rate"], R.T @ rate, rtol=0, atol=1e-15)
    validation.check("imu_specific_force", np.abs(imu["specific_force"] - expected).max() / np.abs(expected).max())
    if environment:  # the tidal acceleration at 3.7 m is ~1e-5 m/s^2: it must have been taken out
        assert np.linalg.norm(gravity) > 1e-6


def test_the_grasp_closes_only_within_every_tolerance():
    """world.capture() closes only when all four errors are within the tolerances: here the
    position is 1.22 m off, so 1.2 m refuses and 1.3 m accepts."""
    assert world(tolerance=Tolerance(1.2, 4.0, 10.0, 10.0)).capture() is None
    w = world(tolerance=Tolerance(1.3, 4.0, 10.0, 10.0))
    report = w.capture()
    assert report is not None and w.grasp.closed
    assert 1.2 < report.errors["position"] < 1.3
    assert world(tolerance=Tolerance(1.3, 4.0, 0.01, 10.0)).capture() is None  # 34 mm/s relative


def test_state_after_capture_continues_bit_for_bit():
    """get_state after the capture, set_state into a fresh world: the next steps are identical."""
    a = world()
    a.grasp.close()
    for _ in range(20):
        a.step(1e-3)
    b = world()
    b.set_state(a.get_state())
    assert b.grasp.closed
    for _ in range(20):
        a.step(1e-3)
        b.step(1e-3)
    for name in a.bodies:
        assert np.array_equal(a.bodies[name].skel.getPositions(), b.bodies[name].skel.getPositions())
        assert np.array_equal(a.bodies[name].skel.getVelocities(), b.bodies[name].skel.getVelocities())


def test_bad_grasps_are_refused_naming_the_key():
    with pytest.raises(ModelError, match="grasp: a capture needs integrator rk4"):
        world(integrator="dart")
    with pytest.raises(ModelError, match=r"grasp\.grasp_frame: 'handle' is not a link of target"):
        OrbitalWorld(
            [BodySpec("servicer", SERVICER), BodySpec("target", TARGET)],
            grasp=GraspSpec("servicer", "arm_tool_link", "target", "handle", ANYWHERE),
        )


def test_component_capture_event_and_outputs():
    """dynamics.dart with a grasp: nothing closes while grasp.close is 0; with it set, the first
    step within tolerance closes, emits one 'capture' event with the residual twist and impulse,
    and grasp.closed turns 1 with the relative twist gone."""
    params = {
        "bodies": {
            "servicer": {"urdf": str(SERVICER), "q": ARM},
            "target": {
                "urdf": str(TARGET),
                "position": [1.6, 0.3, 2.6],
                "twist": [0.01, -0.02, 0.005, 0.03, -0.02, 0.04],
            },
        },
        "tidal_force": False,
        "gravity_gradient": False,
        "imu": ["servicer"],
        "frame_outputs": True,
        "grasp": {
            "chaser": "servicer",
            "end_effector": "arm_tool_link",
            "target": "target",
            "grasp_frame": "target",
            "tolerance": {
                "position": "2 m",
                "orientation": "180 deg",
                "linear_velocity": "1 m/s",
                "angular_velocity": "1 rad/s",
            },
            "force_limit": "1000 N",
            "torque_limit": "1000 N*m",
        },
    }
    h = Harness("dynamics.dart", params)
    h.initialize()
    out = h.step(1_000_000)
    assert out["grasp.closed"] == 0.0 and not h.component.take_events()
    h.inputs["grasp.close"] = 1.0
    out = h.step(1_000_000)
    events = h.component.take_events()
    assert [kind for kind, _ in events] == ["capture"]
    assert events[0][1]["time"] == pytest.approx(0.002)
    assert len(events[0][1]["relative_twist"]) == 6 and len(events[0][1]["impulse"]) == 6
    assert out["grasp.closed"] == 1.0
    assert np.abs(out["grasp.twist_ee_grasp"]).max() < 1e-9
    out = h.step(1_000_000)
    assert not h.component.take_events()


# --------------------------------------------------------------------------- load limits


def overload_world(action: str, force_limit: float, torque_limit: float) -> OrbitalWorld:
    """The arm welded to the target (no environment), the grasp with these load limits."""
    w = OrbitalWorld(
        [
            BodySpec("servicer", SERVICER, q=ARM),
            BodySpec(
                "target",
                TARGET,
                position=np.array((1.6, 0.3, 2.6)),
                orientation=unit((0.1, 0.2, 0.05, 1.0)),
                twist=np.array((0.01, -0.02, 0.005, 0.03, -0.02, 0.04)),
            ),
        ],
        grasp=GraspSpec(
            "servicer",
            "arm_tool_link",
            "target",
            "target",
            ANYWHERE,
            force_limit=force_limit,
            torque_limit=torque_limit,
            on_overload=action,
        ),
        tidal_force=False,
        gravity_gradient=False,
    )
    w.reset_bodies()
    w.grasp.close()
    return w


@pytest.mark.parametrize("action", ["release", "hold"])
def test_an_overloaded_weld_reports_its_peak_and_releases_or_holds(action):
    """The arm's shoulder and elbow torqued at 40 and -25 N m with the target welded. The weld's
    force on the target is the rate of the target's linear momentum (the weld is the only force on
    it): over a 1 ms step the reported peak force is at least the mean |dp/dt| and within 1% of it.
    Limits below it: one grasp_overload report with that peak; ``release`` opens the weld (no
    impulse: the total momentum after equals the one before to 1e-12 relative, and the bodies
    then move apart) and re-closes only after close is lowered; ``hold`` stays closed and reports
    once until the load falls back within the limits."""
    w = overload_world(action, 1e6, 1e6)
    torques = np.zeros(len(w.bodies["servicer"].joints))
    torques[:2] = 40.0, -25.0
    w.set_torques("servicer", torques)
    p0 = w.momentum("target")[:3].copy()
    w.step(1e-3)
    mean_force = float(np.linalg.norm(w.momentum("target")[:3] - p0) / 1e-3)
    peak = w.grasp.peak.copy()
    assert w.grasp.check_overload() is None  # within the large limits: nothing
    print(f"mean weld force {mean_force:.3f} N, peak over the stages {peak[0]:.3f} N, torque {peak[1]:.3f} N m")
    assert mean_force * (1 - 1e-9) <= peak[0] <= 1.01 * mean_force
    w = overload_world(action, 0.5 * mean_force, 1e6)
    w.set_torques("servicer", torques)
    before = total_momentum(w)
    w.step(1e-3)
    report = w.grasp.check_overload()
    assert report is not None and report["action"] == action and report["force_limit"] == 0.5 * mean_force
    assert report["force"] == pytest.approx(peak[0], rel=1e-9)
    assert np.abs(total_momentum(w) - before).max() < 1e-12 * np.abs(before).max()
    if action == "release":
        assert not w.grasp.closed
        w.set_torques("servicer", np.zeros_like(torques))
        w.step(1e-3)
        assert w.grasp.check_overload() is None and w.capture() is None  # disarmed: no re-close
        w.grasp.rearm(False)
        assert w.capture() is not None and w.grasp.closed  # close lowered, then raised
    else:
        assert w.grasp.closed
        w.step(1e-3)
        assert w.grasp.check_overload() is None  # the same overload: one report
        w.set_torques("servicer", np.zeros_like(torques))
        for _ in range(3):
            w.step(1e-3)
            w.grasp.check_overload()
        assert not w.grasp.overloaded  # back within the limits


def test_component_grasp_overload_event_names_the_peaks_and_limits():
    """dynamics.dart: after the capture, torques on the arm beyond what the fixture carries give one
    grasp_overload event (time, peak force and torque, the limits, the action) and grasp.closed
    back to 0 (release, the default)."""
    params = {
        "bodies": {
            "servicer": {"urdf": str(SERVICER), "q": ARM},
            "target": {"urdf": str(TARGET), "position": [1.6, 0.3, 2.6]},
        },
        "tidal_force": False,
        "gravity_gradient": False,
        "grasp": {
            "chaser": "servicer",
            "end_effector": "arm_tool_link",
            "target": "target",
            "grasp_frame": "target",
            "tolerance": {
                "position": "2 m",
                "orientation": "180 deg",
                "linear_velocity": "1 m/s",
                "angular_velocity": "1 rad/s",
            },
            "force_limit": "5 N",
            "torque_limit": "5 N*m",
        },
    }
    h = Harness("dynamics.dart", params)
    h.initialize()
    h.inputs["grasp.close"] = 1.0
    assert h.step(1_000_000)["grasp.closed"] == 1.0
    h.component.take_events()
    tau = np.zeros(h.inputs["servicer.tau"].size)
    tau[:2] = 40.0, -25.0
    h.inputs["servicer.tau"] = tau
    out = h.step(1_000_000)
    events = h.component.take_events()
    assert [kind for kind, _ in events] == ["grasp_overload"], events
    fields = events[0][1]
    assert fields["time"] == pytest.approx(0.002) and fields["action"] == "release"
    assert fields["force_limit"] == 5.0 and fields["torque_limit"] == 5.0
    assert fields["force"] > 5.0 or fields["torque"] > 5.0
    assert out["grasp.closed"] == 0.0
