"""Type ``fmu`` in-process (real FMUs built by pythonfmu, run through FMPy): its outputs equal
FMPy's own ``simulate_fmu`` of the same FMU on the same steps; its variables, units and state;
and every bad input it must refuse."""

import re
import subprocess
import sys
import zipfile

import numpy as np
import pytest

from components.constants import NS_PER_S
from components.errors import ComponentError, ConfigError
from components.fmi.fmu_file import build_python_model
from components.fmi.imported import FMUComponent
from components.sdk import RunSettings
from components.testing.harness import Harness
from tests.conftest import ROOT, needs

pytestmark = needs("fmi", "type fmu")

H_NS = 15_625_000  # 1/64 s: n h is exact in binary, so FMPy's times and Zenorbit's are the same floats
H_S = H_NS / NS_PER_S
WHEEL = {"inertia": 0.05, "max_torque": 0.2, "max_speed": 5.0, "time_constant": 0.05}


@pytest.fixture(scope="module")
def wheel_fmu():
    return build_python_model(ROOT / "models" / "reaction_wheel.py")


@pytest.fixture(scope="module")
def probe_fmu():
    return build_python_model(ROOT / "tests" / "fmus" / "probe.py")


def _command(n: int) -> np.ndarray:
    """A torque command with steps and a sign change (it crosses the speed limit too)."""
    t = np.arange(n) * H_S
    return 0.3 * np.sin(2.0 * t) + 0.05 * (t > 1.0)


def simulate_fmu_apart(path, tmp_path, **options) -> np.ndarray:
    """FMPy's own ``simulate_fmu`` of ``path``, run in a Python process of its own: a pythonfmu
    binary that FMPy loads and frees here, outside the component's hold
    (components/fmi/pythonfmu_exit.py), would abort this process at exit once DART is loaded
    (test_fmu_exit.py runs these tests in processes that must exit 0)."""
    arguments, result = tmp_path / "simulate_args.npz", tmp_path / "simulate_result.npy"
    np.savez(arguments, options=np.array([options], dtype=object))
    code = (
        "import sys, numpy as np, fmpy; options = np.load(sys.argv[2], allow_pickle=True)['options'][0]; "
        "np.save(sys.argv[3], fmpy.simulate_fmu(sys.argv[1], **options))"
    )
    subprocess.run(
        [sys.executable, "-c", code, str(path), str(arguments), str(result)],
        check=True,
        capture_output=True,
        timeout=300,
    )
    return np.load(result)


def test_outputs_equal_fmpy_simulate_fmu_on_the_same_steps(wheel_fmu, tmp_path):
    n = 400  # 6.25 s: the wheel reaches max_speed, the command saturates and reverses
    u = _command(n + 1)
    signal = np.array(list(zip(np.arange(n + 1) * H_S, u)), dtype=[("time", float), ("torque_command", float)])
    outputs = ["motor_torque", "reaction_torque", "wheel_speed"]
    reference = simulate_fmu_apart(
        wheel_fmu,
        tmp_path,
        start_time=0.0,
        stop_time=n * H_S,
        step_size=H_S,
        output_interval=H_S,
        start_values=WHEEL,
        input=signal,
        output=outputs,
    )
    h = Harness("fmu", {"path": str(wheel_fmu), "start_values": WHEEL})
    h.inputs["torque_command"] = u[0]
    h.initialize()
    rows = [[float(h.outputs[name]) for name in outputs]]
    for k in range(n):
        h.inputs["torque_command"] = u[k]
        h.step(H_NS)
        rows.append([float(h.outputs[name]) for name in outputs])
    ours = np.array(rows)
    theirs = np.column_stack([reference[name] for name in outputs])
    assert len(reference) == n + 1
    assert np.array_equal(ours, theirs)  # bit for bit
    assert 5.0 <= abs(ours[:, 2]).max() <= 5.0 + 0.2 * H_S / 0.05  # the speed limit held, one step late at most
    assert ours[:, 0].min() < -0.1 < 0.1 < ours[:, 0].max()  # and the torque changed sign


