"""Outcomes a script can read (issue 44): the shipped capture config, really run (six component
processes over Zenoh), short enough to end captured, aborted or undecided. The summary line (the
last of stderr) states the outcome, events.jsonl's end event records it, --expect / run.expect
turn another outcome into exit code 3, an unknown one is refused before anything starts, and a
campaign's cases say undecided instead of completed."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import pyarrow.parquet as pq
import pytest
import yaml

from tests.conftest import ROOT, component_processes, orchestrator

pytestmark = pytest.mark.integration

CONFIG = ROOT / "configs" / "capture_tumbling_target.yaml"
QUICK_ABORT = "components.controller.parameters.capture_timeout=0.3 s"  # no estimate by then: aborted


def end_event(record) -> dict:
    events = [json.loads(line) for line in (record / "events.jsonl").read_text().splitlines()]
    return events[-1]


def last_line(result) -> str:
    return result.stderr.strip().splitlines()[-1]


def test_a_run_that_does_not_conclude_is_undecided_and_fails_expect_captured(tmp_path):
    """1 s of the shipped capture (the grapple is met at ~2 s): undecided, exit 3 under --expect captured."""
    run = orchestrator("run", CONFIG, "--set", "run.duration=1 s", "--expect", "captured", "--record", tmp_path / "r")
    assert run.returncode == 3, run.stderr
    assert last_line(run).endswith("; undecided: neither captured nor aborted by 1 s"), last_line(run)
    assert "error: the run's outcome is undecided, not captured as expected (exit code 3)" in run.stderr
    end = end_event(tmp_path / "r")
    assert (end["event"], end["status"], end["outcome"]) == ("end", "completed", "undecided")
    assert component_processes() == []


def test_an_abort_is_stated_with_its_time_and_reason_and_run_expect_accepts_it(tmp_path):
    run = orchestrator(
        "run",
        CONFIG,
        "--set",
        "run.duration=1 s",
        "--set",
        QUICK_ABORT,
        "--set",
        "run.expect=aborted",
        "--record",
        tmp_path / "r",
    )
    assert run.returncode == 0, run.stderr
    events = [json.loads(line) for line in (tmp_path / "r" / "events.jsonl").read_text().splitlines()]
    aborted = next(e for e in events if e["event"] == "capture_aborted")
    assert last_line(run).endswith(f"; capture aborted at {aborted['time']:g} s: {aborted['reason']}"), last_line(run)
    assert events[-1]["outcome"] == "aborted" and events[-1]["outcome_text"].startswith("capture aborted at 0.3 s: ")
    # --expect overrides run.expect
    other = orchestrator(
        "run",
        CONFIG,
        "--set",
        "run.duration=1 s",
        "--set",
        QUICK_ABORT,
        "--set",
        "run.expect=aborted",
        "--expect",
        "undecided",
    )
    assert other.returncode == 3 and "capture aborted at 0.3 s" in last_line(other), other.stderr
    assert component_processes() == []


def test_a_capture_is_stated_at_the_controllers_capture_time(tmp_path):
    run = orchestrator("run", CONFIG, "--set", "run.duration=4.5 s", "--expect", "captured", "--record", tmp_path / "r")
    assert run.returncode == 0, run.stderr
    events = [json.loads(line) for line in (tmp_path / "r" / "events.jsonl").read_text().splitlines()]
    closed = next(e for e in events if e["event"] == "capture_closed")
    assert re.search(rf"; captured at {re.escape(format(closed['time'], 'g'))} s$", last_line(run)), last_line(run)
    assert events[-1]["outcome"] == "captured"
    assert component_processes() == []


def test_an_unknown_expected_outcome_is_refused_before_anything_starts(tmp_path):
    for args in (["--expect", "detumbled"], ["--set", "run.expect=detumbled"]):
        run = orchestrator("run", CONFIG, *args, "--record", tmp_path / "r")
        assert run.returncode == 2, run.stderr
        assert (
            "'detumbled' is not an outcome of controller (controller.capture); its outcomes: undecided, "
            "captured, aborted" in run.stderr
        )
        assert not (tmp_path / "r" / "events.jsonl").exists() and "Traceback" not in run.stderr
    check = orchestrator("check", CONFIG, "--expect", "detumbled")
    assert check.returncode == 2 and "its outcomes: undecided, captured, aborted" in check.stderr
    assert orchestrator("check", CONFIG, "--expect", "captured").returncode == 0
    plain = orchestrator("run", ROOT / "configs" / "orbit_iss_kepler.yaml", "--expect", "captured")
    assert plain.returncode == 2 and "no component of this run declares outcomes" in plain.stderr


def test_a_campaigns_cases_say_undecided_and_aborted_not_completed(tmp_path):
    campaign = tmp_path / "campaign.yaml"
    campaign.write_text(
        yaml.safe_dump(
            {
                "config": str(CONFIG),
                "samples": 1,
                "seed": 1,
                "grid": {
                    "run.duration": ["1 s"],
                    "components.controller.parameters.capture_timeout": ["0.3 s", "300 s"],
                },
                "metrics": {"abort_time": {"event": "capture_aborted", "field": "time"}},
                "keep": "none",
            }
        )
    )
    sweep = subprocess.run(
        [
            sys.executable,
            "-m",
            "orchestrator.cli",
            "sweep",
            str(campaign),
            "--out",
            str(tmp_path / "out"),
            "--jobs",
            "2",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert sweep.returncode == 0, sweep.stderr
    table = pq.read_table(tmp_path / "out" / "cases.parquet").to_pandas()
    assert list(table["status"]) == ["completed", "completed"]
    assert list(table["outcome"]) == ["aborted", "undecided"]
    assert "outcomes: 1 aborted (50%), 1 undecided (50%)" in sweep.stderr, sweep.stderr
    assert component_processes() == []
