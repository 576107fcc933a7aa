"""OrbitalWorld (components/dynamics/world.py): conservation, joints, frames, state, contacts.

Tolerances are stated per test. No environment here (r_eci = 0: deep space) unless said.
"""

from pathlib import Path

import numpy as np
import pytest

from components.dynamics.environment import tidal_acceleration
from components.dynamics.world import BodySpec, ModelError, OrbitalWorld
from components.rotations import quat_to_matrix
from tests import validation

ROOT = Path(__file__).resolve().parents[2]
HUMANOID = ROOT / "models" / "humanoid_torso.urdf"
TARGET = ROOT / "models" / "target.urdf"
# a posture away from the joint limits, both elbows bent
POSTURE = {
    "arm_right_1_joint": -0.4,
    "arm_right_2_joint": -0.3,
    "arm_right_4_joint": -1.0,
    "arm_left_1_joint": -0.4,
    "arm_left_2_joint": 0.3,
    "arm_left_4_joint": -1.0,
}


def humanoid(**kw) -> BodySpec:
    defaults = dict(
        q=POSTURE,
        qd={"arm_right_1_joint": 0.3, "arm_left_3_joint": -0.4},
        twist=np.array([0.02, -0.01, 0.005, 0.01, -0.02, 0.015]),
    )
    defaults.update(kw)
    return BodySpec("humanoid", HUMANOID, **defaults)


def link_momentum(world: OrbitalWorld, name: str) -> np.ndarray:
    """Textbook momentum from the links: sum m_i v_i; sum I_i w_i + m_i (c_i - c) x v_i."""
    body = world.bodies[name]
    linear, spin, moment = np.zeros(3), np.zeros(3), np.zeros(3)
    c = np.asarray(body.skel.getCOM())
    for bn, m, inertia in zip(body.nodes, body.mass, body.local_inertia):
        R = bn.getTransform().rotation()
        v = np.asarray(bn.getCOMLinearVelocity())
        linear += m * v
        spin += R @ inertia @ R.T @ np.asarray(bn.getAngularVelocity())
        moment += m * np.cross(np.asarray(bn.getCOM()) - c, v)
    return np.concatenate([linear, spin + moment])


def tracking_torques(world, name, t, kp=2.0, kd=0.5):
    """Arbitrary (state-dependent, smooth) joint torques: a PD towards a moving posture."""
    body = world.bodies[name]
    out = world.outputs(name)
    ref = np.array([POSTURE.get(j, 0.0) for j in body.joints]) + 0.3 * np.sin(1.3 * t + np.arange(len(body.joints)))
    return kp * (ref - out["q"]) - kd * out["qd"]


def test_momentum_output_equals_link_sum():
    world = OrbitalWorld([humanoid()])
    world.reset_bodies()
    world.step(0.01)
    assert np.allclose(world.momentum("humanoid"), link_momentum(world, "humanoid"), rtol=1e-12, atol=1e-12)


def test_rk4_conserves_momentum_of_free_floating_humanoid():
    """10 s at 1 ms, rk4, joint torques changing every step, no environment:
    linear and angular (about the CoM) momentum constant to relative drift < 1e-6."""
    world = OrbitalWorld([humanoid()], integrator="rk4")
    world.reset_bodies()
    h0 = world.momentum("humanoid")
    worst_linear = worst_angular = 0.0
    tau_max = 0.0
    for k in range(10_000):
        tau = tracking_torques(world, "humanoid", k * 1e-3)
        tau_max = max(tau_max, np.abs(tau).max())
        world.set_torques("humanoid", tau)
        world.step(1e-3)
        if k % 100 == 99:
            h = world.momentum("humanoid")
            worst_linear = max(worst_linear, np.linalg.norm(h[:3] - h0[:3]) / np.linalg.norm(h0[:3]))
            worst_angular = max(worst_angular, np.linalg.norm(h[3:] - h0[3:]) / np.linalg.norm(h0[3:]))
    print(
        f"rk4 10 s at 1 ms, |tau| up to {tau_max:.2f} N m: relative momentum drift "
        f"linear {worst_linear:.1e}, angular {worst_angular:.1e}"
    )
    assert tau_max > 0.1
    assert worst_linear < 1e-6 and worst_angular < 1e-6


