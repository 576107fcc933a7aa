"""Controller components through the in-process harness: closed loops with dynamics.dart (one
step of delay, as a Jacobi run), outputs consistent with each other, state hand-over on a swap,
bad configs as ConfigErrors naming the key."""

from pathlib import Path

import numpy as np
import pytest

from components.errors import ConfigError
from components.testing.harness import Harness

ROOT = Path(__file__).resolve().parents[2]
URDF = str(ROOT / "models" / "humanoid_torso.urdf")
MS = 1_000_000
ARM = [f"arm_right_{i}_joint" for i in range(1, 8)]
LEFT = [f"arm_left_{i}_joint" for i in range(1, 8)]
START = dict(zip(ARM, [-0.72, -2.29, -1.85, -1.91, -0.79, 0.61, 0.22]))  # the demo's posture
STATE = ("position", "orientation", "twist", "q", "qd")


def dynamics():
    return Harness(
        "dynamics.dart",
        {
            "tidal_force": False,
            "gravity_gradient": False,
            "link_outputs": False,
            "bodies": {"humanoid": {"urdf": URDF, "q": START, "locked_joints": LEFT}},
        },
    )


def computed_torque(t0_ns=0, **overrides):
    params = {
        "urdf": URDF,
        "joints": ARM,
        "end_effector": "arm_right_tool_link",
        "locked_joints": LEFT,
        "trajectory": {
            "type": "waypoints",
            "start": 0.1,
            "axes": "body",
            "waypoints": [{"time": 1.1, "position": [0.05, 0.0, 0.02], "rotation": [0.0, 0.0, 0.1]}],
        },
    }
    params.update(overrides)
    return Harness("controller.computed_torque", params, t0_ns=t0_ns)


def connect(plant_outputs, controller):
    for name in STATE:
        controller.inputs[name] = plant_outputs[f"humanoid.{name}"]


def closed_loop(controller, steps, plant=None, record=None, swap_at=None, make=None):
    """Jacobi at 1 kHz: the controller sees the plant's state of the step before."""
    plant = plant or dynamics()
    state = plant.initialize()
    connect(state, controller)
    out = controller.initialize()
    for k in range(steps):
        plant.inputs["humanoid.tau"] = out["tau"]
        connect(state, controller)
        if swap_at is not None and k == swap_at:
            controller = swap_at_boundary(controller, make)
        out = controller.step(MS)
        state = plant.step(MS)
        if record is not None:
            record.append(out)
    return out, state


def swap_at_boundary(old, make):
    """What the orchestrator does on a same-type swap: a new instance at the current time, given
    the old one's state and never initialized (a ``make`` whose set_state ignores the state leaves
    it to initialize at its first step, as a swap to another type does)."""
    new = make(t0_ns=old.t_ns)
    new.inputs.update(old.inputs)
    new.set_state(old.get_state())
    return new


def test_closed_loop_tracks_a_waypoint_move():
    record = []
    out, _state = closed_loop(computed_torque(), 1500, record=record)
    error = np.array([r["ee_error"] for r in record])
    tau = np.array([r["tau"] for r in record])
    print(
        f"max position error {np.abs(error[:, :3]).max():.2e} m, orientation {np.abs(error[:, 3:]).max():.2e} rad, "
        f"max |tau| {np.abs(tau).max():.3f} N m"
    )
    assert np.linalg.norm(error[-1, :3]) < 1e-5 and np.linalg.norm(error[-1, 3:]) < 1e-4
    assert np.abs(error[:, :3]).max() < 1e-4
    driven = np.isin(np.arange(14), np.arange(7, 14))  # right arm: URDF joints 7..13
    assert not np.any(tau[:, ~driven]) and np.any(tau[:, driven])
    # outputs consistent with each other: error = desired - obtained, the end effector moved 5.4 cm
    assert np.allclose(out["ee_error"][:3], out["ee_position_desired"] - out["ee_position"])
    first = record[0]
    assert np.linalg.norm(out["ee_position"] - first["ee_position"]) == pytest.approx(np.hypot(0.05, 0.02), abs=1e-4)
    assert 0.05 < float(out["sigma_min"]) < 2.0
    assert np.linalg.norm(out["ee_orientation"]) == pytest.approx(1.0)


