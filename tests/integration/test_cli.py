"""The CLI around a run: check, describe, runtime swap."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from components.units import duration_ns
from tests.conftest import (
    ROOT,
    SHIPPED,
    component_processes,
    config_missing,
    needs,
    orchestrator,
    signal_files,
    start_run,
    wait_for_components,
    wait_for_step,
)

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
    assert result.returncode == 0 and "2 components, 1 connection, 60000 steps" in result.stdout
    described = orchestrator("describe", "test.integrator")
    assert described.returncode == 0
    assert "gain" in described.stdout and "input   u" in described.stdout and "output  x" in described.stdout
    unknown = orchestrator("describe", "controller.nonexistent")
    assert unknown.returncode == 2 and "unknown component type" in unknown.stderr


def swap_step(record) -> int:
    """The step of the run's first swap, from events.jsonl (logged before `swap` answers)."""
    events = [json.loads(line) for line in (record / "events.jsonl").read_text().splitlines()]
    return next(e["step"] for e in events if e["event"] == "swap")


def test_swap_while_running_hands_over_state(write_config, tmp_path):
    config = write_config(CHAIN)
    run = start_run(config, tmp_path / "rec")
    try:
        wait_for_step("swapme", 20, run=run)  # mid-run: the integral is not 0
        bad = orchestrator("swap", "--run", "swapme", "first", "--set", "gian=3")
        assert bad.returncode == 2 and "gian: unknown parameter" in bad.stderr
        swap = orchestrator("swap", "--run", "swapme", "first", "--set", "gain=3")
        assert swap.returncode == 0, swap.stderr
        wait_for_step("swapme", swap_step(tmp_path / "rec") + 20, run=run)  # and steps after it
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
    assert s >= 20 and len(x) > s + 20
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
        "        raise RuntimeError('cannot start')\n"
    )
    config = write_config(CHAIN.replace("swapme", "keepme"))
    run = start_run(config, tmp_path / "rec")
    try:
        wait_for_components("keepme-", 2)
        swap = orchestrator("swap", "--run", "keepme", "first", "--type", "boom.py:Boom")
        assert swap.returncode == 1 and "RuntimeError: cannot start" in swap.stderr, swap.stderr
        assert len(component_processes("keepme-")) == 2  # the replacement is gone, the old one runs
        wait_for_step("keepme", 20, run=run)  # and steps on
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


SHORT = (
    CHAIN.replace("swapme", "short").replace("duration: 600 s", "duration: 1 s").replace("realtime: 1.0", "realtime: 0")
)


def test_every_run_ends_with_a_summary_even_off_a_terminal(write_config, tmp_path):
    """Output captured (no terminal): the last line says how the run ended, how far and how fast
    it got, and where the recording is; after Ctrl-C too. (Its figures of speed are the machine's:
    only their labels are checked.)"""
    done = orchestrator("run", write_config(SHORT), "--record", tmp_path / "rec")
    assert done.returncode == 0, done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("run short completed: 100 steps of 100, 1 s simulated; "), last
    assert " s wall (" in last and "real-time factor" in last, last
    assert last.endswith(f"; recording in {tmp_path / 'rec'}"), last

    started = time.monotonic()
    run = start_run(write_config(CHAIN.replace("swapme", "ctrlc")), tmp_path / "rec2")
    try:
        reached = wait_for_step("ctrlc", 50, run=run)
        run.send_signal(signal.SIGINT)
        _, err = run.communicate(timeout=60)
    finally:
        if run.poll() is None:
            run.kill()
    alive_s = time.monotonic() - started
    assert run.returncode == 130, err
    last = err.strip().splitlines()[-1]
    assert last.startswith("run ctrlc interrupted: "), last
    steps = int(last.split(": ")[1].split()[0])
    assert reached <= steps < 60000, last
    assert f": {steps} steps of 60000, {steps * 0.01:g} s simulated; " in last, last
    assert " s wall (" in last and "real-time factor" in last and last.endswith(f"; recording in {tmp_path / 'rec2'}")
    assert len(pq.read_table(tmp_path / "rec2" / "signals.parquet").column("step")) == steps + 1
    # realtime: 1.0 paces the run to the wall clock: it never gets ahead of it (a busy machine
    # only holds it back). Unpaced, these two blocks step 10 ms in a few microseconds.
    assert steps * 0.01 <= alive_s, (steps, alive_s)
    assert not component_processes("ctrlc-")


