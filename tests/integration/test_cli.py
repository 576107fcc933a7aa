"""The CLI around a run: check, describe, runtime swap."""
from __future__ import annotations

import json
import time

import numpy as np
import pyarrow.parquet as pq
import pytest

from tests.conftest import component_processes, orchestrator, start_run, wait_for_components

pytestmark = pytest.mark.integration

CHAIN = """
run: {name: swapme, epoch: 2022-09-18T12:00:00Z, duration: 600 s, step: 10 ms, realtime: 1.0}
components:
  source: {type: test.constant, parameters: {value: 1.0}}
  first: {type: test.integrator}
connections:
  first.u: source.y
"""


def test_check_and_describe(write_config):
    config = write_config(CHAIN)
    result = orchestrator("check", config)
    assert result.returncode == 0 and "2 components, 1 connections, 60000 steps" in result.stdout
    described = orchestrator("describe", "test.integrator")
    assert described.returncode == 0
    assert "gain" in described.stdout and "input   u" in described.stdout and "output  x" in described.stdout
    unknown = orchestrator("describe", "controller.nonexistent")
    assert unknown.returncode == 2 and "unknown component type" in unknown.stderr


def test_swap_while_running_hands_over_state(write_config, tmp_path):
    config = write_config(CHAIN)
    run = start_run(config, tmp_path / "rec")
    try:
        wait_for_components("swapme-", 2)
        time.sleep(0.5)
        bad = orchestrator("swap", "--run", "swapme", "first", "--set", "gian=3")
        assert bad.returncode == 2 and "gian: unknown parameter" in bad.stderr
        swap = orchestrator("swap", "--run", "swapme", "first", "--set", "gain=3")
        assert swap.returncode == 0, swap.stderr
        time.sleep(0.5)
        assert orchestrator("stop", "--run", "swapme").returncode == 0
        _, err = run.communicate(timeout=30)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 0, err
    events = [json.loads(line) for line in (tmp_path / "rec/events.jsonl").read_text().splitlines()]
    swap_event = next(e for e in events if e["event"] == "swap")
    s = swap_event["step"]
    x = np.array(pq.read_table(tmp_path / "rec/signals.parquet").column("first.x"))
    k = np.arange(len(x))
    h = 0.01
    expected = np.where(k <= s, k * h, s * h + 3 * (k - s) * h)  # the integral carries over, then gain 3
    assert np.allclose(x, expected, rtol=0, atol=1e-9)
    assert swap_event["generation"] == 1 and swap_event["state_handed_over"] is True
    assert not component_processes("swapme-")


def test_profile_reports_compute_and_waiting_per_component():
    result = orchestrator("run", "configs/user_component.yaml", "--set", "run.duration=0.5 s", "--profile")
    assert result.returncode == 0, result.stderr
    out = result.stderr
    assert "profile: 500 steps" in out and "real-time factor" in out
    for name in ("push", "spring"):
        row = next(line.split() for line in out.splitlines() if line.split()[:1] == [name])
        compute, waiting = float(row[1]), float(row[3])
        assert row[2] == row[4] == "us" and compute > 0 and waiting >= 0, out


def test_a_failed_runtime_swap_leaves_the_old_component_running(write_config, tmp_path):
    (tmp_path / "boom.py").write_text(
        "from components.testing.blocks import Integrator\n\n"
        "class Boom(Integrator):\n"
        "    def initialize(self, t0_ns, inputs):\n"
        "        raise RuntimeError('cannot start')\n")
    config = write_config(CHAIN.replace("swapme", "keepme"))
    run = start_run(config, tmp_path / "rec")
    try:
        wait_for_components("keepme-", 2)
        swap = orchestrator("swap", "--run", "keepme", "first", "--type", "boom.py:Boom")
        assert swap.returncode == 1 and "RuntimeError: cannot start" in swap.stderr, swap.stderr
        assert len(component_processes("keepme-")) == 2  # the replacement is gone, the old one runs
        time.sleep(0.3)
        assert orchestrator("stop", "--run", "keepme").returncode == 0
        _, err = run.communicate(timeout=30)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 0, err
    x = np.array(pq.read_table(tmp_path / "rec/signals.parquet").column("first.x"))
    assert np.allclose(x, 0.01 * np.arange(len(x)), rtol=0, atol=1e-9)  # integrated on, undisturbed
    events = [json.loads(line) for line in (tmp_path / "rec/events.jsonl").read_text().splitlines()]
    assert any(e["event"] == "warning" and "swap of first" in e["message"] for e in events)
    assert not component_processes("keepme-")


def test_an_unusable_record_directory_is_a_usage_error(write_config, tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    result = orchestrator("run", write_config(CHAIN), "--record", blocker / "rec")
    assert result.returncode == 2 and "--record" in result.stderr and "Traceback" not in result.stderr
