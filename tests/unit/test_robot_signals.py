"""Shared signals (components.signals) and joint units (components.robots.model): consumers
declare what producers publish, a prismatic joint's q, qd and tau are in m, m/s and N, and
docs/design.md §3 names every variable of every type."""

import re
import textwrap
from pathlib import Path

import pytest

from components import registry
from components.robots.model import joint_units
from components.robots.urdf import read_urdf
from components.sdk import RunSettings, resolve_parameters
from components.signals import BODY_STATE
from orchestrator.config.load import load
from orchestrator.config.yaml_file import ConfigErrors
from tests.conftest import needs

MODELS = Path(__file__).resolve().parents[2] / "models"
LINK = '<link name="{0}"><inertial><mass value="{1}"/><inertia ixx="1" iyy="1" izz="1"/></inertial></link>'
JOINT = (
    '<joint name="{0}" type="{1}"><parent link="{2}"/><child link="{3}"/><axis xyz="1 0 0"/>'
    '<limit lower="-0.5" upper="0.5" effort="10" velocity="1"/></joint>'
)


def robot(tmp_path, *kinds: str, name: str = "robot") -> Path:
    """A chain base -> l1 -> l2 ... with one joint of each kind."""
    links = ["base"] + [f"l{i + 1}" for i in range(len(kinds))]
    parts = [LINK.format(name, 10.0 if name == "base" else 1.0) for name in links]
    parts += [JOINT.format(f"j{i + 1}", kind, links[i], links[i + 1]) for i, kind in enumerate(kinds)]
    path = tmp_path / f"{name}.urdf"
    path.write_text(f'<robot name="r">{"".join(parts)}</robot>')
    return path


def variables(type_name: str, params: dict) -> dict:
    cls = registry.load(type_name)
    _, typed, errors = resolve_parameters(cls, params, RunSettings())
    assert not errors, errors
    return {v.name: v for v in cls.declare(typed, RunSettings())}


@pytest.mark.parametrize(
    "kinds, units",
    [
        (("revolute", "continuous"), ("rad", "rad/s", "N*m")),
        (("prismatic", "prismatic"), ("m", "m/s", "N")),
        (("prismatic", "revolute"), ("m, rad", "m/s, rad/s", "N, N*m")),
        ((), ("rad", "rad/s", "N*m")),
    ],
)
def test_joint_units_follow_the_joint_types(tmp_path, kinds, units):
    assert joint_units(read_urdf(robot(tmp_path, *kinds))) == units


@needs("fmi", "an FMU's units")
def test_a_mixed_body_has_one_unit_per_joint_in_fmus_too(tmp_path):
    from components.fmi.slave import element_units

    dynamics = variables("dynamics.dart", {"bodies": {"r": {"urdf": str(robot(tmp_path, "prismatic", "revolute"))}}})
    assert element_units(dynamics["r.q"].unit, 2) == ["m", "rad"]
    assert element_units(dynamics["r.tau"].unit, 2) == ["N", "N*m"]


def test_prismatic_joints_are_in_metres_and_newtons(tmp_path):
    urdf = str(robot(tmp_path, "prismatic"))
    dynamics = variables("dynamics.dart", {"bodies": {"r": {"urdf": urdf}}})
    assert [dynamics[f"r.{k}"].unit for k in ("q", "qd", "tau")] == ["m", "m/s", "N"]
    pd = variables("controller.joint_pd", {"urdf": urdf, "gains": {"j1": {"p": 1.0}}})
    assert [pd[k].unit for k in ("q", "qd", "tau", "q_desired")] == ["m", "m/s", "N", "m"]


