"""Multi-process runs: the real orchestrator CLI, real component processes, real Zenoh on loopback."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from tests.conftest import (
    ROOT,
    component_processes,
    orchestrator,
    signal_files,
    start_run,
    wait_for_components,
    wait_for_step,
    wait_until,
)

pytestmark = pytest.mark.integration

CHAIN = """
run: {{name: {name}, epoch: 2022-09-18T12:00:00Z, duration: {steps} s, step: 1 s, algorithm: {algorithm}}}
components:
  source: {{type: test.constant, parameters: {{value: 1.0}}}}
  first: {{type: test.integrator}}
  second: {{type: test.integrator}}
connections:
  first.u: source.y
  second.u: first.x
"""


def signals(directory):
    return pq.read_table(directory / "signals.parquet").to_pydict()


def events(directory):
    import json

    return [json.loads(line) for line in (directory / "events.jsonl").read_text().splitlines()]


@pytest.mark.parametrize(
    "algorithm, second",
    [
        # integrator chain with a 1 s step: first.x(k) = k exactly; second sees first.x with
        # Jacobi's one-step delay (sum of 0..k-1) or Gauss-Seidel's same-step value (sum of 1..k).
        ("jacobi", lambda k: k * (k - 1) / 2),
        ("gauss-seidel", lambda k: k * (k + 1) / 2),
    ],
)
def test_integrator_chain_matches_closed_form_exactly(write_config, tmp_path, algorithm, second):
    steps = 10_000
    config = write_config(CHAIN.format(name="chain", steps=steps, algorithm=algorithm))
    result = orchestrator("run", config, "--record", tmp_path / "rec")
    assert result.returncode == 0, result.stderr
    data = signals(tmp_path / "rec")
    k = np.arange(steps + 1)
    assert data["step"] == list(k)
    assert np.array_equal(data["time"], k.astype(float))
    assert np.array_equal(data["first.x"], k.astype(float))  # exact: integers in float64
    assert np.array_equal(data["second.x"], second(k).astype(float))
    kinds = [e["event"] for e in events(tmp_path / "rec")]
    assert kinds[0] == "start" and kinds[-1] == "end"
    assert (tmp_path / "rec" / "config.yaml").exists()
    assert not component_processes("chain-")


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_multi_rate_component_holds_between_its_steps(write_config, tmp_path, algorithm):
    config = write_config(f"""
run: {{name: rates, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 10 ms, algorithm: {algorithm}}}
components:
  slow: {{type: test.counter, step: 50 ms}}
  fast: {{type: test.counter}}
  sum: {{type: test.integrator}}
connections: {{sum.u: slow.n}}
""")
    assert orchestrator("run", config, "--record", tmp_path / "rec").returncode == 0
    data = signals(tmp_path / "rec")
    k = np.arange(101)
    assert np.array_equal(data["fast.n"], k)
    # slow steps at k = 0, 5, 10, ... over 50 ms; its output for t_(k+5) shows from row k+5 on and
    # holds until its next one: never a value from the future
    assert np.array_equal(data["slow.n"], np.floor(k / 5))
    # a reader sees the held value: Jacobi the row before (t_k), Gauss-Seidel, placed after it in
    # config order, the value for t_(k+1)
    j = np.arange(100)
    u = np.floor(j / 5) if algorithm == "jacobi" else np.floor((j + 1) / 5)
    assert np.allclose(data["sum.x"], np.concatenate([[0.0], np.cumsum(0.01 * u)]), rtol=0, atol=1e-12)


def test_two_runs_of_one_config_are_bit_identical(write_config, tmp_path):
    config = write_config("""
run: {name: twice, epoch: 2022-09-18T12:00:00Z, duration: 3 s, step: 1 ms}
components:
  push: {type: test.constant, parameters: {value: 2.0}}
  spring: {type: oscillator.py:Oscillator, parameters: {mass: 2 kg, stiffness: 8 N/m, x0: 1 m}}
