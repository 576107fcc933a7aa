"""The paper's demo (configs/humanoid_tracking.yaml, cut at 6 s) with its dynamics swapped from
dynamics.dart to dynamics.pinocchio at t = 5 s, over the bus: the new engine takes the old one's
state (never initialized; events.jsonl says so), the run ends within 1e-9 of the undisturbed DART
run, and the recorded config.yaml replays it bit for bit.

The undisturbed reference is the same config stepped in process (orchestrator/run/inprocess.py),
which a bus run equals bit for bit (tests/integration/test_bus_equals_in_process.py).
"""

from __future__ import annotations

import json

import numpy as np
import pandas
import pytest

from orchestrator.config.load import load
from orchestrator.run.inprocess import run_in_process
from orchestrator.run.rows import Rows
from tests.conftest import ROOT, component_processes, orchestrator

pytestmark = pytest.mark.integration

DEMO = ROOT / "configs" / "humanoid_tracking.yaml"
SHORT = "run.duration=6 s"
SWAP = "events=[{at: 5 s, swap: dynamics, type: dynamics.pinocchio}]"


def events(record) -> list[dict]:
    return [json.loads(line) for line in (record / "events.jsonl").read_text().splitlines()]


def test_swap_from_dart_to_pinocchio_continues_from_the_exact_state(tmp_path):
    record, replay = tmp_path / "swapped", tmp_path / "replay"
    done = orchestrator("run", DEMO, "--record", record, "--set", SHORT, "--set", SWAP)
    assert done.returncode == 0, done.stderr
    assert not component_processes("humanoid_tracking-")
    swap = next(e for e in events(record) if e["event"] == "swap")
    assert (swap["type"], swap["step"], swap["state_handed_over"]) == ("dynamics.pinocchio", 5000, True)
    swapped = pandas.read_parquet(record / "signals.parquet")

    config = load(DEMO, [SHORT])
    columns = Rows(config.components.values(), config.step_ns).columns
    undisturbed = pandas.DataFrame(run_in_process(config), columns=columns)
    dynamics = [c for c in columns if c.startswith(("dynamics.", "controller."))]
    before, after = swapped[dynamics].iloc[:5001].to_numpy(), swapped[dynamics].iloc[5000:].to_numpy()
    assert np.array_equal(before, undisturbed[dynamics].iloc[:5001].to_numpy())  # DART until the swap
    reference = undisturbed[dynamics].iloc[5000:].to_numpy()
    difference = np.abs(after - reference) / np.maximum(1.0, np.abs(reference))
    print(f"largest difference after the swap: {difference.max():.1e} (last row {difference[-1].max():.1e})")
    assert len(after) == 1001 and difference.max() <= 1e-9
    table = pandas.read_parquet(record / "swaps" / "dynamics.1.parquet")  # the new type's own table
    q = "dynamics.humanoid.q[13]"
    assert table["step"].iloc[0] == 5000 and np.array_equal(table[q].to_numpy(), swapped[q].to_numpy()[5000:])

    (tmp_path / "models").symlink_to(ROOT / "models")  # the recorded config's ../models/ paths
    done = orchestrator("run", record / "config.yaml", "--record", replay)
    assert done.returncode == 0, done.stderr
    assert pandas.read_parquet(replay / "signals.parquet").equals(swapped)
