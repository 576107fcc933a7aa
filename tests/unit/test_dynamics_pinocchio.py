"""DART (OrbitalWorld) against Pinocchio: free-floating forward dynamics of the same URDF.

Coordinates: DART's FreeJoint velocity is (omega_W, v_W) of the base origin, its acceleration the
time derivative of that; Pinocchio's free-flyer velocity is (v_b, omega_b) in the base frame and
its acceleration the derivative of those. With R = R_W_base:
    a_pin_angular = R^T alpha_W,  a_pin_linear = R^T a_W - omega_b x v_b.
Tolerance: |a_dart - a_pin| <= 1e-8 * max(1, |a|) over every coordinate.
"""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from components.constants import NS_PER_S
from components.dynamics.world import BodySpec, OrbitalWorld
from tests import validation

ROOT = Path(__file__).resolve().parents[2]


def random_rotation(rng):
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def free_floating_model(path):
    """Pinocchio model of the URDF on a free flyer, in zero gravity."""
    model = pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer())
    model.gravity = pin.Motion.Zero()
    return model


def pinocchio_state(model, joints, p, quat, v_W, w_W, q, qd):
    R = pin.Quaternion(quat[3], *quat[:3]).toRotationMatrix()
    q_pin = pin.neutral(model)
    v_pin = np.zeros(model.nv)
    q_pin[:3], q_pin[3:7] = p, quat
    v_pin[:3], v_pin[3:6] = R.T @ v_W, R.T @ w_W
    for name, value, rate in zip(joints, q, qd):
        jid = model.getJointId(name)
        q_pin[model.joints[jid].idx_q] = value
        v_pin[model.joints[jid].idx_v] = rate
    return q_pin, v_pin, R


def compare(model, joints, R, v_pin, a_pin, dart):
    v_b, w_b = v_pin[:3], v_pin[3:6]
    lin = R.T @ dart["dv_W_base"][:3] - np.cross(w_b, v_b)
    ang = R.T @ dart["dv_W_base"][3:]
    qdd = np.array([a_pin[model.joints[model.getJointId(n)].idx_v] for n in joints])
    a_ref = np.concatenate([a_pin[:3], a_pin[3:6], qdd])
    a_dart = np.concatenate([lin, ang, dart["qdd"]])
    scale = max(1.0, np.abs(a_ref).max())
    return np.abs(a_dart - a_ref).max() / scale


@pytest.mark.parametrize("urdf", ["humanoid_torso.urdf", "servicer.urdf"])
def test_free_floating_accelerations_match_pinocchio(urdf):
    path = ROOT / "models" / urdf
    world = OrbitalWorld([BodySpec("robot", path)], tidal_force=False, gravity_gradient=False)
    model = free_floating_model(path)
    data = model.createData()
    body = world.bodies["robot"]
    joints = body.joints
    lower = np.array([body.model.joint(j).lower for j in joints])
    upper = np.array([body.model.joint(j).upper for j in joints])
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(20):
        p, quat = rng.normal(size=3), random_rotation(rng)
        v_W, w_W = rng.normal(size=3), rng.normal(size=3)
        q = rng.uniform(lower, upper)
        qd, tau = rng.normal(size=len(joints)), rng.normal(size=len(joints)) * 2.0
        tau = np.clip(tau, -body.effort, body.effort)  # OrbitalWorld clips to the URDF efforts
        world.set_body_state("robot", p, quat, np.concatenate([v_W, w_W]), q, qd)
        world.set_torques("robot", tau)
        dart = world.forward_dynamics("robot")
        q_pin, v_pin, R = pinocchio_state(model, joints, p, quat, v_W, w_W, q, qd)
        tau_pin = np.zeros(model.nv)
        for name, t in zip(joints, tau):
            tau_pin[model.joints[model.getJointId(name)].idx_v] = t
        a_pin = pin.aba(model, data, q_pin, v_pin, tau_pin)
        worst = max(worst, compare(model, joints, R, v_pin, a_pin, dart))
    print(f"{urdf}: max relative difference DART vs Pinocchio {worst:.2e}")
    validation.check("dart_aba", worst)


