"""Shadow mode end to end: the paper's demo (1 s) with a shadow of the controller that has other
gains, against the same run without it and against that controller run alone in the harness on
the recorded inputs; its plot; and a shadow that fails."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from components.testing.harness import Harness
from orchestrator.plots.recording import figures
from tests.conftest import ROOT, component_processes, orchestrator

pytestmark = pytest.mark.integration

BODY_INPUTS = ("position", "orientation", "twist", "q", "qd")  # what the controller reads of dynamics.humanoid


def load(directory) -> dict[str, np.ndarray]:
    table = pq.read_table(directory / "signals.parquet")
    return {name: table.column(name).to_numpy() for name in table.column_names}


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """The demo cut to 1 s, run twice at once: as shipped, and with a shadow controller of
    softer gains (kp 64, kd 16: still critically damped, 8 rad/s)."""
    base = tmp_path_factory.mktemp("shadow")
    raw = yaml.safe_load(
        (ROOT / "configs" / "humanoid_tracking.yaml").read_text().replace("../models/", f"{ROOT}/models/")
    )
    shadow = {**raw["components"]["controller"]["parameters"], "kp": [64] * 6, "kd": [16] * 6}
    raw["components"]["controller"]["shadow"] = {"type": "controller.computed_torque", "parameters": shadow}
    (base / "shadowed.yaml").write_text(yaml.safe_dump(raw, sort_keys=False))  # config order matters
    configs = {"plain": ROOT / "configs" / "humanoid_tracking.yaml", "shadowed": base / "shadowed.yaml"}
    procs = {
        name: subprocess.Popen(
            [
                sys.executable,
                "-m",
                "orchestrator.cli",
                "run",
                str(config),
                "--record",
                str(base / name),
                "--set",
                "run.duration=1 s",
            ],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for name, config in configs.items()
    }
    for name, proc in procs.items():
        try:
            _, err = proc.communicate(timeout=300)
        finally:
            if proc.poll() is None:
                proc.kill()
        assert proc.returncode == 0, f"{name}: {err}"
    return {name: load(base / name) for name in configs} | {"dir": base, "shadow": shadow}


def test_a_shadow_controller_leaves_the_run_untouched_and_equals_that_controller_fed_the_recorded_inputs(demo):
    plain, shadowed = demo["plain"], demo["shadowed"]
    assert len(plain["time"]) == 1001
    for column, values in plain.items():  # the loop never sees the shadow
        assert np.array_equal(shadowed[column], values), column
    start = json.loads((demo["dir"] / "shadowed" / "events.jsonl").read_text().splitlines()[0])
    assert start["components"]["controller_shadow"] == "controller.computed_torque"
    assert start["shadows"] == {"controller_shadow": "controller"}
    assert not component_processes(start["run_id"])

    # the shadow, run alone: at step k it reads dynamics' outputs at t_k (Jacobi: tag k = row k);
    # at initialize, dynamics' initialized outputs, sampled at 0 (it initializes before the controller)
    harness = Harness(
        "controller.computed_torque", demo["shadow"], epoch="2022-09-18T12:00:00Z", config_dir=ROOT / "configs"
    )
    columns = {
        v.name: [f"controller_shadow.{c.split('.', 1)[1]}" for c in v.columns("x")]
        for v in harness.output_layout.variables
    }

    def feed(row: int) -> None:
        for name in BODY_INPUTS:
            n = harness.input_layout.variables[[v.name for v in harness.input_layout.variables].index(name)].size
            harness.inputs[name] = np.array([shadowed[f"dynamics.humanoid.{name}[{i}]"][row] for i in range(n)])

    def recorded(row: int) -> np.ndarray:
        return np.array([shadowed[c][row] for v in columns.values() for c in v])

    def alone(outputs: dict) -> np.ndarray:
        return np.concatenate([np.ravel(outputs[name]) for name in columns])

    feed(0)
    harness.input_times_ns = dict.fromkeys(BODY_INPUTS, 0)
    assert np.array_equal(alone(harness.initialize()), recorded(0))
    harness.input_times_ns = {}  # from here on: each step's own time
    for k in range(1000):
        feed(k)
        assert np.array_equal(alone(harness.step(1_000_000)), recorded(k + 1)), f"step {k}"
    # not a copy of the main: other gains, other torques (the start's co-rotation error, ~1e-3 N m)
    tau = np.column_stack(
        [shadowed[f"controller.tau[{i}]"] - shadowed[f"controller_shadow.tau[{i}]"] for i in range(14)]
    )
    assert np.abs(tau).max() > 1e-4


def test_plot_draws_main_minus_shadow(demo):
    made = dict(figures(demo["dir"] / "shadowed"))
    assert "controller_shadow.png" in made and "controller_shadow.png" not in dict(figures(demo["dir"] / "plain"))
    ax = next(a for a in made["controller_shadow.png"].axes if a.get_title() == "|tau| (14 elements)")
    data = demo["shadowed"]
    tau = np.column_stack([data[f"controller.tau[{i}]"] - data[f"controller_shadow.tau[{i}]"] for i in range(14)])
    assert np.array_equal(ax.get_lines()[0].get_ydata(), np.linalg.norm(tau, axis=1))
    ax = next(a for a in made["controller_shadow.png"].axes if a.get_title() == "ee_error")
    assert len(ax.get_lines()) == 6 and not any(np.any(line.get_ydata()) for line in ax.get_lines())  # same inputs


def test_a_shadow_that_dies_fails_the_run_naming_it(write_config, tmp_path):
    config = write_config("""
run: {name: dies, epoch: 2022-09-18T12:00:00Z, duration: 2 s, step: 1 ms}
components:
  steady: {type: test.faulty, parameters: {fault: kill, at_step: 100000}, shadow: {type: test.faulty, parameters: {fault: kill, at_step: 500}}}
""")
    result = orchestrator("run", config, "--record", tmp_path / "rec")
    assert result.returncode == 1 and "component 'steady_shadow' (test.faulty) died at step" in result.stderr, (
        result.stderr
    )
    events = [json.loads(line) for line in (tmp_path / "rec" / "events.jsonl").read_text().splitlines()]
    assert events[-1]["status"] == "failed" and any(
        e["event"] == "fault" and "steady_shadow" in e["message"] for e in events
    )
    assert len(load(tmp_path / "rec")["steady.y"]) <= 501  # the run ended there
    assert not component_processes(events[0]["run_id"])