def test_dart_integrator_runs_and_roughly_conserves_momentum():
    """DART's semi-implicit step: first order; 2 s at 1 ms, relative drift < 1e-2."""
    world = OrbitalWorld([humanoid()], integrator="dart")
    world.reset_bodies()
    h0 = world.momentum("humanoid")
    for k in range(2000):
        world.set_torques("humanoid", tracking_torques(world, "humanoid", k * 1e-3))
        world.step(1e-3)
    h = world.momentum("humanoid")
    drift = np.linalg.norm(h - h0) / np.linalg.norm(h0)
    print(f"dart 2 s at 1 ms: relative momentum drift {drift:.1e}")
    assert drift < 1e-2


def test_joint_stop_holds_the_limit_and_keeps_momentum():
    """rk4: a wrist pushed hard into its limit stays within one step's travel of it, and the
    stop (an internal impulse) leaves the momentum unchanged to 1e-9 relative."""
    world = OrbitalWorld([humanoid()], integrator="rk4")
    world.reset_bodies()
    body = world.bodies["humanoid"]
    k7 = body.joints.index("arm_right_7_joint")
    upper = body.model.joint("arm_right_7_joint").upper
    h0 = world.momentum("humanoid")
    tau = np.zeros(14)
    tau[k7] = 0.2
    peak = -np.inf
    for _ in range(1000):
        world.set_torques("humanoid", tau)
        world.step(1e-3)
        peak = max(peak, world.outputs("humanoid")["q"][k7])
    q = world.outputs("humanoid")["q"][k7]
    drift = np.linalg.norm(world.momentum("humanoid") - h0) / np.linalg.norm(h0)
    print(f"wrist stop: limit {upper}, peak {peak:.5f}, final {q:.5f}, momentum drift {drift:.1e}")
    assert upper - 1e-3 < q and peak < upper + 0.02
    assert drift < 1e-9


def test_state_restore_at_a_joint_limit_continues_bit_exactly():
    """A wrist pushed into its stop: the state taken while it rests there (the stop is part of
    the state) restores into a fresh world that continues to identical bits. Without the stop in
    the state the continuation differs (the issue measured 1.2e-4 rad within 20 steps)."""

    def pushed(world, n):
        tau = np.zeros(14)
        tau[world.bodies["humanoid"].joints.index("arm_right_7_joint")] = 0.2
        for _ in range(n):
            world.set_torques("humanoid", tau)
            world.step(1e-3)
        return world.outputs("humanoid")["q"]

    a = OrbitalWorld([humanoid()], integrator="rk4")
    a.reset_bodies()
    pushed(a, 600)
    state = a.get_state()
    assert np.count_nonzero(state["humanoid.stop_side"]) == 1, "the wrist should rest on its stop"
    expected = pushed(a, 40)
    b = OrbitalWorld([humanoid()], integrator="rk4")
    b.set_state(state)
    assert np.array_equal(pushed(b, 40), expected)
    c = OrbitalWorld([humanoid()], integrator="rk4")
    c.set_state({**state, "humanoid.stop_side": np.zeros(14)})
    assert np.max(np.abs(pushed(c, 40) - expected)) > 1e-9


def test_dart_integrator_enforces_joint_limits():
    """integrator: dart: DART's joint-limit constraints hold a wrist pushed into its stop
    (within 0.01 rad, DART's constraint softness)."""
    world = OrbitalWorld([humanoid()], integrator="dart")
    world.reset_bodies()
    body = world.bodies["humanoid"]
    k7 = body.joints.index("arm_right_7_joint")
    tau = np.zeros(14)
    tau[k7] = 0.2
    for _ in range(500):
        world.set_torques("humanoid", tau)
        world.step(1e-3)
    q = world.outputs("humanoid")["q"][k7]
    assert abs(q - body.model.joint("arm_right_7_joint").upper) < 0.01


def test_effort_limits_clip_torques():
    world = OrbitalWorld([humanoid()])
    world.reset_bodies()
    body = world.bodies["humanoid"]
    effort = body.effort.copy()
    world.set_torques("humanoid", effort)
    at_limit = world.forward_dynamics("humanoid")["qdd"]
    world.set_torques("humanoid", 10 * effort)
    assert np.array_equal(world.forward_dynamics("humanoid")["qdd"], at_limit)


