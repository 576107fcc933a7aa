"""dynamics.pinocchio against dynamics.dart: the same parameters and inputs give the same outputs,
every one, to 1e-9 over seconds, and the state of either continues in the other.

The two types integrate the same equations with the same integrator in the same coordinates
(components/dynamics/world.py); only the forward dynamics, mass matrix and kinematics come from
two libraries (DART's articulated-body algorithm against Pinocchio's ABA), independent to
rounding. Each scenario is a closed loop (joint torques from the outputs, as a controller's), on
a circular orbit with the environment on: tidal force and gravity-gradient torque on every link,
drag where a link has an area. Tolerance: |dart - pinocchio| <= 1e-9 max(1, |dart|) per element
(measured ~1e-12).

The bodies' attitudes stay away from the identity: DART's transform of a FreeJoint rotation vector
shorter than 1e-3 rad is a truncated series (off by |phi|^3 / 6, up to 1.7e-10; Pinocchio's and
the integrator's are exact), which a weld's stabilization then feeds back (1e-8 in a capture).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from components.testing.harness import Harness
from tests import validation
from tests.conftest import shipped_configs

ROOT = Path(__file__).resolve().parents[2]
CONFIGS, MODELS = ROOT / "configs", ROOT / "models"
MS = 1_000_000
MU = 3.986004418e14
TOLERANCE = 1e-9
DEMO = yaml.safe_load((CONFIGS / "humanoid_tracking.yaml").read_text())["components"]["dynamics"]["parameters"]


def circular(t: float, a: float = 6778e3) -> dict[str, np.ndarray]:
    """An equatorial circular orbit, 1 rad along it at t = 0 (LVLH is not W's axes)."""
    n = math.sqrt(MU / a**3)
    th = n * t + 1.0
    return {
        "r_eci": a * np.array([math.cos(th), math.sin(th), 0.0]),
        "v_eci": a * n * np.array([-math.sin(th), math.cos(th), 0.0]),
        "q_eci_lvlh": np.array([0.0, 0.0, math.sin(th / 2), math.cos(th / 2)]),
        "w_lvlh": np.array([0.0, 0.0, n]),
    }


def harness(engine: str, params: dict, t0_ns: int = 0) -> Harness:
    return Harness(f"dynamics.{engine}", params, config_dir=CONFIGS, t0_ns=t0_ns)


def pd_torques(out: dict, body: str, k: int, q0: np.ndarray) -> np.ndarray:
    """A PD law towards a posture that swings slowly (0.2 rad at 0.5 Hz) around the start."""
    target = q0 + 0.2 * math.sin(math.pi * k * 1e-3)
    return 2.0 * (target - out[f"{body}.q"]) - 0.5 * out[f"{body}.qd"]


def run(h: Harness, steps: int, torques=None, close_at: int | None = None) -> list[dict]:
    """``steps`` steps of 1 ms from h's time (initialized first if it was not); the outputs of each."""
    bodies = [v.name[:-4] for v in h.input_layout.variables if v.name.endswith(".tau")]
    if h.t_ns == 0:
        h.inputs.update(circular(0.0))
        out = h.initialize()
    else:
        out = h.outputs
    q0 = {b: out[f"{b}.q"].copy() for b in bodies}
    history = []
    for _ in range(steps):
        k = h.t_ns // MS
        h.inputs.update(circular(k * 1e-3))
        for b in bodies:
            h.inputs[f"{b}.tau"] = torques(out, b, k) if torques else pd_torques(out, b, k, q0[b])
        if close_at is not None and k >= close_at:
            h.inputs["grasp.close"] = 1.0
        out = h.step(MS)
        history.append(out)
    return history


def assert_agree(got: list[dict], expected: list[dict], what: str) -> float:
    """Every output at every step within TOLERANCE; the largest relative difference."""
    worst = 0.0
    for k, (a, b) in enumerate(zip(expected, got)):
        assert a.keys() == b.keys()
        for key in a:
            difference = np.abs(a[key] - b[key]) / np.maximum(1.0, np.abs(a[key]))
            assert difference.max(initial=0.0) <= TOLERANCE, f"{what}: {key} at step {k + 1}: {difference.max():.2e}"
            worst = max(worst, difference.max(initial=0.0))
    print(f"{what}: largest difference {worst:.1e} over {len(got)} steps and {len(got[0])} outputs")
    return worst


def both(params: dict, steps: int, **kw) -> tuple[list[dict], list[dict]]:
    return run(harness("dart", params), steps, **kw), run(harness("pinocchio", params), steps, **kw)


def test_demo_humanoid_every_output_agrees():
    """The demo's humanoid (left arm locked, LVLH start), with the per-link outputs (poses, tidal
    forces, gravity-gradient torques), the CoM frame relative to LVLH and the base IMU, 3 s."""
    params = {**DEMO, "link_outputs": True, "frame_outputs": True, "imu": ["humanoid"]}
    dart, pinocchio = both(params, 3000)
    assert np.abs(dart[-1]["humanoid.qd"]).max() > 0.05 and np.abs(dart[-1]["humanoid.gg_torque"]).max() > 0.0
    validation.check("pinocchio_dart", assert_agree(pinocchio, dart, "humanoid"))


def test_servicer_with_wheels_and_drag_agrees():
    """The capture servicer: a six-joint arm and three continuous reaction wheels (Pinocchio's
    (cos, sin) joints), drag on the bus (a 300 km orbit, where it is largest), 2 s."""
    params = {
        "drag": True,
        "frame_outputs": True,
        "imu": ["servicer"],
        "link_outputs": True,
        "bodies": {
            "servicer": {
                "urdf": "../models/capture/servicer.urdf",
                "frame": "lvlh",
                "drag_area": {"bus": 4.0},
                "q": {"arm_2_joint": 0.6, "arm_3_joint": 1.0},
                "qd": {"wheel_z_joint": 20.0},
                "twist": [0, 0, 0, 0.01, -0.02, 0.03],
            }
        },
    }
    dart, pinocchio = both(params, 2000)
    assert np.abs(dart[-1]["servicer.drag_force"]).max() > 0.0
    validation.check("pinocchio_dart", assert_agree(pinocchio, dart, "servicer"))


def slider_urdf(tmp_path: Path) -> Path:
    """A base with a prismatic slide carrying an arm (revolute) and two fingers on prismatic
    joints, the second a mimic of the first (a gripper)."""

    def link(name, mass, size):
        return (
            f'<link name="{name}"><inertial><origin xyz="0.02 0.01 0" rpy="0.1 0.2 0.3"/><mass value="{mass}"/>'
            f'<inertia ixx="{size}" iyy="{1.2 * size}" izz="{1.4 * size}" ixy="{0.05 * size}" ixz="0" iyz="0"/></inertial></link>'
        )

    def joint(name, kind, parent, child, xyz, axis, limit="-0.5 0.5", mimic=""):
        lower, upper = limit.split()
        return (
            f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{xyz}" rpy="0 0.3 0"/><axis xyz="{axis}"/>'
            f'<limit lower="{lower}" upper="{upper}" effort="5" velocity="1"/>{mimic}</joint>'
        )

    text = (
        "<robot name='slider'>"
        + link("base", 20, 1.0)
        + link("carriage", 2, 0.05)
        + link("arm", 1, 0.02)
        + link("finger_a", 0.1, 0.001)
        + link("finger_b", 0.1, 0.001)
        + joint("slide", "prismatic", "base", "carriage", "0.3 0 0.1", "1 0 0")
        + joint("hinge", "revolute", "carriage", "arm", "0 0 0.2", "0 0.6 0.8", "-2 2")
        + joint("finger_a_joint", "prismatic", "arm", "finger_a", "0.2 0.02 0", "0 1 0", "0 0.05")
        + joint(
            "finger_b_joint",
            "prismatic",
            "arm",
            "finger_b",
            "0.2 -0.02 0",
            "0 -1 0",
            "0 0.05",
            '<mimic joint="finger_a_joint" multiplier="1" offset="0"/>',
        )
        + "</robot>"
    )
    path = tmp_path / "slider.urdf"
    path.write_text(text)
    return path


def test_prismatic_joints_and_a_mimic_finger_agree(tmp_path):
    """A prismatic slide, a revolute on it and a gripper whose second finger mimics the first, 2 s:
    the fingers stay together (mimic) and every output agrees."""
    params = {
        "link_outputs": True,
        "bodies": {
            "s": {
                "urdf": str(slider_urdf(tmp_path)),
                "q": {"finger_a_joint": 0.02},
                "qd": {"slide": 0.05, "hinge": -0.3},
            }
        },
    }
    dart, pinocchio = both(params, 2000)
    q = pinocchio[-1]["s.q"]
    assert q[3] == pytest.approx(q[2], abs=1e-12) and abs(dart[-1]["s.q"][0]) > 0.01
    validation.check("pinocchio_dart", assert_agree(pinocchio, dart, "slider"))


def test_a_joint_resting_on_its_limit_agrees():
    """The humanoid's right wrist pushed against its upper stop by 0.2 N m, the rest of the arm
    free, 1.5 s: it reaches the stop, rests there (in both the stop is in the state) and every
    output agrees."""
    params = {"bodies": {"humanoid": {"urdf": "../models/humanoid_torso.urdf"}}}
    wrist = 13  # arm_right_7_joint in URDF order

    def pushed(out, body, k):
        tau = np.zeros(14)
        tau[wrist] = 0.2
        return tau

    hs = {engine: harness(engine, params) for engine in ("dart", "pinocchio")}
    runs = {engine: run(h, 1500, torques=pushed) for engine, h in hs.items()}
    from components.bus import decode_state

    for h in hs.values():
        assert decode_state(h.get_state())["humanoid.stop_side"][wrist] == 1.0
    validation.check("pinocchio_dart", assert_agree(runs["pinocchio"], runs["dart"], "wrist on its stop"))


def test_capture_grasp_and_weld_agree():
    """Two bodies, the grasp closing at 2 ms (the impact) and the arm then driven against the
    welded target for 1 s: the weld's wrench, the relative frames and both bodies agree."""
    arm = {f"arm_{i}_joint": v for i, v in zip(range(1, 7), [0.3, 0.5, 0.9, -0.2, 0.4, 0.1])}
    params = {
        "bodies": {
            "servicer": {"urdf": "../models/servicer.urdf", "q": arm, "orientation": [0.2, -0.1, 0.3, 0.92]},
            "target": {
                "urdf": "../models/target.urdf",
                "position": [1.6, 0.3, 2.6],
                "orientation": [0.1, 0.2, 0.05, 0.97],
                "twist": [0.01, -0.02, 0.005, 0.03, -0.02, 0.04],
            },
        },
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
            "force_limit": "1e6 N",
            "torque_limit": "1e6 N*m",
        },
    }
    dart, pinocchio = both(params, 1000, close_at=1)
    assert dart[1]["grasp.closed"] == 1.0 and np.abs(dart[-1]["grasp.wrench"]).max() > 0.1
    validation.check("pinocchio_dart", assert_agree(pinocchio, dart, "capture"))


