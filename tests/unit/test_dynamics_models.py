"""models/*.urdf: Table 1 of the paper in the humanoid, names the controller relies on, and both
URDF readers (ours, Pinocchio's) agree."""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from components.robots.urdf import read_urdf
from components.robots.urdf_elements import UrdfError

MODELS = Path(__file__).resolve().parents[2] / "models"
TABLE1_MASS = [2.741, 2.425, 2.209, 0.877, 1.878, 0.409, 0.308]
TABLE1_LENGTH = [0.28, 0.144, 0.0, 0.274, 0.265, 0.0, 0.0]


def test_humanoid_follows_table_1():
    model = read_urdf(MODELS / "humanoid_torso.urdf")
    assert model.root == "torso"
    assert model.movable_joints == [f"arm_{s}_{i}_joint" for s in ("left", "right") for i in range(1, 8)]
    torso = model.tree.getroot().find("link[@name='torso']/inertial")
    assert float(torso.find("mass").get("value")) == 93.0
    inertia = {k: float(v) for k, v in torso.find("inertia").attrib.items()}
    assert inertia == {"ixx": 18.6, "iyy": 15.4, "izz": 4.1, "ixy": -0.008, "ixz": -0.027, "iyz": 0.058}
    for side in ("left", "right"):
        for i in range(7):
            assert model.link(f"arm_{side}_{i + 1}_link").mass == TABLE1_MASS[i]
            joint = model.joint(f"arm_{side}_{i + 1}_joint")
            assert np.linalg.norm(joint.xyz) == pytest.approx(TABLE1_LENGTH[i], abs=1e-9)
            assert np.isfinite(joint.lower) and np.isfinite(joint.effort)
        tool = model.joint(f"arm_{side}_tool_joint")
        assert tool.type == "fixed" and tool.child == f"arm_{side}_tool_link"
    assert set(model.frame_links()) == {"arm_left_tool_link", "arm_right_tool_link"}


@pytest.mark.parametrize(
    "name, nq, mass", [("humanoid_torso", 14, 93 + 2 * sum(TABLE1_MASS)), ("servicer", 6, None), ("target", 0, 200.0)]
)
def test_pinocchio_loads_the_models_on_a_free_flyer(name, nq, mass):
    model = pin.buildModelFromUrdf(str(MODELS / f"{name}.urdf"), pin.JointModelFreeFlyer())
    ours = read_urdf(MODELS / f"{name}.urdf")
    assert model.nv == 6 + nq and len(ours.movable_joints) == nq
    total = sum(inertia.mass for inertia in model.inertias)
    assert total == pytest.approx(sum(link.mass for link in ours.links))
    if mass is not None:
        assert total == pytest.approx(mass)
    if name == "servicer":
        assert 500.0 < total < 560.0 and model.existFrame("arm_tool_link")


def test_read_urdf_errors(tmp_path):
    with pytest.raises(UrdfError, match="not found"):
        read_urdf(tmp_path / "missing.urdf")
    path = tmp_path / "cycle.urdf"
    path.write_text(
        "<robot name='c'><link name='a'/><link name='b'/>"
        "<joint name='j1' type='fixed'><parent link='a'/><child link='b'/></joint>"
        "<joint name='j2' type='fixed'><parent link='b'/><child link='a'/></joint></robot>"
    )
    with pytest.raises(UrdfError, match="root"):
        read_urdf(path)
    path.write_text(
        "<robot name='c'><link name='a'><inertial><mass value='1'/><inertia ixx='1' iyy='1' izz='1'/>"
        "</inertial></link><link name='b'/><joint name='j' type='revolute'><parent link='a'/>"
        "<child link='b'/><axis xyz='0 0 1'/></joint></robot>"
    )
    with pytest.raises(UrdfError, match="needs a <limit>"):
        read_urdf(path)


def test_a_process_parses_each_urdf_once(monkeypatch, tmp_path):
    """The demo's dynamics (schema, declaration, check, setup) and controller (schema, declaration)
    in one process, as in the orchestrator's check or a process group, parse the humanoid once; a
    changed file is parsed again."""
    import yaml

    from components.controller.computed_torque_component import ComputedTorqueComponent
    from components.dynamics.component import DartDynamics
    from components.robots import urdf
    from components.sdk import RunSettings, resolve_parameters

    parses, parse = [], urdf._parse
    monkeypatch.setattr(urdf, "_parsed", {})
    monkeypatch.setattr(urdf, "_parse", lambda path, packages: parses.append(path.name) or parse(path, packages))
    demo = MODELS.parent / "configs" / "humanoid_tracking.yaml"
    components = yaml.safe_load(demo.read_text())["components"]
    run = RunSettings("2022-01-01T00:00:00Z", demo.parent)
    params = {}
    for cls, name in ((DartDynamics, "dynamics"), (ComputedTorqueComponent, "controller")):
        _, params[name], errors = resolve_parameters(cls, components[name]["parameters"], run)
        assert not errors
        cls.declare(params[name], run)
    DartDynamics.preflight(params["dynamics"], run, 0.001)
    DartDynamics(params["dynamics"], run, compile_kernels=False)
    assert parses == ["humanoid_torso.urdf"]

    copy = tmp_path / "humanoid_torso.urdf"
    copy.write_text((MODELS / "humanoid_torso.urdf").read_text())
    assert read_urdf(copy) is read_urdf(copy)
    copy.write_text(copy.read_text().replace('name="humanoid_torso"', 'name="renamed"', 1))
    assert read_urdf(copy).name == "renamed" and parses == ["humanoid_torso.urdf"] * 3
