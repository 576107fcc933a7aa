"""A component is set up once per process: what its ``validate`` works out from the parameters (the
URDF read and checked, gains per joint) is what ``declare`` and the instance get, not worked out again.

Counted as a component process does it (components/process.py: ``registry.resolve`` on the
instantiate message's parameters, then ``build``), on the shipped configs' controllers: each reads
its URDF once (before the typed road: three times, in validate, declare and __init__)."""

from __future__ import annotations

import pytest

from components import registry
from components.controller import body_loop, capture_setup
from components.sdk import RunSettings
from orchestrator.config.load import load
from tests.conftest import ROOT


def _joint_pd(controller: dict) -> dict:
    """A joint_pd on the demo controller's URDF, driving its first arm joint."""
    return {"urdf": controller["urdf"], "gains": {controller["joints"][0]: {"p": 10.0, "d": 1.0}}}


@pytest.mark.parametrize(
    "config, type_name, parameters",
    [
        ("humanoid_tracking.yaml", "controller.computed_torque", dict),
        ("capture_tumbling_target.yaml", "controller.capture", dict),
        ("humanoid_tracking.yaml", "controller.joint_pd", _joint_pd),
    ],
)
def test_a_component_process_reads_its_urdf_once(config, type_name, parameters, monkeypatch):
    spec = load(ROOT / "configs" / config).components["controller"]
    params = parameters(spec.parameters)
    reads = []

    def counted(read):
        def read_model(*args, **kwargs):
            reads.append(args[0])
            return read(*args, **kwargs)

        return read_model

    for module in (body_loop, capture_setup):
        monkeypatch.setattr(module, "read_model", counted(module.read_model))
    run = RunSettings.from_json(spec.run.to_json())  # as the instantiate message carries it
    registry.resolve(type_name, params, run).build()
    assert reads == [params["urdf"]]
