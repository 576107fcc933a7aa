"""Type ``fmu`` in real runs (real processes, real Zenoh, FMPy, DART): the shipped reaction wheel
FMU in the loop with the dynamics against momentum conservation; swap and restart of the FMU with
its state; a failing FMU step; the errors `check` gives before anything starts."""

import subprocess
import sys

import numpy as np
import pandas
import pytest
import yaml

from tests.conftest import ROOT, component_processes, needs, orchestrator

pytestmark = [pytest.mark.integration, needs("fmi", "type fmu")]

CONFIG = ROOT / "configs" / "reaction_wheel_fmu.yaml"
I_BUS_Z, J_WHEEL = 24.4, 0.05  # models/wheel_sat.urdf: bus izz, wheel izz (the FMU's inertia)


def _run(tmp_path, name, *sets, expect=0):
    record = tmp_path / name
    done = orchestrator("run", CONFIG, "--record", record, "--set", "run.duration=2 s", *[f"--set={s}" for s in sets])
    assert done.returncode == expect, done.stderr[-2000:]
    return done, record


@pytest.fixture(scope="module")
def undisturbed(tmp_path_factory):
    _, record = _run(tmp_path_factory.mktemp("fmu"), "plain")
    return pandas.read_parquet(record / "signals.parquet")


def test_the_wheel_fmu_and_the_dart_bus_exchange_momentum_exactly(undisturbed):
    """The FMU integrates its own inertial wheel speed from the torque it commands; DART gives the
    bus rate and the joint rate. Two models, one answer: ws = wz + qd, and with zero total
    momentum about z, I_bus wz + J ws = 0 (so wz = -J ws / I_bus)."""
    d = undisturbed
    ws, wz, qd = (
        d["wheel.wheel_speed"].to_numpy(),
        d["dynamics.sat.twist[5]"].to_numpy(),
        d["dynamics.sat.qd[0]"].to_numpy(),
    )
    assert ws[-1] > 1.0  # 0.1 N m for ~2 s on 0.05 kg m^2
    assert np.abs(ws - (wz + qd)).max() < 1e-12 * ws[-1] * 100
    assert np.abs(I_BUS_Z * wz + J_WHEEL * ws).max() < 1e-12
    assert np.abs(d["dynamics.sat.twist[3]"]).max() < 1e-15 and np.abs(d["dynamics.sat.twist[4]"]).max() < 1e-15
    tau = d["wheel.motor_torque"].to_numpy()
    assert tau[-1] == pytest.approx(0.1, rel=1e-9)  # the lag settled on the command
    assert np.array_equal(d["wheel.reaction_torque"].to_numpy(), -tau)


def test_a_swap_and_a_restart_of_the_fmu_continue_from_its_state(tmp_path, undisturbed):
    _, swapped = _run(tmp_path, "swap", "events=[{at: 1 s, swap: wheel}]")
    _, restarted = _run(
        tmp_path,
        "restart",
        "components.wheel.on_failure=restart",
        "run.checkpoint_every=500 ms",
        "faults=[{at: 1.23 s, component: wheel, kind: crash}]",
    )
    events = (restarted / "events.jsonl").read_text()
    assert '"restart"' in events and '"fault"' in events
    for record in (swapped, restarted):
        assert pandas.read_parquet(record / "signals.parquet").equals(undisturbed)  # bit for bit


def test_a_failing_fmu_step_ends_the_run_naming_the_component_and_the_step(tmp_path, write_config):
    config = write_config(f"""
run: {{name: probe_fails, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 10 ms}}
components:
  probe: {{type: fmu, parameters: {{path: {ROOT}/tests/fmus/probe.py, start_values: {{fail_at: 0.25}}}}}}
""")
    done = orchestrator("run", config, "--record", tmp_path / "rec")
    assert done.returncode == 1
    assert "probe" in done.stderr and "step 25" in done.stderr and "told to fail" in done.stderr, done.stderr[-1500:]
    assert "Traceback" not in done.stderr
    rows = pandas.read_parquet(tmp_path / "rec" / "signals.parquet")
    assert rows["probe.count"].iloc[-1] == 25 and len(rows) == 26  # every step before the failure kept
    assert not component_processes("probe_fails-")


def test_check_refuses_before_anything_starts(tmp_path, write_config):
    stateless = tmp_path / "stateless"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pythonfmu",
            "build",
            "-f",
            str(ROOT / "tests" / "fmus" / "probe.py"),
            "-d",
            str(stateless),
        ],
        check=True,
        capture_output=True,
    )

    def variant(edit):
        config = yaml.safe_load(CONFIG.read_text())
        config["components"]["wheel"]["parameters"]["path"] = str(ROOT / "models" / "reaction_wheel.py")
        config["components"]["dynamics"]["parameters"]["bodies"]["sat"]["urdf"] = str(
            ROOT / "models" / "wheel_sat.urdf"
        )
        edit(config)
        return write_config(yaml.safe_dump(config), "variant.yaml")

    cases = {
        "start_values.gain: the FMU has no variable 'gain'": lambda c: c["components"]["wheel"]["parameters"][
            "start_values"
        ].update(gain=1.0),
        "unit mismatch: input dynamics.sat.tau is in N*m, output wheel.wheel_speed in rad/s": lambda c: c[
            "connections"
        ].update({"dynamics.sat.tau": "wheel.wheel_speed"}),
        "connections.dynamics.r_eci: shape mismatch": lambda c: c["connections"].update(
            {"dynamics.r_eci": "wheel.wheel_speed"}
        ),
        "components.wheel.parameters.path: FMU file": lambda c: c["components"]["wheel"]["parameters"].update(
            path="missing.fmu"
        ),
    }
    for message, edit in cases.items():
        done = orchestrator("check", variant(edit))
        assert done.returncode == 2 and message in done.stderr, (message, done.stderr)
    config = write_config(f"""
run: {{name: stateless, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 10 ms}}
components:
  probe: {{type: fmu, on_failure: restart, parameters: {{path: {stateless}/Probe.fmu}}}}
""")
    done = orchestrator("check", config)
    assert done.returncode == 2 and "canGetAndSetFMUstate=false" in done.stderr, done.stderr
    done = orchestrator(
        "check", config, "--set", "components.probe.on_failure=stop", "--set", "events=[{at: 0.5 s, swap: probe}]"
    )
    assert done.returncode == 2 and "events[0].swap: a swap to the same type hands the state over" in done.stderr
