"""``orchestrator check`` on the capture scenario with estimator.fiducial (its wrist camera
embedded) in place of the relative-pose oracle: accepted as it is, and refused with exit 2 naming
the key (and the field of the layout file) for bad parameters."""
from __future__ import annotations

import pytest
import yaml

from components.camera.render import egl_problem
from tests.conftest import ROOT, orchestrator

pytestmark = [pytest.mark.integration,
              pytest.mark.skipif(egl_problem() is not None, reason=f"no EGL here: {egl_problem()}")]
CAPTURE = ROOT / "configs" / "capture_tumbling_target.yaml"
KEY = "components.pose_sensor.parameters"


@pytest.fixture
def config(tmp_path):
    data = yaml.safe_load(CAPTURE.read_text())
    for body in data["components"]["dynamics"]["parameters"]["bodies"].values():
        body["urdf"] = str((CAPTURE.parent / body["urdf"]).resolve())
    controller = data["components"]["controller"]["parameters"]
    controller["urdf"] = str((CAPTURE.parent / controller["urdf"]).resolve())
    bodies = {name: body["urdf"] for name, body in data["components"]["dynamics"]["parameters"]["bodies"].items()}
    camera = {"bodies": bodies, "body": "servicer", "link": "ee", "position": [0, 0.07, -0.03],
              "orientation": [0.1305, 0, 0, 0.9914], "width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 319.5,
              "cy": 239.5, "near": 0.02, "far": 20, "ambient": 0.1, "seed": 5, "pixel_noise": 2, "depth_noise": 0}
    data["components"]["pose_sensor"] = {"type": "estimator.fiducial", "step": "100 ms", "parameters": {
        "camera": camera, "end_effector": "ee", "markers": str(ROOT / "models" / "capture" / "grapple_markers.yaml"),
        "min_markers": 2, "max_reprojection_error": 1.5}}
    connections = data["connections"]
    del connections["pose_sensor.p_true"], connections["pose_sensor.q_true"]
    for body in bodies:
        for variable in ("position", "orientation", "q"):
            connections[f"pose_sensor.camera.{body}.{variable}"] = f"dynamics.{body}.{variable}"
    connections["pose_sensor.camera.r_eci"] = "orbit.r_eci"
    path = tmp_path / "vision.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_the_estimator_in_place_of_the_oracle_checks(config):
    done = orchestrator("check", config)
    assert done.returncode == 0, done.stderr
    assert "6 components" in done.stdout


@pytest.mark.parametrize("setting, key, expected", [
    ("min_markers=9", "min_markers", "expected at most the layout's 5 markers, got 9"),
    ("markers=nowhere.yaml", "markers", "marker layout 'nowhere.yaml' not found"),
    ("end_effector=arm_5_link", "end_effector", "joint arm_6_joint between them is revolute, not fixed"),
    ("camera.link=hand", "camera.link", "expected a link of servicer"),
    ("camera.fx=0", "camera.fx", "expected a quantity > 0, got 0"),
    ("max_reprojection_error=-1", "max_reprojection_error", "expected a quantity > 0, got -1"),
])
def test_bad_parameters_exit_2_naming_the_key(config, setting, key, expected):
    done = orchestrator("check", config, "--set", f"{KEY}.{setting}")
    assert done.returncode == 2, done.stdout + done.stderr
    assert f"{KEY}.{key}: " in done.stderr and expected in done.stderr, done.stderr


def test_a_bad_layout_file_exits_2_naming_the_field_in_it(config, tmp_path):
    layout = yaml.safe_load((ROOT / "models" / "capture" / "grapple_markers.yaml").read_text())
    layout["markers"][2]["id"] = 1
    path = tmp_path / "layout.yaml"
    path.write_text(yaml.safe_dump(layout))
    done = orchestrator("check", config, "--set", f"{KEY}.markers={path}")
    assert done.returncode == 2, done.stdout + done.stderr
    assert f"{KEY}.markers: {path}: marker id 1 listed twice" in done.stderr, done.stderr