def test_gains_kp_kd_take_one_number_for_all_six_axes():
    """kp: 50 (docs/design.md §5's `--set components.controller.parameters.kp=50`) is kp: [50] * 6; units
    work in either form. The closed loops are bit-identical, and differ from the default gains."""
    one, _ = closed_loop(computed_torque(kp=50, kd="10 Hz"), 300)
    six, _ = closed_loop(computed_torque(kp=[50] * 6, kd=[10, 10, 10, 10, 10, "10 Hz"]), 300)
    default, _ = closed_loop(computed_torque(), 300)
    for key in one:
        assert np.array_equal(one[key], six[key]), key
    assert not np.array_equal(one["tau"], default["tau"])
    arm = computed_torque(kp=50).component.arm
    assert arm.kp.tolist() == [50.0] * 6 and arm.kd.tolist() == [20.0] * 6  # default kd: 20


def test_swap_hands_the_trajectory_over():
    """A same-type swap mid-move (new instance, set_state, no initialize) continues
    bit-identically: the trajectory stays anchored at the run's initial pose."""
    reference, _ = closed_loop(computed_torque(), 600)
    swapped, _ = closed_loop(computed_torque(), 600, swap_at=300, make=computed_torque)
    for key in reference:
        assert np.array_equal(reference[key], swapped[key]), key
    # without the hand-over the new instance would re-anchor at the current pose
    unhanded, _ = closed_loop(computed_torque(), 600, swap_at=300, make=lambda t0_ns: _initialized(t0_ns))
    assert not np.array_equal(reference["ee_position_desired"], unhanded["ee_position_desired"])
    c = computed_torque()
    c.inputs.update({"q": np.array([0.0] * 7 + list(START.values())), "orientation": [0, 0, 0, 1.0]})
    c.initialize()
    with pytest.raises(ValueError, match="ee_position_0"):
        c.component.set_state({"q_posture": np.zeros(7)})


def test_controller_initialized_before_the_dynamics_anchors_at_the_first_real_state():
    """Listed before the dynamics (initialized with its inputs' start values), the controller
    re-anchors at the first state it steps from, and tracks the same path."""
    reference, _ = closed_loop(computed_torque(), 300)
    plant, controller = dynamics(), computed_torque()
    out = controller.initialize()  # inputs at their start values: q = 0, identity
    state = plant.initialize()
    for _ in range(300):
        plant.inputs["humanoid.tau"] = out["tau"]
        connect(state, controller)
        out = controller.step(MS)
        state = plant.step(MS)
    assert np.allclose(out["ee_position_desired"], reference["ee_position_desired"], atol=1e-12)
    assert np.linalg.norm(out["ee_error"][:3]) < 1e-4


def test_a_locked_joint_that_moves_stops_the_controller():
    plant = Harness(
        "dynamics.dart",
        {
            "tidal_force": False,
            "gravity_gradient": False,
            "link_outputs": False,
            "bodies": {"humanoid": {"urdf": URDF, "q": START, "qd": {"arm_left_4_joint": 0.1}}},
        },
    )
    with pytest.raises(ValueError, match="locked_joints: arm_left_4_joint moves"):
        closed_loop(computed_torque(), 5, plant=plant)


def _initialized(t0_ns):
    """A swap without hand-over: set_state is a no-op, so the new instance initializes at its
    first step, at the current state."""
    h = computed_torque(t0_ns=t0_ns)
    h.set_state = lambda blob: None
    return h