connections: {spring.force: push.y}
""")
    (tmp_path / "oscillator.py").write_text((ROOT / "components/examples/oscillator.py").read_text())
    for name in ("a", "b"):
        assert orchestrator("run", config, "--record", tmp_path / name).returncode == 0
    assert signal_files(tmp_path / "a") == signal_files(tmp_path / "b")


def test_two_simultaneous_runs_do_not_cross(write_config, tmp_path):
    """Same run name, same keys, two orchestrators at once: each sees only its own components."""
    procs = []
    for value, name in ((1.0, "a"), (3.0, "b")):
        config = write_config(
            CHAIN.format(name="same", steps=3000, algorithm="jacobi").replace("value: 1.0", f"value: {value}"),
            name=f"{name}.yaml",
        )
        procs.append(start_run(config, tmp_path / name))
    for p in procs:
        _, err = p.communicate(timeout=120)
        assert p.returncode == 0, err
    k = np.arange(3001)
    for value, name in ((1.0, "a"), (3.0, "b")):
        data = signals(tmp_path / name)
        assert np.array_equal(data["first.x"], value * k)
        assert np.array_equal(data["second.x"], value * k * (k - 1) / 2)


def test_user_component_from_the_readme(tmp_path):
    """configs/user_component.yaml: a mass on a spring under a constant force, against the closed form."""
    result = orchestrator("run", "configs/user_component.yaml", "--record", tmp_path / "rec")
    assert result.returncode == 0, result.stderr
    data = signals(tmp_path / "rec")
    t, x = np.array(data["time"]), np.array(data["spring.x"])
    omega, f_over_k = np.sqrt(8 / 2), 2.0 / 8
    reference = f_over_k + (1 - f_over_k) * np.cos(omega * t)
    # semi-implicit Euler at h = 1 ms: phase error ~ omega^3 h t / 24 per unit amplitude, < 1e-3 m over 10 s
    assert np.abs(x - reference).max() < 2e-3


FAULTY = """
run: {{name: faulty, epoch: 2022-09-18T12:00:00Z, duration: 10 s, step: 10 ms, step_timeout: 5 s}}
components:
  counter: {{type: test.counter}}
  bad: {{type: test.faulty, parameters: {{fault: {fault}, at_step: 50}}}}
