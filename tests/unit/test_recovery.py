"""The decisions behind checkpoints, restarts and hang detection (orchestrator/run/recovery.py, state.py)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from components.schedule import Route
from orchestrator.config.specs import Fault
from orchestrator.run.recovery import hung, next_checkpoint
from orchestrator.run.state import Checkpoint, faults_left

MS = 1_000_000


def checkpoint_at(row: int) -> Checkpoint:
    return Checkpoint(row, np.zeros(0), [], {}, {}, [])


def test_periodic_checkpoints_fall_on_multiples_of_checkpoint_every():
    assert next_checkpoint(None, 100 * MS, MS) is None  # none taken yet: not restartable
    assert next_checkpoint(checkpoint_at(0), None, MS) is None  # no run.checkpoint_every
    assert next_checkpoint(checkpoint_at(0), 100 * MS, MS) == 100
    assert next_checkpoint(checkpoint_at(250), 100 * MS, MS) == 300  # after a swap's checkpoint at 250
    assert next_checkpoint(checkpoint_at(300), 100 * MS, 10 * MS) == 310


def test_a_restart_drops_the_fault_behind_it_and_those_the_run_went_past():
    passed, ahead, cause, later = (
        Fault(30 * MS, "y", "crash"),
        Fault(45 * MS, "y", "crash"),
        Fault(50 * MS, "x", "hang", 2000 * MS),
        Fault(120 * MS, "x", "crash"),
    )
    faults = [passed, ahead, cause, later]
    # x failed with steps up to 64 granted; the restart goes back to row 40
    assert faults_left(faults, "x", 64, 40, MS) == [ahead, later]
    # y failed: its first fault behind the horizon is the cause; x's fault at 50 fires again after row 40
    assert faults_left(faults, "y", 64, 40, MS) == [ahead, cause, later]


def test_a_member_holding_its_inputs_without_stepping_for_step_timeout_is_hung():
    source = SimpleNamespace(name="s", progress=20, progress_at=1.0, routes=[])
    consumer = SimpleNamespace(
        name="c", progress=5, progress_at=1.5, routes=[Route("s", np.arange(1), np.arange(1), 1, 0)]
    )
    live = {"s": source, "c": consumer}
    # c holds its inputs for step 5 (s is at 20) since its own last output at 1.5 s
    assert hung(live, 20, 0.5, 3.9, 2.5) is None
    assert hung(live, 20, 0.5, 4.1, 2.5) is consumer
    assert hung(live, 20, 2.0, 4.1, 2.5) is None  # a grant since: counted from there
    assert hung(live, 5, 0.5, 4.1, 2.5) is None  # step 5 is not granted
    source.progress = 4  # the input of step 5 has not come
    source.progress_at = 4.0
    assert hung(live, 20, 0.5, 4.1, 2.5) is None
    assert hung(live, 20, 0.5, 6.6, 2.5) is source  # ... and the source is the one stuck