def test_locked_joints_stay_at_their_initial_position():
    locked = ["arm_left_1_joint", "arm_left_4_joint"]
    world = OrbitalWorld([humanoid(locked_joints=tuple(locked), qd={"arm_right_1_joint": 0.3})])
    world.reset_bodies()
    body = world.bodies["humanoid"]
    assert body.skel.getNumDofs() == 6 + 14 - 2
    idx = [body.joints.index(j) for j in locked]
    h0 = world.momentum("humanoid")
    for _k in range(200):
        world.set_torques("humanoid", np.full(14, 0.05))  # torque on locked joints ignored
        world.step(1e-3)
    out = world.outputs("humanoid")
    assert out["q"].shape == (14,)
    assert out["q"][idx].tolist() == [POSTURE["arm_left_1_joint"], POSTURE["arm_left_4_joint"]]
    assert out["qd"][idx].tolist() == [0.0, 0.0]
    assert np.linalg.norm(world.momentum("humanoid") - h0) / np.linalg.norm(h0) < 1e-9
    # the welded joint sits where the joint would be at that q: same link pose as a free body
    free = OrbitalWorld([humanoid(qd={})])
    welded = OrbitalWorld([humanoid(qd={}, locked_joints=tuple(locked))])
    free.reset_bodies()
    welded.reset_bodies()
    assert np.allclose(
        free.outputs("humanoid")["link_position"], welded.outputs("humanoid")["link_position"], atol=1e-12
    )


def test_environment_as_generalized_forces_equals_dart_external_forces():
    """The environment enters DART as generalized forces J^T W, one Jacobian per anchor (the links
    welded to it by locked or fixed joints summed into one wrench). Same accelerations as DART's
    own path, each link's tidal force at its CoM and gravity-gradient torque as external forces;
    and the tidal forces equal the numpy formula of environment.py at the links' CoMs from DART. A close, light 'planet' (mu 1e12, |R| 10 km) makes the environment comparable to the
    joint torques. Tolerance 1e-12 relative (rounding: measured ~1e-15)."""
    locked = ("arm_left_1_joint", "arm_left_4_joint", "arm_right_6_joint")
    world = OrbitalWorld([humanoid(locked_joints=locked, qd={})], mu=1e12)
    body = world.bodies["humanoid"]
    skel = body.skel
    assert len(body.anchors) < len(body.nodes)
    rng = np.random.default_rng(5)
    for _ in range(5):
        r_eci = rng.normal(size=3)
        r_eci *= 1e4 / np.linalg.norm(r_eci)
        world.set_orbit(r_eci, np.zeros(3))
        quat = rng.normal(size=4)
        q = rng.uniform(-0.5, 0.5, 14)
        q[[body.joints.index(j) for j in locked]] = [POSTURE.get(j, 0.0) for j in locked]
        world.set_body_state(
            "humanoid", rng.normal(size=3), quat / np.linalg.norm(quat), rng.normal(size=6), q, rng.normal(size=14)
        )
        world.set_torques("humanoid", rng.normal(size=14))
        qdd = world.forward_dynamics("humanoid")["qdd"]
        nodes = [body.link_names.index(bn.getName()) for bn in body.nodes]  # per node (massive link)
        tidal, _, torque = (w[nodes] for w in body.environment_wrenches(r_eci, np.zeros(3)))
        coms = np.array([bn.getCOM() for bn in body.nodes])
        expected_tidal = body.mass[:, None] * tidal_acceleration(r_eci, coms, 1e12)
        assert np.abs(tidal - expected_tidal).max() <= 1e-12 * np.abs(expected_tidal).max()
        skel.setForces(body.tau)
        for bn, f, t in zip(body.nodes, tidal, torque):
            bn.setExtForce(f, bn.getLocalCOM(), False, True)
            bn.addExtTorque(t, False)
        skel.computeForwardDynamics()
        expected = body.joint_velocities(skel.getAccelerations())
        skel.clearExternalForces()
        assert np.abs(torque).max() > 1e-3 and np.abs(tidal).max() > 1.0
        print(f"relative difference {np.abs(qdd - expected).max() / np.abs(expected).max():.1e}")
        assert np.abs(qdd - expected).max() <= 1e-12 * np.abs(expected).max()


