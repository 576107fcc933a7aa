"""A run over the bus gives exactly the numbers of the same components stepped in one process."""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from components.constants import NS_PER_S
from orchestrator.config.load import load
from orchestrator.run.inprocess import run_in_process
from tests.conftest import ROOT, orchestrator

pytestmark = pytest.mark.integration


def recorded(directory) -> np.ndarray:
    table = pq.read_table(directory / "signals.parquet")
    return np.column_stack([table.column(name).to_numpy() for name in table.column_names[2:]])


GROUPED_DEMO = ["components.dynamics.process=loop", "components.controller.process=loop"]


@pytest.mark.parametrize("grouping", [[], GROUPED_DEMO], ids=["separate", "grouped"])
def test_the_papers_demo_over_the_bus_equals_the_in_process_loop_bit_for_bit(tmp_path, grouping):
    config = ROOT / "configs" / "humanoid_tracking.yaml"
    overrides = ["run.duration=0.3 s", *grouping]
    result = orchestrator("run", config, "--record", tmp_path / "rec", *[a for o in overrides for a in ("--set", o)])
    assert result.returncode == 0, result.stderr
    bus = recorded(tmp_path / "rec")
    reference = run_in_process(load(config, overrides))
    assert bus.shape == reference.shape == (301, bus.shape[1])
    assert np.array_equal(bus, reference)
    assert np.ptp(bus[:, 0]) > 1e3  # the orbit moved (r_eci[0], m): not a run of start values


@pytest.mark.parametrize("grouped", [False, True], ids=["separate", "grouped"])
@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_a_multi_rate_loop_with_a_cycle_over_the_bus_equals_the_in_process_loop(
    write_config, tmp_path, algorithm, grouped
):
    # an oscillator pushed by a slower integrator of its own position: a feedback loop across rates;
    # the spring has a shadow of its own type and parameters, fed by integral, which comes after it
    # in config order: it equals the spring bit for bit only if it steps on the very same inputs.
    # Grouped: spring, integral and push in one process (the shadow, in its own, reads spring and
    # integral over the bus; total reads push over the bus), the numbers unchanged.
    group = ", process: loop" if grouped else ""
    config = write_config(f"""
run: {{name: loop, epoch: 2022-09-18T12:00:00Z, duration: 2 s, step: 1 ms, algorithm: {algorithm}}}
components:
  spring:
    type: components.examples.oscillator:Oscillator
    parameters: {{mass: 2 kg, stiffness: 8 N/m, x0: 1 m}}
    shadow: {{type: components.examples.oscillator:Oscillator, parameters: {{mass: 2 kg, stiffness: 8 N/m, x0: 1 m}}}}
    {"process: loop" if grouped else ""}
  integral: {{type: test.integrator, step: 7 ms, parameters: {{gain: -3.0}}{group}}}
  push: {{type: test.constant, parameters: {{value: 0.5}}{group}}}
  total: {{type: test.integrator}}
connections: {{spring.force: integral.x, integral.u: spring.x, total.u: push.y}}
""")
    result = orchestrator("run", config, "--record", tmp_path / "rec")
    assert result.returncode == 0, result.stderr
    bus = recorded(tmp_path / "rec")
    reference = run_in_process(load(config))
    assert np.array_equal(bus, reference)
    logs = sorted(p.name for p in (tmp_path / "rec" / "logs").glob("*.log"))
    assert logs == (
        ["group.loop.0.log", "spring_shadow.0.log", "total.0.log"]
        if grouped
        else ["integral.0.log", "push.0.log", "spring.0.log", "spring_shadow.0.log", "total.0.log"]
    )
    columns = pq.read_table(tmp_path / "rec" / "signals.parquet").column_names[2:]
    spring_x, integral_x = bus[:, columns.index("spring.x")], bus[:, columns.index("integral.x")]
    assert np.ptp(spring_x) > 0.5 and np.ptp(integral_x) > 0.1  # both moved
    spring = [c for c in columns if c.startswith("spring.")]
    assert len(spring) >= 2 and all(
        np.array_equal(bus[:, columns.index(c)], bus[:, columns.index(f"spring_shadow{c[6:]}")]) for c in spring
    )
    # the sample time of integral.u (spring.x): row r holds integral's output of its step k =
    # floor(r / 7) * 7 - 7, which read spring.x at t_k (Jacobi) or t_(k+1) (Gauss-Seidel: spring first)
    k = np.arange(len(bus)) // 7 * 7 - 7
    ahead = int(algorithm == "gauss-seidel")
    assert np.array_equal(bus[7:, columns.index("integral.u_time")], ((k + ahead) * 1_000_000 / NS_PER_S)[7:])


@pytest.mark.parametrize("grouped", [False, True], ids=["separate", "grouped"])
def test_same_type_swaps_in_the_demo_continue_exactly(tmp_path, grouped):
    """Swapping the controller (in the loop), its shadow and the orbit (running ahead, batched)
    mid-run hands their state over without a trace: the numbers equal an undisturbed in-process
    run (the shadow, of other gains, goes on beside a swapped main and through its own swap).
    Grouped: orbit, dynamics and controller in one process; each swapped member's new generation
    runs in a process of its own, the rest of the group goes on."""
    raw = yaml.safe_load(
        (ROOT / "configs" / "humanoid_tracking.yaml").read_text().replace("../models/", f"{ROOT}/models/")
    )
    if grouped:
        for name in ("orbit", "dynamics", "controller"):
            raw["components"][name]["process"] = "loop"
    controller = raw["components"]["controller"]
    controller["shadow"] = {"type": controller["type"], "parameters": {**controller["parameters"], "kp": [64] * 6}}
    reference = tmp_path / "shadowed.yaml"
    reference.write_text(yaml.safe_dump(raw, sort_keys=False))
    raw["events"] = [
        {"at": "0.1 s", "swap": "controller"},
        {"at": "0.15 s", "swap": "controller_shadow"},
        {"at": "0.2 s", "swap": "orbit"},
    ]
    config = tmp_path / "swaps.yaml"
    config.write_text(yaml.safe_dump(raw, sort_keys=False))
    result = orchestrator("run", config, "--record", tmp_path / "rec", "--set", "run.duration=0.3 s")
    assert result.returncode == 0, result.stderr
    swaps = [line for line in (tmp_path / "rec" / "events.jsonl").read_text().splitlines() if '"swap"' in line]
    assert len(swaps) == 3
    assert np.array_equal(recorded(tmp_path / "rec"), run_in_process(load(reference, ["run.duration=0.3 s"])))
    if grouped:
        logs = sorted(p.name for p in (tmp_path / "rec" / "logs").glob("*.log"))
        assert logs == [
            "controller.1.log",
            "controller_shadow.0.log",
            "controller_shadow.1.log",
            "group.loop.0.log",
            "orbit.1.log",
        ]