@pytest.mark.parametrize("first, second", [("dart", "pinocchio"), ("pinocchio", "dart")])
def test_state_handed_over_between_engines_continues(first, second):
    """The demo's humanoid run 1 s on one engine, its state (get_state, through the bus encoding)
    set into the other, never initialized: the next second agrees with the first engine going on."""
    a = harness(first, DEMO)
    run(a, 1000)
    b = harness(second, DEMO, t0_ns=a.t_ns)
    b.set_state(a.get_state())
    b._outputs = a._outputs.copy()  # the outputs it starts from (the swap's)
    assert_agree(run(b, 1000), run(a, 1000), f"{first} -> {second}")


def shipped_configs_for_both_engines():
    """(config, dynamics component) of every shipped config whose dynamics suits both engines (rk4)."""
    for config in shipped_configs():
        path = config.values[0]
        for name, entry in yaml.safe_load(path.read_text())["components"].items():
            if entry["type"] == "dynamics.dart" and (entry.get("parameters") or {}).get("integrator", "rk4") == "rk4":
                yield pytest.param(path.name, name, marks=config.marks)


@pytest.mark.parametrize("config, component", list(shipped_configs_for_both_engines()))
def test_shipped_config_runs_with_both_engines(config, component):
    """The config stepped in process (orchestrator/run/inprocess.py, as a bus run would), 200 steps
    with its dynamics' type as shipped and with ``--set components.<dynamics>.type=dynamics.pinocchio``:
    every recorded column agrees."""
    from orchestrator.config.load import load
    from orchestrator.run.inprocess import run_in_process

    rows = {
        engine: run_in_process(load(CONFIGS / config, [f"components.{component}.type=dynamics.{engine}"]), steps=200)
        for engine in ("dart", "pinocchio")
    }
    difference = np.abs(rows["pinocchio"] - rows["dart"]) / np.maximum(1.0, np.abs(rows["dart"]))
    print(f"{config}: largest difference {difference.max():.1e}")
    assert difference.max() <= TOLERANCE