def test_environment_wrenches_match_pinocchio_external_forces():
    """The per-link tidal force (at the CoM) and gravity-gradient torque applied in DART give the
    accelerations Pinocchio's ABA gives for the same wrenches passed as joint-frame fext. A close,
    light 'planet' (mu 1e12, |R| 10 km) makes the environment comparable to the joint torques."""
    path = ROOT / "models" / "humanoid_torso.urdf"
    mu = 1e12
    world = OrbitalWorld([BodySpec("robot", path)], mu=mu)
    model = free_floating_model(path)
    data = model.createData()
    body = world.bodies["robot"]
    joints = body.joints
    rng = np.random.default_rng(3)
    worst, largest = 0.0, 0.0
    for _ in range(10):
        r_eci = rng.normal(size=3)
        r_eci *= 1e4 / np.linalg.norm(r_eci)
        world.set_orbit(r_eci, np.zeros(3))
        p, quat = rng.normal(size=3) * 0.5, random_rotation(rng)
        v_W, w_W, q = rng.normal(size=3), rng.normal(size=3), rng.uniform(-0.5, 0.5, len(joints))
        qd, tau = rng.normal(size=len(joints)), rng.normal(size=len(joints))
        world.set_body_state("robot", p, quat, np.concatenate([v_W, w_W]), q, qd)
        world.set_torques("robot", tau)
        dart = world.forward_dynamics("robot")
        nodes = [body.link_names.index(bn.getName()) for bn in body.nodes]  # per node (massive link)
        tidal, _drag, torque = (w[nodes] for w in body.environment_wrenches(r_eci, np.zeros(3)))
        largest = max(largest, np.abs(tidal).max(), np.abs(torque).max())
        q_pin, v_pin, R = pinocchio_state(model, joints, p, quat, v_W, w_W, q, qd)
        pin.forwardKinematics(model, data, q_pin)
        pin.updateFramePlacements(model, data)
        fext = [pin.Force.Zero() for _ in range(model.njoints)]
        for bn, f, t in zip(body.nodes, tidal, torque):
            frame = model.frames[model.getFrameId(bn.getName(), pin.BODY)]
            c = np.array(bn.getCOM())
            wrench_W = pin.Force(f, t + np.cross(c, f))  # about the W origin
            fext[frame.parentJoint] += data.oMi[frame.parentJoint].actInv(wrench_W)
        tau_pin = np.zeros(model.nv)
        for name, value in zip(joints, tau):
            tau_pin[model.joints[model.getJointId(name)].idx_v] = value
        a_pin = pin.aba(model, data, q_pin, v_pin, tau_pin, fext)
        worst = max(worst, compare(model, joints, R, v_pin, a_pin, dart))
    print(f"environment wrenches up to {largest:.2g}: max relative difference {worst:.2e}")
    assert largest > 1.0
    validation.check("dart_aba", worst)


def test_link_poses_match_pinocchio_frames():
    """link_position / link_orientation outputs (tool frames included) against Pinocchio's
    frame placements for random configurations: 1e-12."""
    path = ROOT / "models" / "humanoid_torso.urdf"
    world = OrbitalWorld([BodySpec("robot", path)])
    model = free_floating_model(path)
    data = model.createData()
    body = world.bodies["robot"]
    rng = np.random.default_rng(11)
    for _ in range(5):
        p, quat, q = rng.normal(size=3), random_rotation(rng), rng.uniform(-1, 1, len(body.joints))
        world.set_body_state("robot", p, quat, np.zeros(6), q)
        out = world.link_outputs("robot")
        positions = out["link_position"].reshape(-1, 3)
        orientations = out["link_orientation"].reshape(-1, 4)
        q_pin, _, _ = pinocchio_state(model, body.joints, p, quat, np.zeros(3), np.zeros(3), q, np.zeros(len(q)))
        pin.framesForwardKinematics(model, data, q_pin)
        for link, position, orientation in zip(body.link_names, positions, orientations):
            placement = data.oMf[model.getFrameId(link)]
            assert np.allclose(position, placement.translation, atol=1e-12), link
            R = pin.Quaternion(orientation[3], *orientation[:3]).toRotationMatrix()
            assert np.allclose(R, placement.rotation, atol=1e-12), link