def test_lvlh_initial_state_co_rotates():
    """frame: lvlh, zero twist: the base turns with LVLH and moves as w x p."""
    angle = 0.7
    q_eci_lvlh = np.array([0.0, 0.0, np.sin(angle / 2), np.cos(angle / 2)])
    w_lvlh = np.array([0.0, 0.0, 1.1e-3])
    spec = BodySpec(
        "t", TARGET, frame="lvlh", position=np.array([10.0, 0.0, 0.0]), orientation=np.array([0.0, 0.0, 0.0, 1.0])
    )
    world = OrbitalWorld([spec], tidal_force=False, gravity_gradient=False)
    world.set_orbit([7e6, 0, 0], [0, 7.5e3, 0], q_eci_lvlh, w_lvlh)
    world.reset_bodies()
    out = world.outputs("t")
    R_WL = quat_to_matrix(q_eci_lvlh)
    assert np.allclose(out["position"], R_WL @ [10.0, 0.0, 0.0], atol=1e-12)
    assert np.allclose(out["orientation"], q_eci_lvlh, atol=1e-12)
    assert np.allclose(out["twist"][3:], w_lvlh, atol=1e-15)
    assert np.allclose(out["twist"][:3], np.cross(w_lvlh, R_WL @ [10.0, 0.0, 0.0]), atol=1e-12)


@pytest.mark.parametrize("integrator", ["rk4", "dart"])
def test_state_restore_continues_bit_exactly(integrator):
    """get_state after 50 steps, 50 more steps; a fresh world given the state does the same 50
    steps to identical bits (outputs compared with array_equal)."""
    specs = [humanoid(), BodySpec("target", TARGET, position=np.array([1.5, 0.0, 0.0]))]
    orbit = ([6778e3, 0, 0], [0, 7668.6, 0], [0, 0, 0, 1], [0, 0, 1.13e-3])

    def run(world, k0, n):
        for k in range(k0, k0 + n):
            world.set_orbit(*orbit)
            world.set_torques("humanoid", 0.05 * np.sin(0.01 * k + np.arange(14)))
            world.step(1e-3)
        return {**world.outputs("humanoid"), **{f"t.{k}": v for k, v in world.outputs("target").items()}}

    a = OrbitalWorld(specs, integrator=integrator, substeps=2)
    a.set_orbit(*orbit)
    a.reset_bodies()
    run(a, 0, 50)
    state = a.get_state()
    expected = run(a, 50, 50)
    b = OrbitalWorld(specs, integrator=integrator, substeps=2)
    b.set_state(state)
    got = run(b, 50, 50)
    for key in expected:
        assert np.array_equal(expected[key], got[key]), key


def test_nan_torque_is_refused_naming_the_variable():
    world = OrbitalWorld([humanoid()])
    tau = np.zeros(14)
    tau[3] = np.nan
    with pytest.raises(ValueError, match=r"humanoid\.tau.*arm_left_4_joint"):
        world.set_torques("humanoid", tau)
    with pytest.raises(ValueError, match=r"humanoid\.tau: expected 14 values"):
        world.set_torques("humanoid", np.zeros(3))


def test_bad_specs_are_refused_naming_the_key():
    with pytest.raises(ModelError, match="duplicate body name") as e:
        OrbitalWorld([humanoid(), humanoid()])
    assert e.value.key == "humanoid"
    with pytest.raises(ModelError) as e:
        OrbitalWorld([humanoid(q={"no_such_joint": 0.1})])
    assert e.value.key == "humanoid.q.no_such_joint"
    with pytest.raises(ModelError) as e:
        OrbitalWorld([humanoid(q={"arm_right_4_joint": 1.0})])  # elbow limit [-2.36, 0.0035]
    assert e.value.key == "humanoid.q.arm_right_4_joint"
    with pytest.raises(ModelError) as e:
        OrbitalWorld([humanoid(locked_joints=("arm_right_1_joint",))])  # locked but has qd
    assert e.value.key == "humanoid.qd.arm_right_1_joint"