def test_joint_pd_drives_joints_to_targets_and_along_waypoints():
    gains = {j: {"p": 20.0, "d": 3.0, "i": 1.0, "i_clamp": 0.2} for j in ARM[:4]}  # shoulder, elbow
    gains.update({j: {"p": 1.0, "d": 0.05} for j in ARM[4:]})  # light wrist links
    controller = Harness(
        "controller.joint_pd",
        {
            "urdf": URDF,
            "gains": gains,
            "targets": {"arm_right_4_joint": -1.5},
            "trajectory": {
                "start": 0.2,
                "waypoints": [
                    {"time": 1.2, "q": {"arm_right_1_joint": -0.5}},
                    {"time": 2.0, "q": {"arm_right_2_joint": -2.0}},
                ],
            },
        },
    )
    record = []
    out, state = closed_loop(controller, 3000, record=record)
    q = state["humanoid.q"]
    index = {j: k for k, j in enumerate(ARM, start=7)}
    assert q[index["arm_right_4_joint"]] == pytest.approx(-1.5, abs=5e-3)
    assert q[index["arm_right_1_joint"]] == pytest.approx(-0.5, abs=5e-3)
    assert q[index["arm_right_2_joint"]] == pytest.approx(-2.0, abs=5e-3)
    assert q[index["arm_right_7_joint"]] == pytest.approx(START["arm_right_7_joint"], abs=5e-3)
    assert np.allclose(out["q_desired"][7:], [-0.5, -2.0, -1.85, -1.5, -0.79, 0.61, 0.22])
    tau = np.array([r["tau"] for r in record])
    assert not np.any(tau[:, :7])
    efforts = np.array([44.64, 22.32, 17.86, 17.86, 3.0, 6.6, 6.6])
    assert np.all(np.abs(tau[:, 7:]) <= efforts)


def test_joint_pd_saturates_at_the_urdf_effort():
    controller = Harness(
        "controller.joint_pd",
        {"urdf": URDF, "gains": {"arm_right_5_joint": {"p": 1000.0}}, "targets": {"arm_right_5_joint": 2.0}},
    )
    controller.inputs["q"] = np.zeros(14)
    out = controller.initialize()
    assert out["tau"][ARM.index("arm_right_5_joint") + 7] == 3.0  # URDF effort of joint 5


@pytest.mark.parametrize(
    "overrides, key",
    [
        ({"end_effector": "arm_right_hand"}, "end_effector"),
        ({"end_effector": "torso"}, "end_effector"),
        ({"joints": ARM[:6] + ["arm_right_8_joint"]}, "joints"),
        ({"joints": ARM + ["arm_left_1_joint"], "locked_joints": []}, "joints"),  # does not move the right hand
        ({"joints": ARM, "locked_joints": ["arm_right_3_joint"]}, "locked_joints"),
        ({"kp": [100, 100, 100, 100, 100]}, "kp"),
        ({"kd": [1, 2, 3, 4, 5, 6, 7]}, "kd"),
        ({"kp": -1}, "kp"),
        ({"kd": "fast"}, "kd"),
        ({"null_kp": [1, 2, 3]}, "null_kp"),
        ({"base_model": "floating"}, "base_model"),
        ({"urdf": "models/nothing.urdf"}, "urdf"),
        ({"trajectory": {"type": "parabola", "duration": "10 s", "displacement": "2 m"}}, "trajectory.displacement"),
        (
            {"trajectory": {"type": "waypoints", "waypoints": [{"time": 1, "position": [0, 0, 1.7]}]}},
            "trajectory.waypoints[0].position",
        ),
    ],
)
def test_computed_torque_bad_config_names_the_key(overrides, key):
    with pytest.raises(ConfigError) as error:
        computed_torque(**overrides)
    assert error.value.key == key
    print(error.value)


def test_trajectory_out_of_reach_of_the_initial_pose_is_caught_at_initialize():
    """1.0 m sideways is within twice the arm's reach (the check without the initial pose) but
    not within reach of the shoulder from the demo's start posture."""
    controller = computed_torque(
        trajectory={
            "type": "waypoints",
            "waypoints": [{"time": 1.0, "position": [0.1, 0.0, 0.0]}, {"time": 2.0, "position": [0.0, -1.0, 0.0]}],
        }
    )
    controller.inputs.update({"q": np.array([0.0] * 7 + list(START.values()))})
    with pytest.raises(ConfigError) as error:
        controller.initialize()
    assert error.value.key == "trajectory.waypoints[1].position"
    assert "out of reach" in str(error.value)


