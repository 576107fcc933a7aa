"""The default install without its extras (pyproject.toml): every shipped config but those of
CONFIG_EXTRAS checks, and each feature of an extra is refused with exit 2, naming the extra and the
command that installs it. The extras are hidden in this process, as if not installed."""

from __future__ import annotations

import sys

import pytest

from components import extras
from components.robots import packages, urdf
from orchestrator.cli import main
from orchestrator.config.load import load
from orchestrator.config.yaml_file import ConfigErrors
from tests.conftest import CONFIG_EXTRAS, ROOT, SHIPPED

DEMO = ROOT / "configs" / "humanoid_tracking.yaml"


@pytest.fixture
def default_install(monkeypatch):
    """The extras' modules and ROS packages not found, as in ``pip install -e .``; no URDF parsed
    earlier in this process (read_urdf keeps each once: a xacro that finds a hidden package
    would otherwise come back from an earlier test's parse)."""
    monkeypatch.setattr(urdf, "_parsed", {})
    for modules in extras.MODULES.values():
        for module in modules:
            monkeypatch.setitem(sys.modules, module, None)  # find_spec None, import fails
    found = packages.find_package
    monkeypatch.setattr(
        packages,
        "find_package",
        lambda name, given=None: (None, ["hidden by the test"]) if name in extras.PACKAGES else found(name, given),
    )


@pytest.mark.parametrize("config", SHIPPED, ids=lambda p: p.name)
def test_a_shipped_config_checks_without_extras_unless_it_names_its_own(config, default_install):
    extra = CONFIG_EXTRAS.get(config.name)
    if extra is None:
        load(config)
        return
    with pytest.raises(ConfigErrors) as refused:
        load(config)
    message = "\n".join(refused.value.errors)
    assert f"[{extra}]" in message and extras.install_command(extra) in message, message


@pytest.mark.parametrize(
    "command, extra",
    [
        (["check", str(ROOT / "configs" / "panda_on_bus.yaml")], "robots"),
        (["check", str(ROOT / "configs" / "capture_vision.yaml")], "vision"),
        (["check", str(ROOT / "configs" / "reaction_wheel_fmu.yaml")], "fmi"),
        (["run", str(DEMO), "--view", "web"], "view"),
        (["run", str(DEMO), "--view", "save:x.rrd"], "view"),
        (["view", str(ROOT), "--view", "web"], "view"),
        (["export-fmu", "orbit.kepler", "-o", "x.fmu"], "fmi"),
        (["markers", str(ROOT / "models" / "capture" / "grapple_markers.yaml"), "--check"], "vision"),
    ],
    ids=lambda v: v if isinstance(v, str) else v[0],
)
def test_a_feature_without_its_extra_exits_2_naming_it(command, extra, default_install, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # nothing written here: each is refused before it starts
    assert main(command) == 2
    error = capsys.readouterr().err
    assert f"[{extra}]" in error and f'pip install -e "{ROOT}[{extra}]"' in error, error
    assert list(tmp_path.iterdir()) == []


def test_the_install_command_is_this_clone_s(monkeypatch, tmp_path):
    monkeypatch.chdir(ROOT)
    assert extras.install_command("robots") == 'pip install -e ".[robots]"'
    monkeypatch.chdir(tmp_path)
    assert extras.install_command("robots") == f'pip install -e "{ROOT}[robots]"'


def test_the_de440_ephemeris_without_its_extra_names_it(default_install):
    from components.errors import ConfigError
    from components.testing.harness import Harness

    elements = {"semi_major_axis": "6778 km", "eccentricity": 0.0, "inclination": "51 deg", "raan": 0.0}
    params = {**elements, "arg_perigee": 0.0, "mean_anomaly": 0.0, "step": "10 s", "gravity": {"degree": 0, "order": 0}}
    with pytest.raises(ConfigError) as refused:
        Harness(
            "orbit.numerical", {**params, "third_bodies": ["moon"], "ephemeris": "de440"}, epoch="2026-03-20T00:00:00Z"
        )
    assert "[ephemeris]" in str(refused.value) and extras.install_command("ephemeris") in str(refused.value)
    Harness("orbit.numerical", {**params, "third_bodies": ["moon"], "ephemeris": "erfa"}, epoch="2026-03-20T00:00:00Z")