def test_contact_between_bodies_in_dart_mode():
    """integrator: dart. A 200 kg box drifting at 0.2 m/s into the humanoid's arm and torso
    pushes the humanoid: it ends up moving with the box, and the total linear momentum of the
    two bodies is conserved to 1e-4 relative (contact impulses are equal and opposite; DART's
    first-order step of the moving arm drifts ~1e-5)."""
    box = BodySpec(
        "target", TARGET, position=np.array([1.0, 0.0, -0.1]), twist=np.array([-0.2, 0.0, 0.0, 0.0, 0.0, 0.0])
    )
    world = OrbitalWorld([humanoid(twist=np.zeros(6), qd={}), box], integrator="dart")
    world.reset_bodies()
    total0 = world.momentum("humanoid")[:3] + world.momentum("target")[:3]
    for _ in range(2500):
        world.set_torques("humanoid", np.zeros(14))
        world.step(1e-3)
    humanoid_p = world.momentum("humanoid")[:3]
    total = humanoid_p + world.momentum("target")[:3]
    print(
        f"contact: humanoid linear momentum {humanoid_p.round(3)} kg m/s, total drift "
        f"{np.linalg.norm(total - total0) / np.linalg.norm(total0):.1e}"
    )
    assert humanoid_p[0] < -5.0  # pushed along -x by a good part of the box's 40 kg m/s
    assert np.linalg.norm(total - total0) / np.linalg.norm(total0) < 1e-4


@pytest.mark.parametrize("angle", [1e-4, 0.3, 2.5])
def test_left_jacobian_inverse_is_the_rate_of_the_rotation_vector(angle):
    """phi' = J_l(phi)^-1 omega for R = exp(phi) R0 turning at world rate omega, against a central
    difference of scipy's rotation vector of exp(dt omega) exp(phi). Angles on both sides of the
    series switch (t^2 = 1e-6) and near pi. Tolerance 1e-8 relative (difference error ~dt^2)."""
    from scipy.spatial.transform import Rotation

    from components.dynamics.manifold_rk4 import so3_left_jacobian_inverse_times

    rng = np.random.default_rng(11)
    axis = rng.normal(size=3)
    phi = angle * axis / np.linalg.norm(axis)
    omega = rng.normal(size=3)
    dt = 1e-5
    ahead, behind = ((Rotation.from_rotvec(s * dt * omega) * Rotation.from_rotvec(phi)).as_rotvec() for s in (1, -1))
    expected = (ahead - behind) / (2 * dt)
    rate = so3_left_jacobian_inverse_times(phi, omega)
    assert np.abs(rate - expected).max() <= 1e-8 * np.abs(expected).max()


@pytest.mark.parametrize("angle", [0.0, 1e-12, 3e-9, 1e-5, 7.5e-4, 0.3, 2.0, np.pi - 1e-7])
def test_compiled_so3_exp_and_log_are_exact_at_every_angle(angle):
    """manifold_rk4's exp_so3/log_so3 against scipy (quaternion-based, an independent formula):
    1e-15 absolute on the matrix, 1e-15 relative on the rotation vector, at angles from 0 to
    near pi, including those below 1e-3 rad where DART's exponential is truncated; and moved()
    composes on the left with world-frame rates, as DART's FreeJoint chart does."""
    from scipy.spatial.transform import Rotation

    from components.dynamics.manifold_rk4 import exp_so3, log_so3, moved

    rng = np.random.default_rng(5)
    axis = rng.normal(size=3)
    phi = angle * axis / np.linalg.norm(axis)
    expected = Rotation.from_rotvec(phi).as_matrix()
    assert np.abs(exp_so3(phi) - expected).max() <= 1e-15
    back = log_so3(expected)
    if angle < 3.0:
        assert np.linalg.norm(back - phi) <= 1e-15 * angle
    else:  # near pi the angle is ill-conditioned in R: compare the rotations
        assert np.abs(Rotation.from_rotvec(back).as_matrix() - expected).max() <= 1e-15
    q0 = np.concatenate([rng.normal(size=3), rng.normal(size=3), [0.4, -0.2]])
    xi = np.concatenate([phi, rng.normal(size=3), [0.01, 0.02]])
    q = moved(q0, xi)
    R = Rotation.from_rotvec(q[:3]).as_matrix()
    assert np.abs(R - expected @ Rotation.from_rotvec(q0[:3]).as_matrix()).max() <= 2e-15
    assert np.array_equal(q[3:], q0[3:] + xi[3:])