@pytest.mark.parametrize(
    "controller, params",
    [
        ("controller.joint_pd", {"gains": {"arm_1_joint": {"p": 1.0}}}),
        ("controller.computed_torque", {"joints": ["arm_1_joint"], "end_effector": "arm_6_link"}),
    ],
)
def test_consumers_declare_the_signals_as_their_producers_do(controller, params):
    """Same name, shape, unit and start on both ends of every connection of the demo's loop."""

    def same(a, b):
        return (a.shape, a.unit, a.start.tolist()) == (b.shape, b.unit, b.start.tolist())

    orbit = variables("orbit.fixed", {"r_eci": [7e6, 0.0, 0.0]})
    dynamics = variables("dynamics.dart", {"bodies": {"s": {"urdf": str(MODELS / "servicer.urdf")}}})
    ctrl = variables(controller, {"urdf": str(MODELS / "servicer.urdf"), **params})
    assert all(same(orbit[k], dynamics[k]) and dynamics[k].causality == "input" for k in orbit)
    assert all(same(dynamics[f"s.{k}"], ctrl[k]) and ctrl[k].causality == "input" for k in BODY_STATE)
    assert same(ctrl["tau"], dynamics["s.tau"]) and ctrl["tau"].causality == "output"


def config(tmp_path, body: Path, model: Path) -> Path:
    """The dynamics of ``body`` under a joint_pd built on ``model``."""
    path = tmp_path / "c.yaml"
    path.write_text(
        textwrap.dedent(f"""
        run: {{name: slide, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 1 ms}}
        components:
          dyn: {{type: dynamics.dart, parameters: {{bodies: {{r: {{urdf: {body}}}}}}}}}
          pd: {{type: controller.joint_pd, parameters: {{urdf: {model}, gains: {{j1: {{p: 1}}}}}}}}
        connections: {{pd.q: dyn.r.q, pd.qd: dyn.r.qd, dyn.r.tau: pd.tau}}
    """)
    )
    return path


def test_check_connects_a_prismatic_body_to_its_controller_and_no_other(tmp_path):
    slider, hinge = robot(tmp_path, "prismatic", name="slider"), robot(tmp_path, "revolute", name="hinge")
    assert len(load(config(tmp_path, slider, slider)).connections) == 3
    with pytest.raises(ConfigErrors) as e:
        load(config(tmp_path, slider, hinge))
    assert "unit mismatch: input pd.q is in rad, output dyn.r.q in m" in "\n".join(e.value.errors)


@pytest.mark.parametrize(
    "type_name, params",
    [
        ("orbit.fixed", {"r_eci": [7e6, 0.0, 0.0]}),
        ("dynamics.dart", {"bodies": {"s": {"urdf": str(MODELS / "servicer.urdf")}}, "link_outputs": True}),
        (
            "controller.computed_torque",
            {"urdf": str(MODELS / "servicer.urdf"), "joints": ["arm_1_joint"], "end_effector": "arm_6_link"},
        ),
        ("controller.joint_pd", {"urdf": str(MODELS / "servicer.urdf"), "gains": {"arm_1_joint": {"p": 1.0}}}),
        ("test.counter", {}),
        ("test.constant", {"value": 1.0}),
        ("test.integrator", {}),
        ("test.noop", {}),
        ("test.faulty", {"fault": "nan", "at_step": 1}),
    ],
)
def test_the_design_table_names_every_variable(type_name, params):
    """docs/design.md §3 lists each type's variables as ``describe`` prints them (body prefix aside)."""
    design = (Path(__file__).resolve().parents[2] / "docs" / "design.md").read_text()
    table = design[design.index("## 3. Components") : design.index("## 4. Config")]
    row = next(
        line for line in table.splitlines() if f"`{type_name}`" in line or f"`{type_name.split('.')[0]}.*`" in line
    )
    missing = [name for name in variables(type_name, params) if not re.search(rf"[`.]{name.split('.')[-1]}`", row)]
    assert not missing, f"{type_name}: {missing} missing from docs/design.md §3"


def test_controllers_and_viewer_read_urdfs_without_the_dynamics():
    """URDF reading sits below the components (components.robots): a controller or the viewer
    imports nothing of components.dynamics."""
    import ast

    root = Path(__file__).resolve().parents[2] / "components"
    offenders = []
    for path in sorted(
        [
            *(root / "controller").rglob("*.py"),
            *(root / "viewer").rglob("*.py"),
            root / "signals.py",
            *(root / "robots").rglob("*.py"),
        ]
    ):
        for node in ast.walk(ast.parse(path.read_text())):
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else []
            )
            offenders += [f"{path.name}: {n}" for n in names if n.startswith("components.dynamics")]
    assert not offenders, offenders