@pytest.mark.parametrize(
    "params, key",
    [
        ({"gains": {"arm_right_9_joint": {"p": 1}}}, "gains.arm_right_9_joint"),
        ({"gains": {"arm_right_1_joint": {"d": 1}}}, "gains.arm_right_1_joint.p"),
        ({"gains": {"arm_right_1_joint": {"p": -1}}}, "gains.arm_right_1_joint.p"),
        ({"gains": {"arm_right_1_joint": {"p": 1, "k": 2}}}, "gains.arm_right_1_joint.k"),
        (
            {"gains": {"arm_right_1_joint": {"p": 1}}, "targets": {"arm_right_1_joint": 2.0}},
            "targets.arm_right_1_joint",
        ),
        (
            {"gains": {"arm_right_1_joint": {"p": 1}}, "targets": {"arm_right_2_joint": 0.0}},
            "targets.arm_right_2_joint",
        ),
        (
            {
                "gains": {"arm_right_1_joint": {"p": 1}},
                "trajectory": {"waypoints": [{"time": 1, "q": {"arm_right_1_joint": 5}}]},
            },
            "trajectory.waypoints[0].q.arm_right_1_joint",
        ),
    ],
)
def test_joint_pd_bad_config_names_the_key(params, key):
    with pytest.raises(ConfigError) as error:
        Harness("controller.joint_pd", {"urdf": URDF, **params})
    assert error.value.key == key


def test_end_effector_quaternions_keep_their_sign_while_the_base_turns():
    """The base turned through a full turn about z (inputs given open loop): q_W_ee passes w = 0,
    and ee_orientation never jumps to -q from one step to the next, through a swap's hand-over too."""

    def turned(c, k):
        angle = 2 * np.pi * k / 400
        c.inputs.update(
            {
                "q": np.array([0.0] * 7 + list(START.values())),
                "qd": np.zeros(14),
                "orientation": np.array([0.0, 0.0, np.sin(angle / 2), np.cos(angle / 2)]),
            }
        )

    c = computed_torque()
    turned(c, 0)
    series = [c.initialize()["ee_orientation"].copy()]
    for k in range(1, 401):
        turned(c, k)
        if k == 250:
            c = swap_at_boundary(c, computed_torque)
        series.append(c.step(MS)["ee_orientation"].copy())
    q = np.array(series)
    assert np.min(np.einsum("ti,ti->t", q[1:], q[:-1])) > 0.99  # 1/400 turn per step
    assert np.ptp(np.sign(q[:, 3])) == 2  # w did change sign


def test_under_gauss_seidel_the_reference_is_taken_at_the_states_sample_time():
    """The demo stepped in process. Under Gauss-Seidel the controller steps on the state at
    t_(k+1) (the dynamics comes first), so it samples its reference there: its desired pose at row
    r equals the Jacobi run's at row r + 1, bit for bit, through the start of the move (t > 1 s);
    and it keeps the anchor of the initial state (no re-anchoring on the first step's new state)."""
    from orchestrator.config.load import load
    from orchestrator.run.inprocess import run_in_process

    desired = {}
    for algorithm in ("jacobi", "gauss-seidel"):
        config = load(ROOT / "configs" / "humanoid_tracking.yaml", ["run.duration=1.3 s", f"run.algorithm={algorithm}"])
        columns = [c for s in config.components.values() for v in s.outputs.variables for c in v.columns(s.name)]
        i = columns.index("controller.ee_position_desired[0]")
        desired[algorithm] = run_in_process(config)[:, i : i + 3]
    jacobi, gauss_seidel = desired["jacobi"], desired["gauss-seidel"]
    assert np.linalg.norm(jacobi[-1] - jacobi[0]) > 1e-6  # the move has begun
    assert np.array_equal(gauss_seidel[1:-1], jacobi[2:])