def test_record_refuses_a_used_directory_unless_overwrite(write_config, tmp_path):
    config, rec = write_config(SHORT), tmp_path / "rec"
    assert orchestrator("run", config, "--record", rec).returncode == 0
    before = signal_files(rec)
    (rec / "logs" / "stale.0.log").write_text("from an earlier run")

    again = orchestrator("run", config, "--record", rec, "--set", "components.source.parameters.value=2")
    assert again.returncode == 2 and str(rec) in again.stderr and "--overwrite" in again.stderr, again.stderr
    assert signal_files(rec) == before  # nothing lost

    replaced = orchestrator(
        "run", config, "--record", rec, "--overwrite", "--set", "components.source.parameters.value=2"
    )
    assert replaced.returncode == 0, replaced.stderr
    assert not (rec / "logs" / "stale.0.log").exists()
    assert pq.read_table(rec / "signals.parquet").column("first.x").to_pylist()[-1] == pytest.approx(2.0)

    (rec / "notes.txt").write_text("mine")  # not a run's: --overwrite keeps out
    refused = orchestrator("run", config, "--record", rec, "--overwrite")
    assert refused.returncode == 2 and "notes.txt" in refused.stderr and (rec / "notes.txt").exists()
    assert orchestrator("run", config, "--overwrite").returncode == 2


def test_messages_that_fit_the_mistake(write_config, tmp_path):
    config = write_config(SHORT)
    typo = orchestrator("check", config, "--set", "components.sorce.parameters.value=3")
    assert typo.returncode == 2
    assert "no component 'sorce' (components: source, first)" in typo.stderr, typo.stderr
    broken = write_config("run: {name: a, epoch: 2022-09-18T12:00:00Z\n  duration: 1 s\n", "broken.yaml")
    result = orchestrator("check", broken)
    lines = result.stderr.splitlines()
    assert result.returncode == 2 and "line 2, column 11" in lines[0], result.stderr
    assert lines[1] == "      duration: 1 s" and lines[2] == "    " + " " * 10 + "^", lines
    assert orchestrator("run", config, "--record", tmp_path / "rec").returncode == 0
    resolved = yaml.safe_load((tmp_path / "rec" / "config.yaml").read_text())
    assert resolved["run"]["duration"] == "1 s" and resolved["run"]["step"] == "10 ms"
    assert resolved["components"]["first"]["step"] == "10 ms"


def test_types_lists_every_registered_type_with_a_line():
    from components.registry import TYPES

    result = orchestrator("types")
    assert result.returncode == 0, result.stderr
    listed = {line.split()[0]: line.split(None, 1)[1] for line in result.stdout.splitlines() if line.startswith("  ")}
    assert set(listed) == set(TYPES) and "test.constant" in listed
    assert listed["orbit.kepler"] == "Keplerian orbit about the Earth, optionally with J2 secular drift"
    assert not any("``" in text or ":class:" in text or "(type" in text for text in listed.values())
    typo = orchestrator("check", "configs/user_component.yaml", "--set", "components.push.type=test.constnt")
    assert typo.returncode == 2 and "test.constant" in typo.stderr


def test_describe_a_user_component_shows_its_variables_once_its_parameters_are_given():
    cwd = ROOT / "components" / "examples"
    bare = orchestrator("describe", "oscillator.py:Oscillator", cwd=cwd)
    assert bare.returncode == 0, bare.stderr
    assert "depend on the required parameters mass, stiffness" in bare.stdout
    assert bare.stdout.count("moving mass") == 1  # parameters listed once
    given = orchestrator("describe", "oscillator.py:Oscillator", "--set", "mass=2", "--set", "stiffness=3 N/m", cwd=cwd)
    rows = [line.split() for line in given.stdout.splitlines() if line.startswith(("  input", "  output"))]
    assert [r[:3] for r in rows] == [["input", "force", "()"], ["output", "x", "()"], ["output", "v", "()"]], (
        given.stdout
    )
    typo = orchestrator("describe", "oscillator.py:Oscillator", "--set", "stifness=3", cwd=cwd)
    assert typo.returncode == 2 and "stifness: unknown parameter" in typo.stderr and "stiffness" in typo.stderr
    bad = orchestrator("describe", "oscillator.py:Oscillator", "--set", "mass=2", "--set", "stiffness=3 kg", cwd=cwd)
    assert bad.returncode == 2 and "stiffness" in bad.stderr and "Traceback" not in bad.stderr
    builtin = orchestrator("describe", "dynamics.dart", "--set", "bodies={sat: {urdf: models/target.urdf}}")
    assert builtin.returncode == 0 and "output  sat.orientation" in builtin.stdout, builtin.stderr
    assert ":class:" not in builtin.stdout and "``" not in builtin.stdout


