"""orchestrator export-fmu: component types as FMI 2.0 co-simulation FMUs, run by FMPy (a master
Zenorbit did not write) and compared bit for bit with the native component and a real run."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from components.constants import NS_PER_S
from components.extras import missing
from components.testing.harness import Harness
from tests.conftest import ROOT, orchestrator

fmpy = pytest.importorskip("fmpy", reason=missing("fmi", "testing the FMU export"))
from fmpy.fmi2 import FMU2Slave  # noqa: E402  (the extra [fmi]: skipped above without it)
from fmpy.validation import validate_fmu  # noqa: E402

from components.fmi.exported import export_fmu  # noqa: E402  (pythonfmu: the same extra)
from components.fmi.slave import element_units  # noqa: E402

pytestmark = pytest.mark.integration

EPOCH = "2022-09-18T12:00:00Z"
KEPLER_STEPS, KEPLER_STEP = 60, 1.0  # s: configs/orbit_iss_kepler.yaml's step
HUMANOID_STEPS, HUMANOID_STEP = 40, 0.01  # s: configs/free_floating_humanoid.yaml's step


def config_parameters(config: str, component: str) -> dict:
    return yaml.safe_load((ROOT / "configs" / config).read_text())["components"][component]["parameters"]


def as_overrides(parameters: dict) -> list[str]:
    """--set values for parameters as a config gives them (JSON is YAML)."""
    return [f"{key}={json.dumps(value)}" for key, value in parameters.items()]


def element_columns(variable) -> list[str]:
    """FMI names of a variable's elements, from the recording's column naming."""
    return [column.split(".", 1)[1] for column in variable.columns("c")]


def native_rows(harness: Harness, steps: int, h_ns: int) -> np.ndarray:
    """Outputs at t0 then after each step, in layout order, one row each."""
    rows = [harness.output_layout.start_vector()]
    harness.output_layout.pack(harness.initialize(), rows[0])
    for _ in range(steps):
        row = np.empty(harness.output_layout.size)
        harness.output_layout.pack(harness.step(h_ns), row)
        rows.append(row)
    return np.array(rows)


def fmu_rows(result: np.ndarray, names: list[str]) -> np.ndarray:
    return np.column_stack([result[name] for name in names])


def output_names(harness: Harness) -> list[str]:
    return [name for v in harness.output_layout.variables for name in element_columns(v)]


def orbit_inputs() -> dict[str, np.ndarray]:
    """A fixed orbit input: the ISS-like orbit's outputs at t = 0."""
    return Harness("orbit.kepler", config_parameters("orbit_iss_kepler.yaml", "orbit"), epoch=EPOCH).initialize()


def humanoid_torques(size: int) -> np.ndarray:
    return 0.02 * np.sin(np.arange(1, size + 1))


def humanoid_harness() -> Harness:
    return Harness(
        "dynamics.dart",
        config_parameters("free_floating_humanoid.yaml", "dynamics"),
        epoch=EPOCH,
        config_dir=ROOT / "configs",
    )


def constant_inputs(harness: Harness, values: dict[str, np.ndarray]) -> np.ndarray:
    """FMPy input signals holding ``values``: one sample, held (FMPy interpolates between two
    samples as w0 * v0 + w1 * v1, which is not exactly v for v0 == v1)."""
    names, row = [], []
    for v in harness.input_layout.variables:
        names += element_columns(v)
        row += list(np.broadcast_to(values[v.name], v.shape).ravel())
    dtype = [("time", np.float64)] + [(name, np.float64) for name in names]
    return np.array([(0.0, *row)], dtype=dtype)


