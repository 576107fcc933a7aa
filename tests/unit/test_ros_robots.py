"""Robots as ROS packages ship them (package:// URIs, xacro, mimic joints, .dae visuals), physics
that cannot be right refused or flagged, and the recording directory's lock. No processes."""

from __future__ import annotations

import multiprocessing
import os
import signal
import textwrap
from pathlib import Path

import numpy as np
import pytest

from components.errors import ConfigError
from components.robots.packages import resolve_uri
from components.robots.urdf import read_urdf
from components.robots.urdf_elements import UrdfError
from tests.conftest import ROOT, needs

PANDA_BUS = ROOT / "models" / "ros" / "panda_on_bus.urdf.xacro"
needs_robots = needs("robots", "the Panda of example-robot-data")


def urdf(tmp_path: Path, body: str, name: str = "robot.urdf") -> Path:
    path = tmp_path / name
    path.write_text(f'<robot name="r">{textwrap.dedent(body)}</robot>')
    return path


BASE = """<link name="base"><inertial><mass value="10"/>
  <inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial></link>"""


def arm(inertia: str = 'ixx="0.1" iyy="0.1" izz="0.1"', mass: str = "1") -> str:
    return (
        BASE
        + f'''<link name="arm"><inertial><mass value="{mass}"/>
      <inertia {inertia} ixy="0" ixz="0" iyz="0"/></inertial></link>
      <joint name="j" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
      <limit lower="-1" upper="1" effort="10" velocity="1"/></joint>'''
    )


# ---------------------------------------------------------------- package:// and xacro


def mesh_package(tmp_path: Path, name: str = "my_robot") -> Path:
    package = tmp_path / "src" / name
    (package / "meshes").mkdir(parents=True)
    (package / "package.xml").write_text(f"<package><name>{name}</name></package>")
    (package / "meshes" / "box.stl").write_text("solid box\nendsolid box\n")
    return package


def mesh_urdf(tmp_path: Path, uri: str) -> Path:
    return urdf(
        tmp_path,
        f'''<link name="base"><inertial><mass value="1"/>
        <inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial>
        <visual><geometry><mesh filename="{uri}"/></geometry></visual></link>''',
    )


def test_package_uri_from_the_packages_map(tmp_path, monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    package = mesh_package(tmp_path)
    model = read_urdf(mesh_urdf(tmp_path, "package://my_robot/meshes/box.stl"), {"my_robot": str(package)})
    assert f'filename="{package / "meshes" / "box.stl"}"' in model.text


def test_package_uri_from_ros_package_path(tmp_path, monkeypatch):
    package = mesh_package(tmp_path, "other_name_than_dir")
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "nothing") + os.pathsep + str(tmp_path / "src"))
    model = read_urdf(mesh_urdf(tmp_path, "package://other_name_than_dir/meshes/box.stl"))
    assert str(package / "meshes" / "box.stl") in model.text


def test_unresolved_package_names_the_uri_and_where_it_looked(tmp_path, monkeypatch):
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path))
    with pytest.raises(UrdfError) as error:
        read_urdf(mesh_urdf(tmp_path, "package://no_such_pkg/meshes/box.stl"))
    message = str(error.value)
    assert "package://no_such_pkg/meshes/box.stl" in message and "link 'base'" in message
    assert "run.packages" in message and f"ROS_PACKAGE_PATH {tmp_path}" in message
    assert "installed Python packages" in message


def test_missing_mesh_file_in_a_found_package(tmp_path):
    package = mesh_package(tmp_path)
    with pytest.raises(UrdfError, match=r"no file 'meshes/gone\.dae' in package 'my_robot'"):
        read_urdf(mesh_urdf(tmp_path, "package://my_robot/meshes/gone.dae"), {"my_robot": str(package)})


@needs_robots
def test_installed_python_package_and_xacro_wrapper():
    model = read_urdf(PANDA_BUS)  # $(find example-robot-data) and package:// through the wheel
    assert model.root == "bus" and "panda_hand" in model.link_names
    assert model.mimics == {"panda_finger_joint2": ("panda_finger_joint1", 1.0, 0.0)}
    assert "package://" not in model.text and "$(find" not in model.text
    assert model.movable_joints[-2:] == ["panda_finger_joint1", "panda_finger_joint2"]