def test_describe_shows_nested_parameters_typed_and_the_config_sections():
    """Nested parameters (bodies, gains, trajectories) are listed with their own typed fields, from the
    same declaration that validates them; `describe config` lists the config's sections."""
    dynamics = orchestrator("describe", "dynamics.dart")
    lines = [line.split() for line in dynamics.stdout.splitlines()]
    assert lines[[words[:1] for words in lines].index(["bodies"])][:5] == [
        "bodies",
        "{body",
        "name:",
        "Body}",
        "required",
    ]
    assert lines[[words[:1] for words in lines].index(["position"])][:9] == [
        "position",
        "float[3]",
        "[m];",
        "plausible",
        "-100",
        "to",
        "100",
        "km",
        "default",
    ]
    assert "Body: one free-floating URDF multibody (bodies.<name>)" in dynamics.stdout
    pid = orchestrator("describe", "controller.joint_pd").stdout
    assert "PID gains: one joint's gains" in pid and "float [N*m/rad]" in pid
    config = orchestrator("describe", "config")
    assert config.returncode == 0 and "step_timeout" in config.stdout and "default 10 s" in config.stdout
    assert "viewer: the live view, in Rerun or Foxglove" in config.stdout


def test_a_swap_to_another_type_records_what_is_true(write_config, tmp_path):
    """The old type's columns go NaN from the swap on, the new type's outputs get a table of their
    own, and the recorded config names the new type in an event: it replays the run."""
    import pandas

    run = start_run(write_config(CHAIN.replace("swapme", "retype")), tmp_path / "rec")
    try:
        wait_for_step("retype", 20, run=run)
        swap = orchestrator("swap", "--run", "retype", "first", "--type", "test.noop", "--set", "size=1")
        assert swap.returncode == 0, swap.stderr
        wait_for_step("retype", swap_step(tmp_path / "rec") + 10, run=run)
        assert orchestrator("stop", "--run", "retype").returncode == 0
        _, err = run.communicate(timeout=30)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 0, err
    record = tmp_path / "rec"
    events = [json.loads(line) for line in (record / "events.jsonl").read_text().splitlines()]
    swap_event = next(e for e in events if e["event"] == "swap")
    s = swap_event["step"]
    assert swap_event["type"] == "test.noop" and swap_event["parameters"] == {"size": 1}
    assert swap_event["state_handed_over"] is False
    signals = pandas.read_parquet(record / "signals.parquet")
    x = signals["first.x"].to_numpy()
    assert np.allclose(x[: s + 1], np.arange(s + 1) * 0.01, rtol=0, atol=1e-9) and np.isnan(x[s + 1 :]).all()
    assert len(x) > s + 1 and (signals["source.y"] == 1.0).all()
    swapped = pandas.read_parquet(record / "swaps" / f"first.{swap_event['generation']}.parquet")
    assert list(swapped.columns) == ["step", "time", "first.y[0]"]
    assert swapped["step"].tolist() == signals["step"].tolist()[s:] and (swapped["first.y[0]"] == 0.0).all()
    recorded = yaml.safe_load((record / "config.yaml").read_text())
    assert duration_ns(recorded["events"][0].pop("at"), "at") == s * 10_000_000
    assert recorded["events"] == [{"swap": "first", "type": "test.noop", "parameters": {"size": 1}}]
    rows = len(signals)
    replay = orchestrator(
        "run",
        record / "config.yaml",
        "--record",
        tmp_path / "replay",
        "--set",
        f"run.duration={(rows - 1) * 10} ms",
        "--set",
        "run.realtime=0",
    )
    assert replay.returncode == 0, replay.stderr
    assert pandas.read_parquet(tmp_path / "replay" / "signals.parquet").equals(signals)
    assert not component_processes("retype-")