@pytest.fixture(scope="module")
def kepler_fmu(tmp_path_factory):
    out = tmp_path_factory.mktemp("kepler") / "kepler.fmu"
    result = orchestrator(
        "export-fmu",
        "orbit.kepler",
        *[arg for s in as_overrides(config_parameters("orbit_iss_kepler.yaml", "orbit")) for arg in ("--set", s)],
        "--epoch",
        EPOCH,
        "-o",
        out,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == (
        f"wrote {out} (0 inputs, 13 outputs, FMI 2.0 co-simulation, state: get/set and serialize)"
    )
    return out


@pytest.fixture(scope="module")
def humanoid_fmu(tmp_path_factory):
    """The free-floating humanoid's dynamics; its URDF path (../models/...) is relative to configs/."""
    out = tmp_path_factory.mktemp("humanoid") / "humanoid.fmu"
    export_fmu(
        "dynamics.dart", config_parameters("free_floating_humanoid.yaml", "dynamics"), out, EPOCH, ROOT / "configs"
    )
    return out


def test_kepler_fmu_in_fmpy_equals_native_and_orchestrator_run(kepler_fmu, tmp_path):
    result = fmpy.simulate_fmu(
        kepler_fmu, start_time=0.0, stop_time=KEPLER_STEPS * KEPLER_STEP, output_interval=KEPLER_STEP
    )
    harness = Harness("orbit.kepler", config_parameters("orbit_iss_kepler.yaml", "orbit"), epoch=EPOCH)
    names = output_names(harness)
    from_fmu = fmu_rows(result, names)
    assert from_fmu.shape == (KEPLER_STEPS + 1, 13)
    assert np.array_equal(result["time"], np.arange(KEPLER_STEPS + 1) * KEPLER_STEP)
    assert np.array_equal(from_fmu, native_rows(harness, KEPLER_STEPS, round(KEPLER_STEP * NS_PER_S)))

    run = orchestrator(
        "run", "configs/orbit_iss_kepler.yaml", "--set", f"run.duration={KEPLER_STEPS} s", "--record", tmp_path / "rec"
    )
    assert run.returncode == 0, run.stderr
    signals = pq.read_table(tmp_path / "rec/signals.parquet")
    recorded = np.column_stack([np.asarray(signals.column(f"orbit.{name}")) for name in names])
    assert np.array_equal(from_fmu, recorded)


def test_dynamics_fmu_with_constant_inputs_equals_native(humanoid_fmu):
    harness = humanoid_harness()
    n = harness.inputs["humanoid.tau"].size
    values = {**orbit_inputs(), "humanoid.tau": humanoid_torques(n)}
    harness.inputs.update(values)
    stop = HUMANOID_STEPS * HUMANOID_STEP
    result = fmpy.simulate_fmu(
        humanoid_fmu,
        start_time=0.0,
        stop_time=stop,
        output_interval=HUMANOID_STEP,
        input=constant_inputs(harness, values),
    )
    native = native_rows(harness, HUMANOID_STEPS, round(HUMANOID_STEP * NS_PER_S))
    from_fmu = fmu_rows(result, output_names(harness))
    assert from_fmu.shape == native.shape == (HUMANOID_STEPS + 1, harness.output_layout.size)
    assert np.array_equal(from_fmu, native)
    assert np.ptp(result["humanoid.q[0]"]) > 1e-3  # the arm moved: the inputs and steps did something
    with zipfile.ZipFile(humanoid_fmu) as archive:  # the URDF travels in the FMU, the parameter rewritten
        assert "resources/files/_outside/up/models/humanoid_torso.urdf" in archive.namelist()
        spec = json.loads(archive.read("resources/zenorbit.json"))
        assert spec["parameters"]["bodies"]["humanoid"]["urdf"] == "_outside/up/models/humanoid_torso.urdf"
        assert not [name for name in archive.namelist() if "__pycache__" in name]
        assert "resources/components/dynamics/component.py" in archive.namelist()


def test_model_description_is_valid_with_vector_names_units_and_descriptions(kepler_fmu, humanoid_fmu):
    for path in (kepler_fmu, humanoid_fmu):
        assert validate_fmu(str(path)) == []
    kepler = fmpy.read_model_description(kepler_fmu, validate=True)
    assert kepler.coSimulation.modelIdentifier == "kepler"
    assert kepler.coSimulation.canGetAndSetFMUstate and kepler.coSimulation.canSerializeFMUstate
    r0 = next(v for v in kepler.modelVariables if v.name == "r_eci[0]")
    assert (r0.causality, r0.type, r0.unit) == ("output", "Real", "m")
    assert r0.description == "position of the reference orbit point, ECI (GCRF axes) (element 0)"
    assert [v.name for v in kepler.modelVariables][:4] == ["r_eci[0]", "r_eci[1]", "r_eci[2]", "v_eci[0]"]

    humanoid = fmpy.read_model_description(humanoid_fmu, validate=True)
    by_name = {v.name: v for v in humanoid.modelVariables}
    twist = [by_name[f"humanoid.twist[{i}]"].unit for i in range(6)]
    assert twist == ["m/s"] * 3 + ["rad/s"] * 3  # "m/s, rad/s" split over the six
    assert by_name["humanoid.momentum[5]"].unit == "kg*m^2/s"
    tau = by_name["humanoid.tau[0]"]
    assert (tau.causality, tau.unit, tau.start) == ("input", "N*m", "0.0")
    assert tau.description.startswith("joint torques (N m, N for prismatic), URDF order: ")
    assert by_name["q_eci_lvlh[3]"].start == "1.0"
    units = {u.name: u.baseUnit for u in humanoid.unitDefinitions}
    assert (units["N*m"].kg, units["N*m"].m, units["N*m"].s) == (1, 2, -2)


def test_fmu_state_serialized_mid_run_restores_bit_identically(humanoid_fmu):
    description = fmpy.read_model_description(humanoid_fmu)
    unzipped = fmpy.extract(humanoid_fmu)
    outputs = [v.valueReference for v in description.modelVariables if v.causality == "output"]
    torque = [v.valueReference for v in description.modelVariables if v.name.startswith("humanoid.tau[")]
    steps, middle, h = 12, 5, HUMANOID_STEP

    def instance(name: str) -> FMU2Slave:
        slave = FMU2Slave(
            guid=description.guid,
            unzipDirectory=unzipped,
            modelIdentifier=description.coSimulation.modelIdentifier,
            instanceName=name,
        )
        slave.instantiate()
        return slave

    def torques(k: int) -> list[float]:  # inputs that change from step to step
        return list(humanoid_torques(len(torque)) * (1 + k % 3))

    def step(slave: FMU2Slave, k: int) -> list[float]:
        slave.setReal(torque, torques(k))
        slave.doStep(currentCommunicationPoint=k * h, communicationStepSize=h)
        return slave.getReal(outputs)

    first, second = instance("first"), instance("second")
    try:
        first.setupExperiment(startTime=0.0)
        first.enterInitializationMode()
        first.exitInitializationMode()
        rows = [step(first, k) for k in range(middle)]
        state = first.getFMUstate()
        blob = first.serializeFMUstate(state)
        first.freeFMUstate(state)
        rows += [step(first, k) for k in range(middle, steps)]

        state = first.deSerializeFMUstate(blob)
        first.setFMUstate(state)
        first.freeFMUstate(state)
        assert first.getReal(outputs) == rows[middle - 1] and first.getReal(torque) == torques(middle - 1)
        assert np.array_equal([step(first, k) for k in range(middle, steps)], rows[middle:])

        state = second.deSerializeFMUstate(blob)  # serialized by one instance, restored in another
        second.setFMUstate(state)
        second.freeFMUstate(state)
        assert np.array_equal([step(second, k) for k in range(middle, steps)], rows[middle:])
    finally:
        for slave in (first, second):
            slave.terminate()
            slave.freeInstance()
        shutil.rmtree(unzipped, ignore_errors=True)


RAMP = '''"""A component with no get_state/set_state that reads a file a parameter names."""
from pathlib import Path

import numpy as np

from components.constants import NS_PER_S
from components.sdk import Component, Parameter, Variable


class Ramp(Component):
    """Five ramps, slopes from a file, plus an offset input; a step ending after fail_at raises."""
    type_name = "test.ramp"
    parameters = (Parameter("slopes", "str", description="file of five slopes, relative to the config"),
                  Parameter("fail_at", "float", unit="s", default=1e9, description="when it breaks"))
    variables = (Variable("offset.u", "input", (), "m", 0.5, "added to every ramp"),
                 Variable("y", "output", (5,), "m, s", 0.0, "the ramps"))

    def __init__(self, params, run):
        self.slopes = np.loadtxt(run.config_dir / params["slopes"])
        self.fail_at = params["fail_at"]

    def initialize(self, t0_ns, inputs):
        return {"y": self.slopes * (t0_ns / NS_PER_S) + inputs["offset.u"]}

    def do_step(self, t_ns, h_ns, inputs):
        if (t_ns + h_ns) / NS_PER_S > self.fail_at:
            raise RuntimeError("the ramp ran out")
        return {"y": self.slopes * ((t_ns + h_ns) / NS_PER_S) + inputs["offset.u"]}
'''


def test_type_without_state_travels_with_its_files_and_a_failing_step_fails(tmp_path):
    (tmp_path / "plant").mkdir()
    (tmp_path / "plant/ramp.py").write_text(RAMP)
    (tmp_path / "data").mkdir()
    (tmp_path / "data/slopes.txt").write_text("1 2 3 4 5\n")
    out = export_fmu(
        "plant/ramp.py:Ramp", {"slopes": "data/slopes.txt", "fail_at": 0.35}, tmp_path / "out/ramp.fmu", None, tmp_path
    )
    shutil.rmtree(tmp_path / "plant")  # the FMU carries the type's file and the table
    shutil.rmtree(tmp_path / "data")

    description = fmpy.read_model_description(out, validate=True)
    assert not description.coSimulation.canGetAndSetFMUstate and not description.coSimulation.canSerializeFMUstate
    offset, y0 = description.modelVariables[:2]
    assert (offset.name, offset.causality, offset.unit, offset.start) == ("offset.u", "input", "m", "0.5")
    assert (y0.name, y0.unit, y0.description) == ("y[0]", None, "the ramps (element 0) [units: m, s]")

    messages = []
    result = fmpy.simulate_fmu(
        out,
        stop_time=1.0,
        output_interval=0.1,
        debug_logging=True,
        input=np.array([(0.0, 0.25)], dtype=[("time", float), ("offset.u", float)]),
        logger=lambda env, name, status, category, message: messages.append(message),
    )
    assert result["time"][-1] == pytest.approx(0.3)  # the step to 0.4 failed: the simulation ends there
    assert result["y[4]"][3] == 5 * 0.3 + 0.25  # the component saw t = 300 000 000 ns
    assert b"plant/ramp.py:Ramp: step at t = 0.3 s failed: RuntimeError: the ramp ran out" in messages


def test_element_units_split_a_unit_list_evenly_or_not_at_all():
    assert element_units("m/s, rad/s", 6) == ["m/s"] * 3 + ["rad/s"] * 3
    assert element_units("N*m", 2) == ["N*m", "N*m"]
    assert element_units("m/s, rad/s", 5) is None
    assert element_units("", 2) == [None, None]


def test_the_fmu_runs_on_its_own_copy_of_zenorbit_in_another_process(humanoid_fmu, tmp_path):
    """A fresh Python process (not this checkout's code on its path) runs the FMU and exits cleanly."""
    script = f"""
import json, sys, fmpy
result = fmpy.simulate_fmu({str(humanoid_fmu)!r}, stop_time=0.03, output_interval=0.01)
print(json.dumps({{"components": sys.modules["components"].__file__, "q": result["humanoid.q[0]"].tolist()}}))
"""
    done = subprocess.run(
        [sys.executable, "-c", script],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"},
    )
    assert done.returncode == 0, done.stderr[-2000:]  # no crash at exit either
    answer = json.loads(done.stdout.strip().splitlines()[-1])
    assert answer["components"].endswith("/resources/components/__init__.py")
    assert not answer["components"].startswith(str(ROOT))
    here = fmpy.simulate_fmu(humanoid_fmu, stop_time=0.03, output_interval=0.01)
    assert answer["q"] == here["humanoid.q[0]"].tolist()


def kepler_sets(**changes) -> list[str]:
    parameters = {**config_parameters("orbit_iss_kepler.yaml", "orbit"), **changes}
    return [
        "orbit.kepler",
        *(f"--set={s}" for s in as_overrides({k: v for k, v in parameters.items() if v is not None})),
    ]


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["orbit.keppler"], "unknown component type 'orbit.keppler'"),
        (kepler_sets(semi_major_axes="7000 km"), "--set semi_major_axes: unknown parameter of orbit.kepler (known: "),
        (kepler_sets(eccentricity=None), "--set eccentricity: missing required parameter"),
        (
            kepler_sets(mean_anomaly=None, time_of_perigee="2022-09-18T11:30:00Z"),
            "orbit.kepler needs the run epoch (run.epoch, the UTC of t = 0): pass --epoch UTC",
        ),
        ([*kepler_sets(), "--epoch", "yesterday"], "--epoch: expected a UTC time like 2022-09-18T12:00:00Z"),
        (
            ["dynamics.dart", "--set=bodies.robot.urdf=missing.urdf"],
            "--set bodies.robot.urdf: URDF file 'missing.urdf' not found",
        ),
    ],
    ids=["unknown-type", "unknown-parameter", "missing-parameter", "needs-epoch", "bad-epoch", "missing-file"],
)
def test_bad_export_requests_exit_2_naming_the_problem(arguments, message, tmp_path):
    result = orchestrator("export-fmu", *arguments, "-o", tmp_path / "x.fmu")
    assert result.returncode == 2 and message in result.stderr, result.stderr
    assert result.stderr.startswith("error: ") and "Traceback" not in result.stderr
    assert not list(tmp_path.glob("*.fmu"))


@pytest.mark.parametrize(
    "name, message",
    [
        ("kepler.zip", "kepler.zip: the output must be a .fmu file, e.g. -o "),
        ("my-orbit.fmu", "my-orbit.fmu: the file name is the FMU's model identifier and must be a C identifier"),
    ],
)
def test_output_name_must_be_an_fmu_named_by_an_identifier(name, message, tmp_path):
    result = orchestrator("export-fmu", *kepler_sets(), "-o", tmp_path / name)
    assert result.returncode == 2 and message in result.stderr, result.stderr
    assert "Traceback" not in result.stderr and not list(tmp_path.iterdir())