"""


@pytest.mark.parametrize(
    "fault, message",
    [
        ("raise", "component 'bad' (test.faulty) failed in step 50 (t = 0.5 s): RuntimeError: deliberate failure"),
        ("kill", "component 'bad' (test.faulty) died at step "),
        ("exit", "component 'bad' (test.faulty) died at step "),
        ("hang", "component 'bad' did not answer step 50 within 5 s"),
        ("nan", "component 'bad' produced a non-finite value in output 'y' at step 50"),
    ],
)
def test_a_failing_component_stops_the_run_with_exit_1(write_config, tmp_path, fault, message):
    config = write_config(FAULTY.format(fault=fault))
    result = orchestrator("run", config, "--record", tmp_path / "rec", timeout=120)
    assert result.returncode == 1
    assert message in result.stderr, result.stderr
    assert "Traceback" not in result.stderr
    data = signals(tmp_path / "rec")  # readable up to the failure
    # a process that dies outright (SIGKILL, _exit) takes with it the outputs that had not yet left
    # it (its unsent batch, and what Zenoh's sending thread still held): the recording ends at the
    # last step that reached the orchestrator, which the message names
    last = int(result.stderr.split("died at step ")[1].split(":")[0]) if fault in ("kill", "exit") else 50
    assert last <= 50
    assert data["step"] == list(range(last + 1)) and data["counter.n"][-1] == last
    assert events(tmp_path / "rec")[-1]["status"] == "failed"
    assert not component_processes("faulty-")


def test_every_row_the_failing_component_sent_is_recorded_when_the_others_are_late(write_config, tmp_path):
    """The failing component's last outputs make rows only with the others' outputs for them. On a
    loaded machine those may come seconds later: here the counter is held 3 s at step 45 (an
    injected delay: a component starved of CPU, as it looks to the orchestrator) while 'bad' runs
    ahead and fails at step 50. Every row up to 50 is recorded, none left out for lateness."""
    config = write_config(
        FAULTY.format(fault="raise") + "faults: [{at: 0.45 s, component: counter, kind: delay, duration: 3 s}]\n"
    )
    result = orchestrator("run", config, "--record", tmp_path / "rec", timeout=120)
    assert result.returncode == 1, result.stderr
    assert "component 'bad' (test.faulty) failed in step 50" in result.stderr, result.stderr
    data = signals(tmp_path / "rec")
    assert data["step"] == list(range(51)) and data["counter.n"] == [float(k) for k in range(51)]
    assert data["bad.y"][-1] == 50


def test_component_killed_from_outside_is_seen_quickly(write_config, tmp_path):
    """SIGKILL from another process midway: liveliness tells the orchestrator, not the step
    deadline (an hour here: a run that waited for it would outlast the test's wait)."""
    config = write_config("""
run: {name: victim, epoch: 2022-09-18T12:00:00Z, duration: 600 s, step: 1 ms, realtime: 1.0, step_timeout: 1 h}
components:
  a: {type: test.counter}
  b: {type: test.counter}
""")
    run = start_run(config, tmp_path / "rec")
    try:
        victims = wait_for_components("victim-", 2)
        reached = wait_for_step("victim", 100, run=run)
        pid = next((int(line.split()[0]) for line in victims if "--name b " in line), None)
        if pid is None:
            run.kill()
            raise AssertionError(f"no component b: {victims} {run.communicate()}")
        os.kill(pid, signal.SIGKILL)
        _, err = run.communicate(timeout=120)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 1, err
    assert "component 'b' (test.counter) died" in err and "did not answer" not in err, err
    steps = signals(tmp_path / "rec")["step"]
    assert steps == list(range(len(steps))) and len(steps) > reached  # every row up to the death
    assert not component_processes("victim-")


def test_stop_and_ps_from_the_cli(write_config, tmp_path):
    config = write_config("""
run: {name: longrun, epoch: 2022-09-18T12:00:00Z, duration: 1000 s, step: 1 ms, realtime: 1.0}
components:
  a: {type: test.counter}
""")
    run = start_run(config, tmp_path / "rec")
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            listing = orchestrator("ps")
            if "longrun-" in listing.stdout and "a:test.counter" in listing.stdout:
                break
            time.sleep(0.5)
        assert "a:test.counter" in listing.stdout, listing
        reached = wait_for_step("longrun", 10, run=run)
        stop = orchestrator("stop", "--run", "longrun")
        assert stop.returncode == 0, stop.stderr
        run.communicate(timeout=30)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 0
    data = signals(tmp_path / "rec")
    assert reached <= data["step"][-1] < 1_000_000 and data["a.n"][-1] == data["step"][-1]
    assert events(tmp_path / "rec")[-1]["status"] == "stopped by request"
    assert orchestrator("stop", "--run", "longrun").returncode == 2  # gone now: named, exit 2


def thread_cpus(pid: int) -> dict[int, set[int]]:
    """{thread id: the CPUs it may run on} of a live process, from /proc."""
    cpus = {}
    for tid in os.listdir(f"/proc/{pid}/task"):
        status = Path(f"/proc/{pid}/task/{tid}/status").read_text()
        allowed = status.split("Cpus_allowed_list:")[1].split()[0]
        cpus[int(tid)] = {
            c for part in allowed.split(",") for c in (range(int(part.split("-")[0]), int(part.split("-")[-1]) + 1))
        }
    return cpus


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs 2 CPUs")
@pytest.mark.parametrize("mode", ["true", "process"])
def test_dedicated_cpu_keeps_every_other_thread_of_the_run_off_it(write_config, tmp_path, mode):
    """true: a's stepping thread alone on its CPU, a's bus threads with the rest of the run;
    process: every thread of a's process on its CPU; either way no thread of b or the orchestrator."""
    config = write_config(f"""
run: {{name: pinned, epoch: 2022-09-18T12:00:00Z, duration: 1000 s, step: 1 ms, realtime: 1.0}}
components:
  a: {{type: test.counter, dedicated_cpu: {mode}}}
  b: {{type: test.counter}}
""")
    dedicated = max(os.sched_getaffinity(0))
    run = start_run(config, tmp_path / "rec")
    try:
        lines = wait_for_components("pinned-", 2)
        pids = {line.split("--name ")[1].split()[0]: int(line.split()[0]) for line in lines}
        wait_for_step("pinned", 10, run=run)  # stepping: every process has its bus threads
        a, b, orchestrator_threads = thread_cpus(pids["a"]), thread_cpus(pids["b"]), thread_cpus(run.pid)
        assert a[pids["a"]] == {dedicated}  # a's stepping (main) thread, alone on its CPU
        a_bus = [c for tid, c in a.items() if tid != pids["a"]]
        others = list(b.values()) + list(orchestrator_threads.values()) + (a_bus if mode == "true" else [])
        # the bus's threads are among them: a's own besides its stepping thread (true), b's, the orchestrator's
        assert len(a) > 1 and len(b) > 1 and len(orchestrator_threads) > 1, (a, b, orchestrator_threads)
        assert all(dedicated not in c and c for c in others), (dedicated, a, b, orchestrator_threads)
        if mode == "process":
            assert all(c == {dedicated} for c in a_bus), a
        assert orchestrator("stop", "--run", "pinned").returncode == 0
        run.communicate(timeout=30)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 0
    start = events(tmp_path / "rec")[0]
    assert start["cpus"]["a"] == dedicated and dedicated not in start["cpus"]["shared"]
    assert not component_processes("pinned-")


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs 2 CPUs")
def test_dedicated_cpu_of_a_member_places_its_whole_process_group(write_config, tmp_path):
    """a asks for a CPU (process), c in its group does not say: the group's process, every thread
    of it, is on that CPU, and no thread of b or the orchestrator."""
    config = write_config("""
run: {name: grouped_pin, epoch: 2022-09-18T12:00:00Z, duration: 1000 s, step: 1 ms, realtime: 1.0}
components:
  a: {type: test.counter, dedicated_cpu: process, process: pair}
  b: {type: test.counter}
  c: {type: test.counter, process: pair}
""")
    dedicated = max(os.sched_getaffinity(0))
    run = start_run(config, tmp_path / "rec")
    try:
        lines = wait_for_components("grouped_pin-", 2)
        group = next(int(line.split()[0]) for line in lines if "--member=a:0 --member=c:0" in line)
        other = next(int(line.split()[0]) for line in lines if "--name b" in line)
        wait_for_step("grouped_pin", 10, run=run)
        pair, b, orchestrator_threads = thread_cpus(group), thread_cpus(other), thread_cpus(run.pid)
        assert len(pair) > 1 and all(c == {dedicated} for c in pair.values()), pair
        assert all(dedicated not in c and c for c in [*b.values(), *orchestrator_threads.values()])
        assert orchestrator("stop", "--run", "grouped_pin").returncode == 0
        run.communicate(timeout=30)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 0
    start = events(tmp_path / "rec")[0]
    assert start["cpus"]["a"] == start["cpus"]["c"] == dedicated and dedicated not in start["cpus"]["shared"]
    assert not component_processes("grouped_pin-")


def test_ctrl_c_stops_cleanly(write_config, tmp_path):
    """Ctrl-C on a terminal signals the whole process group: components leave it to the orchestrator."""
    config = write_config("""
run: {name: interrupted, epoch: 2022-09-18T12:00:00Z, duration: 1000 s, step: 1 ms, realtime: 1.0}
components:
  a: {type: test.counter}
""")
    run = start_run(config, tmp_path / "rec", start_new_session=True)
    try:
        reached = wait_for_step("interrupted", 10, run=run)
        os.killpg(run.pid, signal.SIGINT)
        _, err = run.communicate(timeout=60)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 130, err
    assert "Traceback" not in err
    data = signals(tmp_path / "rec")
    assert data["a.n"][-1] == data["step"][-1] >= reached
    assert not component_processes("interrupted-")


def test_swap_event_hands_over_state(write_config, tmp_path):
    """A same-type swap at 5 s continues exactly; the new generation's integrator keeps the integral."""
    config = write_config(
        CHAIN.format(name="swapper", steps=10, algorithm="jacobi")
        + "events:\n  - {at: 5 s, swap: second, parameters: {gain: 2.0}}\n"
    )
    assert orchestrator("run", config, "--record", tmp_path / "rec").returncode == 0
    data = signals(tmp_path / "rec")
    k = np.arange(11)
    expected = np.where(k <= 5, k * (k - 1) / 2, 10 + 2 * (k * (k - 1) / 2 - 10))  # gain 2 from step 5 on
    assert np.array_equal(data["second.x"], expected)
    swaps = [e for e in events(tmp_path / "rec") if e["event"] == "swap"]
    assert swaps[0].pop("wall_s") > 0
    assert swaps == [
        {
            "event": "swap",
            "component": "second",
            "type": "test.integrator",
            "parameters": {"gain": 2.0, "x0": 0.0},
            "generation": 1,
            "step": 5,
            "time": 5.0,
            "state_handed_over": True,
        }
    ]


def test_bad_config_exits_2_before_starting_anything(write_config):
    config = write_config(CHAIN.format(name="bad", steps=5, algorithm="jacobi").replace("value: 1.0", "valeu: 1.0"))
    result = orchestrator("run", config)
    assert result.returncode == 2
    assert "components.source.parameters.valeu: unknown parameter" in result.stderr
    assert "components.source.parameters.value: missing required parameter" in result.stderr
    assert "Traceback" not in result.stderr
    assert not component_processes("bad-")


def test_a_recording_directory_removed_mid_run_fails_the_run_cleanly(write_config, tmp_path):
    """The directory deleted under a running recording: exit 1 naming the file, no traceback, and
    no process left (the orchestrator used to hang at exit on the bus's threads)."""
    import shutil

    config = write_config("""
run: {name: unrecorded, epoch: 2022-09-18T12:00:00Z, duration: 1000 s, step: 1 ms, realtime: 1.0}
components:
  a: {type: test.counter}
""")
    run = start_run(config, tmp_path / "rec")
    try:
        wait_for_step("unrecorded", 10, run=run)
        shutil.rmtree(tmp_path / "rec")
        _, err = run.communicate(timeout=60)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 1, err
    assert "cannot write" in err and "signals.parquet" in err and "Traceback" not in err
    assert not component_processes("unrecorded-")


SLOW_START = """
run: {name: slow-start, epoch: 2022-09-18T12:00:00Z, duration: 2 s, step: 1 s}
components:
  quick: {type: test.constant, parameters: {value: 1.0}}
  slow: {type: slow_start.py:SlowStart, parameters: {value: 2.0}}
"""

SLOW_COMPONENT = '''
import time
from pathlib import Path
from components.testing.blocks import Constant

class SlowStart(Constant):
    """A constant whose instantiate lasts until the test lets it go (the file GATE appears), as a
    component compiling its kernels would take long."""
    type_name = "test.slow_start"

    def __init__(self, params, run):
        while not Path(GATE).exists():
            time.sleep(0.05)
        super().__init__(params, run)
'''


def test_a_slow_instantiate_gets_a_note_naming_the_component(write_config, monkeypatch):
    """A first run on a machine compiles the kernels at instantiate (20-45 s on 2 cores): the run
    says what it waits for instead of sitting silent, naming only the component still instantiating;
    a start within SLOW_START_S says nothing. Driven by events, not by how long anything takes:
    the threshold drops to 0 once 'quick' has answered, and 'slow' goes on once the note is out."""
    import io
    import math
    import threading

    from orchestrator.config.load import load
    from orchestrator.run import engine, listener

    config = write_config(SLOW_START)
    gate = config.parent / "go"
    (config.parent / "slow_start.py").write_text(SLOW_COMPONENT.replace("GATE", repr(str(gate))))
    waits: list[dict] = []  # the instantiate wait's expectations, as the run meets them
    wait = listener.Listener.wait

    def watched_wait(self, expect, timeout, what):
        if what == "instantiate":
            waits.append(expect)
        return wait(self, expect, timeout, what)

    def conduct():  # quick answered -> no more patience; the note out -> slow may finish
        try:
            wait_until(lambda: waits and list(waits[0]) == ["slow"], "quick instantiated, slow still waited for")
            monkeypatch.setattr(listener, "SLOW_START_S", 0.0)
            wait_until(lambda: "note: waiting for" in out.getvalue(), "the note")
        finally:
            gate.touch()

    monkeypatch.setattr(listener.Listener, "wait", watched_wait)
    monkeypatch.setattr(listener, "SLOW_START_S", math.inf)
    out = io.StringIO()
    conductor = threading.Thread(target=conduct, daemon=True)
    conductor.start()
    assert engine.Run(load(config), out=out).execute() == 0, out.getvalue()
    conductor.join(timeout=60)
    notes = [line for line in out.getvalue().splitlines() if line.startswith("note: waiting for")]
    assert notes == [
        "note: waiting for 'slow' to instantiate: the first run on a machine compiles its kernels "
        "(numba; 20-45 s on 2 cores), later runs load them from the cache (run.start_timeout: 180 s)"
    ]
    monkeypatch.setattr(listener, "SLOW_START_S", math.inf)  # every start is quick against it: no note
    out = io.StringIO()
    assert (
        engine.Run(load(write_config(CHAIN.format(name="quick", steps=2, algorithm="jacobi"))), out=out).execute() == 0
    )
    assert "note: waiting for" not in out.getvalue()