def test_xacro_with_an_unknown_package(tmp_path, monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    path = tmp_path / "r.urdf.xacro"
    path.write_text(
        '<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<xacro:include filename="$(find nowhere_pkg)/r.urdf"/></robot>'
    )
    with pytest.raises(UrdfError, match=r"nowhere_pkg.*not found"):
        read_urdf(path)


def test_urdf_path_as_package_uri(tmp_path):
    from components.robots.model import read_model

    package = mesh_package(tmp_path)
    (package / "urdf").mkdir()
    (package / "urdf" / "r.urdf").write_text(f"<robot name='r'>{BASE}</robot>")
    model = read_model("package://my_robot/urdf/r.urdf", tmp_path, "urdf", {"my_robot": str(package)})
    assert model.root == "base"
    with pytest.raises(ConfigError, match="package 'absent' not found"):
        read_model("package://absent/urdf/r.urdf", tmp_path, "urdf", {})


def test_resolve_uri_file_and_relative(tmp_path):
    (tmp_path / "m.obj").write_text("")
    assert resolve_uri(f"file://{tmp_path}/m.obj", Path("/")) == tmp_path / "m.obj"
    assert resolve_uri("m.obj", tmp_path) == tmp_path / "m.obj"


# ---------------------------------------------------------------- physics refused or flagged


@pytest.mark.parametrize(
    "inertia, words",
    [
        ('ixx="-0.1" iyy="0.1" izz="0.1"', "not positive definite"),
        ('ixx="1.0" iyy="0.1" izz="0.1"', "triangle inequality"),
    ],
)
def test_impossible_inertia_refused_naming_the_link(tmp_path, inertia, words):
    with pytest.raises(UrdfError, match=f"link 'arm'.*{words}"):
        read_urdf(urdf(tmp_path, arm(inertia)))


def test_point_mass_accepted(tmp_path):
    read_urdf(urdf(tmp_path, arm('ixx="0" iyy="0" izz="0"')))


def test_zero_mass_link_under_a_moving_joint_is_noted(tmp_path):
    model = read_urdf(urdf(tmp_path, arm('ixx="0" iyy="0" izz="0"', mass="0")))
    assert len(model.notes()) == 1 and "link 'arm' has no mass" in model.notes()[0] and "joint 'j'" in model.notes()[0]


def test_mimic_of_a_missing_joint(tmp_path):
    body = (
        arm()
        + """<link name="b"><inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1"/></inertial></link>
      <joint name="k" type="revolute"><parent link="base"/><child link="b"/><mimic joint="nope"/>
      <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>"""
    )
    with pytest.raises(UrdfError, match="'k' mimics 'nope'"):
        read_urdf(urdf(tmp_path, body))


def dynamics_params(tmp_path, **body):
    from components.dynamics.component import DartDynamics
    from components.sdk import RunSettings, resolve_parameters

    path = urdf(tmp_path, arm())
    run = RunSettings("2022-01-01T00:00:00Z", tmp_path)
    _, params, errors = resolve_parameters(DartDynamics, {"bodies": {"b": {"urdf": str(path), **body}}}, run)
    assert not errors
    return DartDynamics, params, run


def test_step_too_coarse_is_flagged_with_the_figure(tmp_path):
    cls, params, run = dynamics_params(tmp_path, frame="lvlh")
    notes = cls.preflight(params, run, 3600.0)
    assert len(notes) == 1 and "too coarse" in notes[0] and "4.46 rad" in notes[0] and "at most 80.7 s" in notes[0]
    assert cls.preflight(params, run, 60.0) == []
    cls, params, run = dynamics_params(tmp_path, twist=[0, 0, 0, 0, 0, 2.0])
    params = {**params, "tidal_force": False, "gravity_gradient": False}
    assert "2 rad/s" in cls.preflight(params, run, 0.1)[0] and cls.preflight(params, run, 0.01) == []


def test_duration_bounds():
    from components.schema import Duration

    with pytest.raises(ConfigError, match="at most 100 years"):
        Duration().convert("1e400 s", "run.duration")
    assert Duration().convert("1 h", "x") == 3600 * 10**9


def test_kepler_hint_below_the_surface():
    from components.orbit.kepler import ElementError, check_elements

    with pytest.raises(ElementError) as error:
        check_elements(6.0e6, 0.0, 0.9)
    assert "did you mean" not in str(error.value) and "for an altitude of 6000 km, a = '12378.1 km'" in str(error.value)


def test_waypoint_time_is_described_as_absolute():
    from components.controller.trajectory import CARTESIAN_WAYPOINT

    time = next(p for p in CARTESIAN_WAYPOINT.fields if p.name == "time")
    assert "s from t = 0, not from the previous waypoint" in time.description


# ---------------------------------------------------------------- mimic joints in DART and Pinocchio


@needs_robots
@pytest.mark.parametrize("limits", [False, True])
def test_mimic_joint_kept_and_momentum_conserved_rk4(limits):
    from components.dynamics.world import BodySpec, OrbitalWorld

    model = read_urdf(PANDA_BUS)
    spec = BodySpec(
        name="sat",
        urdf=model.path,
        q={"panda_joint2": 0.3, "panda_finger_joint1": 0.01},
        qd={"panda_joint1": 0.5, "panda_finger_joint1": 0.005},
        twist=np.array([0, 0, 0, 0.01, 0.02, 0]),
    )
    world = OrbitalWorld([spec], models={"sat": model}, tidal_force=False, gravity_gradient=False, joint_limits=limits)
    world.reset_bodies()
    h0 = world.momentum("sat")
    tau = np.zeros(9)
    tau[7] = 0.5  # pushes finger 1 (and through the mimic, finger 2) open
    world.set_torques("sat", tau)
    for _ in range(1000):
        world.step(1e-3)
    q = world.outputs("sat")["q"]
    assert q[8] == pytest.approx(q[7], abs=1e-12)
    assert q[7] > 0.02
    assert np.linalg.norm(world.momentum("sat") - h0) < 1e-11 * np.linalg.norm(h0)


@needs_robots
def test_controller_model_with_a_mimic_finger_matches_the_dynamics():
    """M* qdd + C* = tau of the controller's Pinocchio model (mimic applied to M, c, J) against
    DART's forward dynamics with the mimic constraint: equal to rounding (0.15 rad/s^2 off when
    the controller's model has the finger joints independent)."""
    from components.controller.free_floating_arm import FreeFloatingArm
    from components.dynamics.world import BodySpec, OrbitalWorld

    model = read_urdf(PANDA_BUS)
    joints = [f"panda_joint{i}" for i in range(1, 8)]
    spec = BodySpec(
        name="sat",
        urdf=model.path,
        twist=np.array([0.01, 0, 0, 0.01, 0.02, 0]),
        q={"panda_joint2": -0.3, "panda_joint4": -2.2, "panda_joint6": 1.9, "panda_finger_joint1": 0.02},
        qd={"panda_joint1": 0.5, "panda_joint3": -0.4, "panda_finger_joint1": 0.05},
    )
    world = OrbitalWorld([spec], models={"sat": model}, tidal_force=False, gravity_gradient=False)
    world.reset_bodies()
    tau = np.zeros(9)
    tau[:7] = [1, -2, 0.5, 1, 0.3, -0.2, 0.1]
    world.set_torques("sat", tau)
    qdd = world.forward_dynamics("sat")["qdd"][:7]
    out = world.outputs("sat")
    arm = FreeFloatingArm(model, model.movable_joints, joints, "panda_hand_tcp")
    arm.set_state(out["position"], out["orientation"], out["twist"], out["q"], out["qd"])
    state = arm.compute()
    assert np.linalg.solve(state.M_star, tau[:7] - state.C_star) == pytest.approx(qdd, abs=1e-9)
    with pytest.raises(ValueError, match="mimics"):
        FreeFloatingArm(model, model.movable_joints, joints + ["panda_finger_joint1"], "panda_hand_tcp")


@needs_robots
def test_dae_visuals_become_triangles():
    from components.viewer.robot import mesh_arrays, read_geometry

    geometry = read_geometry(PANDA_BUS)
    dae = [v for v in geometry.visuals if v.mesh is not None and v.mesh.suffix == ".dae"]
    assert len(dae) == 11 and {c.link for c in geometry.collisions} >= {v.link for v in dae}
    vertices, triangles, normals, colors = mesh_arrays(dae[0].mesh)
    assert vertices.shape[1] == 3 and triangles.shape[1] == 3 and triangles.max() < len(vertices)
    assert normals.shape == vertices.shape and (colors is None or colors.shape == (len(vertices), 4))


# ---------------------------------------------------------------- the recording directory's lock


def _hold_lock(directory, ready):
    from orchestrator.run.recording import claim_directory

    lock = claim_directory(Path(directory), False, "holder")  # noqa: F841 (held until killed)
    ready.set()
    signal.pause()


def test_a_live_run_locks_its_directory_and_the_lock_dies_with_it(tmp_path):
    from orchestrator.run.recording import RecordingError, claim_directory

    directory = tmp_path / "rec"
    ready = multiprocessing.get_context("fork").Event()
    holder = multiprocessing.get_context("fork").Process(target=_hold_lock, args=(str(directory), ready))
    holder.start()
    try:
        assert ready.wait(60)
        for overwrite in (False, True):
            with pytest.raises(RecordingError) as error:
                claim_directory(directory, overwrite, "second")
            assert f"run holder (pid {holder.pid}" in str(error.value) and "--overwrite" not in str(error.value)
    finally:
        os.kill(holder.pid, signal.SIGKILL)  # a crash: no clean-up of its own
        holder.join(60)
    claim_directory(directory, True, "after").close()  # the kernel dropped the dead run's lock


def test_a_visual_mesh_that_cannot_be_read_is_drawn_from_the_collision_geometry(tmp_path):
    from tests.unit.test_viewer_scene import save

    (tmp_path / "broken.dae").write_text("<COLLADA>not a mesh</COLLADA>")
    path = urdf(
        tmp_path,
        """<link name="base"><inertial><mass value="1"/>
        <inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial>
        <visual><geometry><mesh filename="broken.dae"/></geometry></visual>
        <collision><geometry><box size="1 2 3"/></geometry></collision></link>""",
    )
    config = {"components": {"dyn": {"type": "dynamics.dart", "parameters": {"bodies": {"b": {"urdf": str(path)}}}}}}
    columns = [
        "dyn.b.position[0]",
        "dyn.b.position[1]",
        "dyn.b.position[2]",
        "dyn.b.orientation[0]",
        "dyn.b.orientation[1]",
        "dyn.b.orientation[2]",
        "dyn.b.orientation[3]",
    ]
    warnings = []
    rows = np.zeros((2, len(columns)))
    rows[:, 6] = 1.0
    _, rrd = save(tmp_path, columns, config, [(np.arange(2), np.arange(2) * 0.1, rows)], warnings=warnings)
    assert any(
        "visual mesh of link base cannot be drawn (broken.dae" in w and "collision geometry instead" in w
        for w in warnings
    ), warnings
    box = next(entry for p, entry in rrd.items() if p.endswith("/links/base/visual_0_collision_0"))
    assert any(name.endswith("half_sizes") for name in box["static"])


def test_a_robot_mounted_below_its_own_root_is_told_which_link_to_mount(tmp_path):
    """A wrapper that joins its bus to the UR5's base_link, which the UR5's file already holds from
    its own root world (issue 34): the error names both joints and their parents, and says to
    mount the robot by world."""
    urdf = tmp_path / "mounted.urdf"
    inertial = '<inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>'
    urdf.write_text(f"""<robot name="r">
  <link name="bus">{inertial}</link><link name="world"/><link name="base_link">{inertial}</link>
  <joint name="world_joint" type="fixed"><parent link="world"/><child link="base_link"/></joint>
  <joint name="mount" type="fixed"><parent link="bus"/><child link="base_link"/></joint>
</robot>""")
    with pytest.raises(UrdfError) as error:
        read_urdf(urdf)
    assert str(error.value) == (
        "mounted.urdf: joint 'mount': link 'base_link' has two parent joints, 'world_joint' (from 'world') and "
        "'mount' (from 'bus'); 'world' is a root of the file already: mount the robot by it (a joint from 'bus' "
        "to 'world'), or leave 'world' and its joint out"
    )


def test_a_mesh_without_filename_is_no_asset_and_the_others_still_are(tmp_path):
    """A bag's mesh assets: the URDF reader refuses a mesh without filename (the topics' builder
    warns and goes on), so collecting the assets skips it instead of ending the export."""
    from types import SimpleNamespace

    from components.dynamics.ros import _assets

    (tmp_path / "m.stl").write_bytes(b"solid m\nendsolid m\n")
    meshes = (
        '<visual><geometry><mesh/></geometry></visual><visual><geometry><mesh filename="m.stl"/></geometry></visual>'
    )
    path = urdf(tmp_path, BASE.replace("</link>", meshes + "</link>"))
    bodies = {"bodies": {"b": {"urdf": str(path)}}}
    run = SimpleNamespace(config={}, config_dir=str(tmp_path), parameters=lambda name: bodies)
    warnings: list[str] = []
    assert _assets(SimpleNamespace(run=run, warn=warnings.append), "dyn") == {"m.stl": (tmp_path / "m.stl").resolve()}
    assert warnings == []