TUMBLER = """<?xml version="1.0"?>
<robot name="tumbler"><link name="box"><inertial><origin xyz="0 0 0" rpy="0 0 0"/><mass value="10"/>
<inertia ixx="2" ixy="0" ixz="0" iyy="3" iyz="0" izz="4.5"/></inertial></link></robot>
"""
TUMBLER_INERTIA = np.array([2.0, 3.0, 4.5])
TUMBLER_OMEGA = 3.0 * np.array([0.6, -0.5, 0.62]) / np.linalg.norm([0.6, -0.5, 0.62])  # rad/s, body = W at t 0


def euler_reference(duration: float) -> np.ndarray:
    """R_W_body(duration) of the torque-free tumbler: Euler's equations and dR/dt = R [w]x,
    integrated by scipy's DOP853 at rtol 1e-13 (an independent integrator)."""
    from scipy.integrate import solve_ivp

    def rates(_, y):
        w, R = y[:3], y[3:].reshape(3, 3)
        dw = np.cross(TUMBLER_INERTIA * w, w) / TUMBLER_INERTIA
        W = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
        return np.concatenate([dw, (R @ W).ravel()])

    y = solve_ivp(
        rates,
        (0.0, duration),
        np.concatenate([TUMBLER_OMEGA, np.eye(3).ravel()]),
        method="DOP853",
        rtol=1e-13,
        atol=1e-15,
    ).y[:, -1]
    return y[3:].reshape(3, 3)


def test_rk4_attitude_converges_at_fourth_order_down_to_small_steps(tmp_path):
    """A torque-free asymmetric body (I = 2, 3, 4.5 kg m^2, |w| = 3 rad/s) tumbling for 3.2 s,
    against DOP853 on Euler's equations. The attitude error drops ~16x per halving of h at large
    steps (fourth order) and never rises as h shrinks to 0.25 ms (down to a 1e-12 rounding floor);
    the angular momentum drifts by <= 1e-9 (relative) at every step from 4 ms to 0.25 ms.
    (An SO(3) exponential truncated at small angles, as DART's integratePositions is below 1e-3
    rad, gives 4e-7 at 0.25 ms.)"""
    from components.rotations import log_so3

    urdf = tmp_path / "tumbler.urdf"
    urdf.write_text(TUMBLER)
    duration = 3.2
    reference = euler_reference(duration)
    errors, drifts = {}, {}
    for h_ms in (8, 4, 2, 1, 0.5, 0.25):
        world = OrbitalWorld([BodySpec("box", urdf, twist=np.concatenate([np.zeros(3), TUMBLER_OMEGA]))])
        world.reset_bodies()
        L0 = world.momentum("box")[3:]
        for _ in range(round(duration / (h_ms * 1e-3))):
            world.step(h_ms * 1e-3)
        R = quat_to_matrix(world.outputs("box", links=False)["orientation"])
        errors[h_ms] = float(np.linalg.norm(log_so3(reference.T @ R)))
        drifts[h_ms] = float(np.linalg.norm(world.momentum("box")[3:] - L0) / np.linalg.norm(L0))
    print(
        "h ms: attitude error rad, momentum drift: "
        + ", ".join(f"{h}: {errors[h]:.1e}, {drifts[h]:.1e}" for h in errors)
    )
    steps = list(errors)
    for big, small in zip(steps[:3], steps[1:4]):  # 8 -> 4 -> 2 -> 1 ms
        assert 12 < errors[big] / errors[small] < 20, (big, errors)
    for big, small in zip(steps, steps[1:]):
        assert errors[small] <= max(errors[big], 1e-12), (small, errors)
    validation.check("rk4_attitude", errors[1])
    validation.check("rk4_momentum", max(drifts[h] for h in steps[1:]))