def test_demo_humanoid_under_recorded_torques_matches_pinocchio_aba_and_dop853():
    """The paper's demo (configs/humanoid_tracking.yaml) run for 3 s in process; then its recorded
    joint torques drive an independent model of the same free-floating humanoid: Pinocchio's ABA
    (left arm locked, as in the config), the tidal force and gravity-gradient torque on every body
    written here from mu / r^3 (3 u u^T - 1) and 3 mu / r^3 (u x I u), the orbit point interpolated
    (cubic Hermite) between the recorded orbit samples, integrated by scipy's DOP853 (rtol 1e-12)
    with each step's torque held over the step (Jacobi: row k's torque acts on [t_k, t_k+1)).
    Started once from the recorded state at t = 0, it must stay within 1e-9 (m, rad) of DART's
    base position, attitude and joint angles at every step (measured 2e-12). Without the
    environment the difference grows to 1.5e-5 rad in 3 s."""
    from scipy.integrate import solve_ivp

    from components.constants import MU_EARTH
    from orchestrator.config.load import load
    from orchestrator.run.inprocess import run_in_process

    config = load(ROOT / "configs" / "humanoid_tracking.yaml", ["run.duration=3 s"])
    rows = run_in_process(config)
    columns = [c for spec in config.components.values() for v in spec.outputs.variables for c in v.columns(spec.name)]

    def column(name):
        return rows[:, [i for i, c in enumerate(columns) if c.startswith(name + "[")]]

    body = config.components["dynamics"].parameters["bodies"]["humanoid"]
    joints = OrbitalWorld([BodySpec("robot", ROOT / "models" / "humanoid_torso.urdf")]).bodies["robot"].joints
    full = free_floating_model(ROOT / "models" / "humanoid_torso.urdf")
    locked = [full.getJointId(j) for j in body["locked_joints"]]
    model = pin.buildReducedModel(full, locked, pin.neutral(full))  # the config locks the left arm at 0
    model.gravity = pin.Motion.Zero()
    data = model.createData()
    moving = [joints.index(model.names[i]) for i in range(2, model.njoints)]  # joint columns, model order
    tau, r_eci, v_eci = column("controller.tau")[:, moving], column("orbit.r_eci"), column("orbit.v_eci")
    position, orientation, twist = (column(f"dynamics.humanoid.{k}") for k in ("position", "orientation", "twist"))
    q, qd = column("dynamics.humanoid.q")[:, moving], column("dynamics.humanoid.qd")[:, moving]
    bodies = range(1, model.njoints)
    mass = np.array([model.inertias[i].mass for i in bodies])
    lever = np.array([model.inertias[i].lever for i in bodies])
    inertia = np.array([model.inertias[i].inertia for i in bodies])
    h = config.step_ns / NS_PER_S

    def orbit_point(k, s):  # cubic Hermite between the samples at t_k and t_k+1
        return (
            (2 * s**3 - 3 * s**2 + 1) * r_eci[k]
            + (s**3 - 2 * s**2 + s) * h * v_eci[k]
            + (-2 * s**3 + 3 * s**2) * r_eci[k + 1]
            + (s**3 - s**2) * h * v_eci[k + 1]
        )

    def rates(t, y, k, torque):
        x, v = y[: model.nq].copy(), y[model.nq :]
        x[3:7] /= np.linalg.norm(x[3:7])
        r = orbit_point(k, t / h)
        g, u = MU_EARTH / np.linalg.norm(r) ** 3, r / np.linalg.norm(r)
        pin.forwardKinematics(model, data, x)
        R = np.array([data.oMi[i].rotation for i in bodies])
        com = np.einsum("ijk,ik->ij", R, lever) + np.array([data.oMi[i].translation for i in bodies])
        force = g * mass[:, None] * (3 * (com @ u)[:, None] * u - com)  # W axes, at each CoM
        f_local = np.einsum("ijk,ij->ik", R, force)
        u_local = np.einsum("ijk,j->ik", R, u)
        moment = 3 * g * np.cross(u_local, np.einsum("ijk,ik->ij", inertia, u_local)) + np.cross(lever, f_local)
        fext = [pin.Force.Zero()] + [pin.Force(f, m) for f, m in zip(f_local, moment)]
        a = pin.aba(model, data, x, v, np.concatenate([np.zeros(6), torque]), fext)
        xq, w = x[3:7], v[3:6]  # quaternion [x, y, z, w], body angular velocity
        dquat = 0.5 * np.concatenate([xq[3] * w + np.cross(xq[:3], w), [-xq[:3] @ w]])
        R_base = pin.Quaternion(xq[3], *xq[:3]).toRotationMatrix()
        return np.concatenate([R_base @ v[:3], dquat, v[6:], a])

    def recorded(k):
        R_base = pin.Quaternion(orientation[k][3], *orientation[k][:3]).toRotationMatrix()
        x = np.concatenate([position[k], orientation[k], q[k]])
        return x, np.concatenate([R_base.T @ twist[k][:3], R_base.T @ twist[k][3:], qd[k]])

    x, v = recorded(0)
    worst = np.zeros(3)
    for k in range(len(rows) - 1):
        y = solve_ivp(
            rates,
            (0.0, h),
            np.concatenate([x, v]),
            method="DOP853",
            rtol=1e-12,
            atol=1e-14,
            first_step=h,
            args=(k, tau[k]),
        ).y[:, -1]
        x, v = y[: model.nq], y[model.nq :]
        x[3:7] /= np.linalg.norm(x[3:7])
        d = pin.difference(model, x, recorded(k + 1)[0])
        worst = np.maximum(worst, [np.abs(d[:3]).max(), np.abs(d[3:6]).max(), np.abs(d[6:]).max()])
    moved = np.abs(q[-1] - q[0]).max()
    print(
        f"3 s of the demo (joints moved up to {moved:.3f} rad): DART vs Pinocchio ABA + DOP853: "
        f"base position {worst[0]:.1e} m, attitude {worst[1]:.1e} rad, joints {worst[2]:.1e} rad"
    )
    assert moved > 0.01
    validation.check("dart_arm_trajectory", worst.max())