def test_vectors_names_types_and_units_come_from_the_model_description(wheel_fmu, probe_fmu):
    by_name = {v.name: v for v in FMUComponent.declare({"path": str(probe_fmu), "start_values": {}}, RunSettings())}
    assert {n: (v.causality, v.shape) for n, v in by_name.items()} == {
        "u": ("input", (3,)),
        "mode": ("input", ()),
        "p": ("output", (3,)),
        "der_q": ("output", ()),
        "count": ("output", ()),
    }
    assert "der(q)" in by_name["der_q"].description
    wheel = {
        v.name: v
        for v in FMUComponent.declare({"path": str(wheel_fmu), "start_values": {"torque_command": 0.1}}, RunSettings())
    }
    assert wheel["motor_torque"].unit == "N*m" and wheel["wheel_speed"].unit == "rad/s"  # FMI "N.m" read as N*m
    assert wheel["torque_command"].start == 0.1  # an unconnected input holds its start value

    h = Harness("fmu", {"path": str(probe_fmu), "start_values": {"gain": 2.0}})
    h.inputs["u"], h.inputs["mode"] = [1.0, -2.0, 0.5], 2  # Integer input: set as an int
    h.initialize()
    for _ in range(4):
        h.step(H_NS)
    assert np.array_equal(h.outputs["p"], 4 * 2.0 * 3 * np.array([1.0, -2.0, 0.5]) * H_S)
    assert h.outputs["der_q"] == 2.0 and h.outputs["count"] == 4


def test_state_restores_into_a_fresh_instance_and_continues_bit_for_bit(wheel_fmu):
    params = {"path": str(wheel_fmu), "start_values": WHEEL}
    u = _command(120)
    first = Harness("fmu", params)
    first.initialize()
    for k in range(60):
        first.inputs["torque_command"] = u[k]
        first.step(H_NS)
    state = first.get_state()
    second = Harness("fmu", params, t0_ns=first.t_ns)
    second.set_state(state)  # never initialized
    for k in range(60, 120):
        for h in (first, second):
            h.inputs["torque_command"] = u[k]
            h.step(H_NS)
        assert all(np.array_equal(first.outputs[n], second.outputs[n]) for n in first.outputs)
    assert abs(float(second.outputs["wheel_speed"])) > 0.1


def test_a_state_of_another_fmu_is_refused(wheel_fmu, probe_fmu):
    wheel = Harness("fmu", {"path": str(wheel_fmu), "start_values": {}})
    wheel.initialize()
    probe = Harness("fmu", {"path": str(probe_fmu), "start_values": {}})
    with pytest.raises(ComponentError, match="another FMU"):
        probe.set_state(wheel.get_state())


def test_an_fmu_without_state_support_says_why(tmp_path):
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pythonfmu",
            "build",
            "-f",
            str(ROOT / "tests" / "fmus" / "probe.py"),
            "-d",
            str(tmp_path),
        ],
        check=True,
        capture_output=True,
    )
    params = {"path": str(tmp_path / "Probe.fmu"), "start_values": {}}
    assert "canGetAndSetFMUstate=false" in FMUComponent.state_problem(params, RunSettings())
    h = Harness("fmu", params)
    h.initialize()
    with pytest.raises(ComponentError, match="cannot save its state"):
        h.get_state()


def test_a_step_with_status_error_raises_with_the_fmu_log():
    h = Harness("fmu", {"path": "tests/fmus/probe.py", "start_values": {"fail_at": 2 * H_S}}, config_dir=ROOT)
    h.initialize()
    h.step(H_NS)
    h.step(H_NS)
    with pytest.raises(ComponentError, match=r"FMU probe.py: doStep at t = 0.03125 s failed.*told to fail"):
        h.step(H_NS)


def _error(params) -> str:
    with pytest.raises(ConfigError) as caught:
        Harness("fmu", params)
    return f"{caught.value.key}: {caught.value.message}"