# `orchestrator check` of each config given, in one process (one interpreter start, not one a config)
CHECK_EACH = """
import sys
from orchestrator.cli import main
failed = [path for path in sys.argv[1:] if main(["check", path]) != 0]
sys.exit(f"check failed: {failed}" if failed else 0)
"""


def test_check_compiles_no_kernel(tmp_path):
    """`orchestrator check` of every shipped config on a cold numba cache (an empty
    NUMBA_CACHE_DIR) compiles nothing: no kernel lands in the cache (a first run compiles them, at
    its instantiate, with its note); each check passes (issue 34)."""
    cache = tmp_path / "numba"
    configs = [str(c) for c in SHIPPED if not config_missing(c)]  # those of an extra not installed: exit 2
    result = subprocess.run(
        [sys.executable, "-c", CHECK_EACH, *configs],
        cwd=ROOT,
        env={**os.environ, "NUMBA_CACHE_DIR": str(cache)},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.count(": ok — ") == len(configs), result.stdout
    compiled = [p.name for p in cache.rglob("*") if p.is_file()]
    assert not compiled, compiled


@needs("robots", "the Panda of example-robot-data")
def test_dart_warnings_on_massless_links_are_no_noise():
    """The Panda on a bus (panda_link8 has no <inertial>, on a fixed joint: harmless): `check
    --strict` passes, with none of DART's raw C++ warning lines (issue 34) and no warning."""
    result = subprocess.run(
        [sys.executable, "-m", "orchestrator.cli", "check", "--strict", str(ROOT / "configs" / "panda_on_bus.yaml")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    assert "BodyNode.cpp" not in result.stderr and "\x1b[" not in result.stderr, result.stderr
    assert "without mass" not in result.stderr and "warning" not in result.stderr, result.stderr


def test_an_implausible_value_is_a_warning_and_under_strict_an_error(write_config, tmp_path):
    """Issue 44: a tumble rate of 8 meant in deg/s is said in deg/s by check (exit 0), refused by
    check --strict (exit 2); a run warns of a mass beyond its range, in events.jsonl too, and
    run --strict starts nothing."""
    capture = ROOT / "configs" / "capture_tumbling_target.yaml"
    rate = "components.dynamics.parameters.bodies.target.twist.rate"
    line = (
        f"{capture}: {rate}: 8 (read as rad/s) = 458 deg/s, outside the plausible 0 to 60 deg/s; "
        f"write '8 deg/s' for degrees"
    )
    check = orchestrator("check", capture, "--set", f"{rate}=8")
    assert check.returncode == 0 and check.stderr.splitlines() == [f"warning: {line}"], check.stderr
    strict = orchestrator("check", capture, "--set", f"{rate}=8", "--strict")
    assert strict.returncode == 2 and strict.stderr.splitlines() == [
        f"error: {line}",
        f"error: {capture}: --strict makes the warning above an error",
    ], strict.stderr
    config = write_config("""
run: {name: heavy, epoch: 2022-09-18T12:00:00Z, duration: 10 ms, step: 1 ms}
components:
  spring: {type: components.examples.oscillator:Oscillator, parameters: {mass: 1e7, stiffness: 8 N/m}}
""")
    said = (
        f"{config}: components.spring.parameters.mass: 1e7 (read as kg), outside the plausible 0.001 to 1e+06 kg; "
        f"write '1e7 g' for grams"
    )
    run = orchestrator("run", config, "--record", tmp_path / "rec")
    assert run.returncode == 0, run.stderr
    assert f"warning: {said}" in run.stderr.splitlines(), run.stderr
    events = [json.loads(line) for line in (tmp_path / "rec" / "events.jsonl").read_text().splitlines()]
    assert [e["message"] for e in events if e["event"] == "warning"] == [said]
    refused = orchestrator("run", config, "--record", tmp_path / "strict", "--strict")
    assert refused.returncode == 2 and refused.stderr.splitlines() == [
        f"error: {said}",
        f"error: {config}: --strict makes the warning above an error",
    ], refused.stderr
    assert not (tmp_path / "strict").exists() or not any((tmp_path / "strict").iterdir())
