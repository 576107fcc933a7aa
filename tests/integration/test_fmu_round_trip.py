"""Export, then import: orbit.kepler and dynamics.dart exported by `orchestrator export-fmu` and run
back in Zenorbit as type ``fmu`` give the native run's signals, bit for bit (real processes, real
Zenoh, FMPy loading pythonfmu's binary)."""

import pandas
import pytest
import yaml

from tests.conftest import ROOT, needs, orchestrator

pytestmark = [pytest.mark.integration, needs("fmi", "type fmu")]

NATIVE = f"""
run: {{name: round_trip, epoch: 2022-09-18T12:00:00Z, duration: 0.5 s, step: 10 ms, algorithm: jacobi}}
components:
  orbit:
    type: orbit.kepler
    parameters: {{semi_major_axis: 6778 km, eccentricity: 0.0004, inclination: 51.64 deg, raan: 236.55 deg,
                 arg_perigee: 262.44 deg, mean_anomaly: 0 deg, j2: true}}
  dynamics:
    type: dynamics.dart
    parameters:
      integrator: rk4
      tidal_force: true
      gravity_gradient: true
      bodies:
        target: {{urdf: {ROOT}/models/target.urdf, twist: [0, 0, 0, 0.01, -0.02, 0.03]}}
connections:
  dynamics.r_eci: orbit.r_eci
  dynamics.v_eci: orbit.v_eci
  dynamics.q_eci_lvlh: orbit.q_eci_lvlh
  dynamics.w_lvlh: orbit.w_lvlh
"""


def _flat(prefix: str, value) -> list[str]:
    """--set PARAM=VALUE arguments for a parameter mapping (nested keys dotted, values as YAML)."""
    if isinstance(value, dict):
        return [arg for k, v in value.items() for arg in _flat(f"{prefix}.{k}" if prefix else k, v)]
    return [f"--set={prefix}={yaml.safe_dump(value, default_flow_style=True).strip().removesuffix('...').strip()}"]


def test_exported_components_imported_back_equal_the_native_run(tmp_path, write_config):
    native = write_config(NATIVE, "native.yaml")
    config = yaml.safe_load(NATIVE)
    imported = yaml.safe_load(NATIVE)
    for name, entry in config["components"].items():
        fmu = tmp_path / f"{name}.fmu"
        done = orchestrator(
            "export-fmu", entry["type"], *_flat("", entry["parameters"]), "--epoch", "2022-09-18T12:00:00Z", "-o", fmu
        )
        assert done.returncode == 0, done.stderr
        imported["components"][name] = {"type": "fmu", "parameters": {"path": str(fmu)}}
    runs = {}
    for label, path in (
        ("native", native),
        ("imported", write_config(yaml.safe_dump(imported, sort_keys=False), "imported.yaml")),
    ):
        done = orchestrator("run", path, "--record", tmp_path / label)
        assert done.returncode == 0, done.stderr[-2000:]
        runs[label] = pandas.read_parquet(tmp_path / label / "signals.parquet")
    assert list(runs["imported"].columns) == list(runs["native"].columns)  # r_eci[0]... back to r_eci
    assert runs["imported"].equals(runs["native"])
    assert runs["native"]["dynamics.target.twist[5]"].abs().max() > 0.02  # it moved