def test_bad_files_are_refused_naming_the_key_and_the_file(tmp_path, probe_fmu):
    assert _error({"path": str(tmp_path / "nowhere.fmu")}).startswith("path: FMU file")
    corrupt = tmp_path / "corrupt.fmu"
    corrupt.write_bytes(b"PK\x03\x04 not really a zip")
    assert "corrupt.fmu is not an FMU: not a zip archive" in _error({"path": str(corrupt)})
    no_description = tmp_path / "empty.fmu"
    with zipfile.ZipFile(no_description, "w") as z:
        z.writestr("resources/x.txt", "x")
    assert "no modelDescription.xml" in _error({"path": str(no_description)})
    model_exchange = tmp_path / "me.fmu"  # the probe's archive with its interface renamed
    with zipfile.ZipFile(probe_fmu) as src, zipfile.ZipFile(model_exchange, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                data = re.sub(
                    rb'<CoSimulation (?:[^>]*? )?(modelIdentifier="\w+")[^>]*?(/?)>', rb"<ModelExchange \1\2>", data
                )
                data = data.replace(b"</CoSimulation>", b"</ModelExchange>")
            dst.writestr(item, data)
    assert "model exchange only" in _error({"path": str(model_exchange)})
    text = tmp_path / "notes.txt"
    text.write_text("x")
    assert "expected an .fmu file" in _error({"path": str(text)})


def test_only_an_fmu_that_is_safe_beside_others_may_join_a_process_group(tmp_path, probe_fmu):
    """A pythonfmu FMU runs its model in the host's interpreter: refused; an FMU without one (here
    the probe's archive without pythonfmu's resource) may join, unless it says it can be
    instantiated only once per process."""

    def rewritten(name: str, once: bool):
        path = tmp_path / name
        with zipfile.ZipFile(probe_fmu) as src, zipfile.ZipFile(path, "w") as dst:
            for item in src.infolist():
                data = src.read(item)
                if item.filename == "resources/slavemodule.txt":
                    continue
                if item.filename == "modelDescription.xml" and once:
                    data = data.replace(
                        b'canBeInstantiatedOnlyOncePerProcess="false"', b'canBeInstantiatedOnlyOncePerProcess="true"'
                    )
                dst.writestr(item, data)
        return {"path": str(path), "start_values": {}}

    assert "embeds a Python interpreter (pythonfmu)" in FMUComponent.group_problem(
        {"path": str(probe_fmu)}, RunSettings()
    )
    assert FMUComponent.group_problem(rewritten("native.fmu", once=False), RunSettings()) is None
    assert "canBeInstantiatedOnlyOncePerProcess=true" in FMUComponent.group_problem(
        rewritten("once.fmu", once=True), RunSettings()
    )


def test_bad_start_values_are_refused_naming_the_variable(probe_fmu):
    def error(start_values):
        return _error({"path": str(probe_fmu), "start_values": start_values})

    assert error({"gian": 1.0}).startswith(
        "start_values.gian: the FMU has no variable 'gian' (its parameters and inputs: gain"
    )
    assert "only its parameters and inputs take start values" in error({"count": 3})
    assert "is of type Integer: expected an integer, got 1.5" in error({"mode": 1.5})
    assert "is of type Real: expected a number, got 'fast'" in error({"gain": "fast"})
    assert error({"u[0]": 1.0, "gain": [1.0, 2.0]}).startswith("start_values.gain: expected 1 value for 'gain', got 2")


def test_an_fmi3_fmu_equals_fmpy_simulate_fmu(tmp_path):
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pythonfmu3",
            "build",
            "-f",
            str(ROOT / "tests" / "fmus" / "integrator3.py"),
            "-d",
            str(tmp_path),
        ],
        check=True,
        capture_output=True,
    )
    path, n = tmp_path / "Integrator3.fmu", 50
    u = np.cos(np.arange(n + 1) * H_S * 3.0)
    signal = np.array(list(zip(np.arange(n + 1) * H_S, u)), dtype=[("time", float), ("u", float)])
    reference = simulate_fmu_apart(
        path,
        tmp_path,
        stop_time=n * H_S,
        step_size=H_S,
        output_interval=H_S,
        start_values={"k": 3.0},
        input=signal,
        output=["y"],
    )
    h = Harness("fmu", {"path": str(path), "start_values": {"k": 3.0}})
    assert h.component.md.fmiVersion == "3.0"
    h.inputs["u"] = u[0]
    h.initialize()
    ours = [float(h.outputs["y"])]
    for k in range(n):
        h.inputs["u"] = u[k]
        h.step(H_NS)
        ours.append(float(h.outputs["y"]))
    assert np.array_equal(ours, reference["y"])
    assert ours[-1] == pytest.approx(3.0 * np.sum(u[:n]) * H_S, rel=1e-12)
