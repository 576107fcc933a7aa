"""Nothing lost, nothing crashes (real processes, real Zenoh on loopback): a stranger publishing
garbage on a run's keys does not end it, and a kill -9 of the orchestrator leaves a recording
that reads with pandas and no process behind."""

import json
import signal
import struct
import time

import numpy as np
import pandas
import pytest

from components import bus, protocol, queries
from orchestrator.run import runs
from tests.conftest import (
    component_processes,
    orchestrator,
    recorded_rows,
    start_run,
    wait_for_components,
    wait_for_step,
    wait_until,
)

pytestmark = pytest.mark.integration

PACED = """
run: {{name: {name}, epoch: 2022-09-18T12:00:00Z, duration: {duration} s, step: 1 ms, realtime: 1.0}}
components:
  src: {{type: test.constant, parameters: {{value: 2.0}}}}
  int: {{type: test.integrator, parameters: {{gain: 0.5}}}}
connections:
  int.u: src.y
"""


def _events(record) -> list[dict]:
    return [json.loads(line) for line in (record / "events.jsonl").read_text().splitlines()]


def _registered(name: str, timeout: float = 120.0) -> dict:
    deadline = time.monotonic() + timeout
    while not (found := runs.find(name)) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert found, f"run {name} never registered"
    return found[0]


def _dropped(record) -> list[str]:
    return [e["message"] for e in _events(record) if e["event"] == "warning" and "dropped a message" in e["message"]]


def _peers(session) -> int:
    return len(list(session.info.peers_zid()))


GARBAGE_WARNINGS = ("r/int", "r/ghost", "c/int/99/out", "c/int/0/out")  # in events.jsonl, one per key at least
GARBAGE_LOGGED = ("dropped a message", "/o/ghost", "/c/0")  # in the integrator's log


def _framed(kind: bytes, body: dict) -> bytes:
    """A JSON message framed as protocol's are, whatever its body holds (garbage the encoders do not make)."""
    text = json.dumps(body).encode()
    return kind + struct.pack("<I", len(text)) + text


@pytest.mark.parametrize("secret", ["the run's", None, "wrong"])
def test_a_stranger_publishing_garbage_on_the_run_keys_does_not_end_it(write_config, tmp_path, secret):
    """With the run's secret (a buggy process of the run's user) the garbage arrives and is
    dropped with warnings; without it, or with another, the stranger cannot even join. The run
    goes on until stopped, every row there and the integral untouched."""
    config, record = write_config(PACED.format(name="stranger", duration=600)), tmp_path / "rec"
    run = start_run(config, record)
    try:
        assert len(wait_for_components("stranger-", 2)) == 2
        entry = _registered("stranger")
        rid = entry["run_id"]
        wait_for_step("stranger", 10, run=run)
        good = np.zeros((1, 2))  # integrator outputs: x, u_time
        garbage = {
            bus.batch_key(rid, "int"): [
                b"\x00\x01\x02",
                b"B" + bytes(30),
                bus.encode_batch(7, np.array([1]), good[:, :2], good),
                bus.encode_batch(0, np.array([1]), good[:, :2], np.zeros((1, 5))),
            ],
            bus.batch_key(rid, "ghost"): [bus.encode_batch(0, np.array([1]), good[:, :2], good)],
            bus.reply_key(rid, "int", 0): [b"R\xff\xff\xff\xff{", b"E" + bytes(8), _framed(b"E", {"op": "step"})],
            bus.reply_key(rid, "int", 99): [protocol.Fault("step", 1, "x").encode()],
            bus.run_key(rid, "c", "int", "x", "out"): [b"junk"],
            bus.output_key(rid, "int", "src"): [b"\x00\x01\x02", bus.encode_output(0, 5, np.zeros(0)), b"Qxx"],
            bus.output_key(rid, "int", "ghost"): [bus.encode_output(0, 5, np.zeros(1))],
            bus.command_key(rid, "int", 0): [
                b"\x00\x01\x02",
                _framed(b"C", {"op": "explode"}),
                b"C\x05\x00\x00\x00nope!",
            ],
        }
        key = entry["secret"] if secret == "the run's" else secret
        joins = key == entry["secret"]
        with bus.open_session(["tcp/127.0.0.1:0"], [entry["endpoint"]], mesh=True, secret=key) as session:
            if joins:  # gossip: the stranger gets to know every peer of the run
                wait_until(lambda: _peers(session) == 3, "gossip to the run's 3 peers", run=run)
            else:  # the same gossip, for one with the secret opened after it: done when it knows all 3
                with bus.open_session(
                    ["tcp/127.0.0.1:0"], [entry["endpoint"]], mesh=True, secret=entry["secret"]
                ) as insider:
                    wait_until(lambda: _peers(insider) >= 3, "gossip to the run's 3 peers", run=run)
                assert _peers(session) == 0
            replies = list(session.get(bus.run_key(rid, "ctl"), payload=queries.Status().encode(), timeout=30.0))
            assert len(replies) == (1 if joins else 0)
            for _ in range(3):
                for key, payloads in garbage.items():
                    for payload in payloads:
                        session.put(key, payload)
                time.sleep(0.2)
        component_log = record / "logs" / "int.0.log"
        if joins:  # dropped on arrival, each with a warning: wait for the last of them
            wait_until(
                lambda: (
                    all(any(k in m for m in _dropped(record)) for k in GARBAGE_WARNINGS)
                    and all(k in component_log.read_text() for k in GARBAGE_LOGGED)
                ),
                "warning for each garbage key",
                run=run,
            )
        assert orchestrator("stop", "--run", "stranger").returncode == 0
        _, err = run.communicate(timeout=60)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 0, err
    table = pandas.read_parquet(record / "signals.parquet")
    assert len(table) > 10 and table["step"].tolist() == list(range(len(table)))  # every row
    assert np.allclose(table["int.x"], 0.5 * 2.0 * table["time"], rtol=1e-9, atol=1e-12)  # x = gain u t: untouched
    events = _events(record)
    assert events[-1]["event"] == "end" and events[-1]["status"] == "stopped by request"
    assert not component_processes("stranger-")
    dropped, logged = _dropped(record), component_log.read_text()
    if not joins:
        assert not dropped and "dropped a message" not in logged, dropped  # nothing got in
        return
    assert all(any(k in m for m in dropped) for k in GARBAGE_WARNINGS), dropped
    assert all(k in logged for k in GARBAGE_LOGGED), logged


def test_kill_9_of_the_orchestrator_leaves_a_readable_recording_and_no_process(write_config, tmp_path):
    config, record = write_config(PACED.format(name="killed", duration=600)), tmp_path / "rec"
    run = start_run(config, record)
    try:
        assert len(wait_for_components("killed-", 2)) == 2
        wait_until(lambda: recorded_rows(record / "signals.parquet") >= 3000, "3000 rows on disk", run=run)
        run.send_signal(signal.SIGKILL)
        run.communicate(timeout=30)
        wait_until(lambda: not component_processes("killed-"), "end of the components after their orchestrator's")
    finally:
        if run.poll() is None:
            run.kill()
    table = pandas.read_parquet(record / "signals.parquet")
    steps = table["step"].to_numpy()
    assert len(steps) >= 3000 and np.array_equal(steps, np.arange(len(steps)))  # up to the last flush
    assert np.allclose(table["int.x"], 0.5 * 2.0 * steps * 1e-3, rtol=1e-9, atol=1e-12)
    events = _events(record)
    assert events[0]["event"] == "start" and not any(e["event"] == "end" for e in events), events[-1]


# ------------------------------------------------------------------ faults and restarts

FAULTED = """
run: {{name: {name}, epoch: 2022-09-18T12:00:00Z, duration: 2 s, step: 1 ms, {step_timeout}
      checkpoint_every: 0.5 s, max_restarts: {max_restarts}}}
components:
  src: {{type: test.constant, parameters: {{value: 2.0}}}}
  int: {{type: test.integrator, parameters: {{gain: 0.5}}, on_failure: {on_failure}}}
connections:
  int.u: src.y
faults: [{faults}]
"""


# A hang is told from a slow step by run.step_timeout: short here, so that a hang ends the test
# soon, with room on either side (a loaded machine's slow step, a delay fault's length).
FAULT_TIMEOUT = "step_timeout: 5 s,"


def _faulted(write_config, tmp_path, name, faults, on_failure="stop", max_restarts=3):
    config = write_config(
        FAULTED.format(
            name=name, faults=faults, on_failure=on_failure, max_restarts=max_restarts, step_timeout=FAULT_TIMEOUT
        ),
        f"{name}.yaml",
    )
    result = orchestrator("run", config, "--record", tmp_path / name, timeout=120)
    assert not component_processes(f"{name}-")
    return result, tmp_path / name


@pytest.fixture(scope="module")
def undisturbed(tmp_path_factory):
    """The faulted config's run without its faults, and with the default step timeout: the
    reference every recovery must equal."""
    tmp = tmp_path_factory.mktemp("undisturbed")
    config = tmp / "clean.yaml"
    config.write_text(FAULTED.format(name="clean", faults="", on_failure="stop", max_restarts=3, step_timeout=""))
    result = orchestrator("run", config, "--record", tmp / "rec")
    assert result.returncode == 0, result.stderr
    return pandas.read_parquet(tmp / "rec" / "signals.parquet")


@pytest.mark.parametrize(
    "fault, message",
    [
        ("{at: 1.3 s, component: int, kind: crash}", "component 'int' (test.integrator) died at step"),
        ("{at: 1.3 s, component: int, kind: hang}", "component 'int' did not answer step 1300 within 5 s"),
        (
            "{at: 1.3 s, component: int, kind: nan}",
            "component 'int' produced a non-finite value in output 'x' at step 1300",
        ),
        (
            "{at: 1.3 s, component: int, kind: delay, duration: 15 s}",
            "component 'int' did not answer step 1300 within 5 s",
        ),
    ],
)
def test_each_fault_kind_stops_a_run_that_does_not_restart(write_config, tmp_path, undisturbed, fault, message):
    result, record = _faulted(write_config, tmp_path, "stopped", fault)
    assert result.returncode == 1 and f"error: {message}" in result.stderr, result.stderr
    assert "Traceback" not in result.stderr
    events = _events(record)
    assert events[-2]["event"] == "fault" and message in events[-2]["message"]
    end = events[-1]
    assert end == {
        "event": "end",
        "step": end["step"],
        "time": end["time"],
        "status": "failed",
        "wall_s": end["wall_s"],
    }
    assert end["wall_s"] >= events[-2]["wall_s"] > 0  # the run's own clock: the fault, then the end
    table = pandas.read_parquet(record / "signals.parquet")
    assert 1000 <= len(table) <= 1301  # what came before the fault, and nothing after it
    assert table.equals(undisturbed.iloc[: len(table)])
    assert "injecting a fault" in (record / "logs" / "int.0.log").read_text()


def test_a_short_delay_only_slows_the_run(write_config, tmp_path, undisturbed):
    result, record = _faulted(
        write_config, tmp_path, "delayed", "{at: 1.3 s, component: int, kind: delay, duration: 0.3 s}"
    )
    assert result.returncode == 0, result.stderr
    assert pandas.read_parquet(record / "signals.parquet").equals(undisturbed)
    assert "injecting a fault: delay" in (record / "logs" / "int.0.log").read_text()


@pytest.mark.parametrize("kind", ["crash", "hang", "delay, duration: 15 s"])
def test_a_restart_from_the_last_checkpoint_ends_as_if_nothing_happened(write_config, tmp_path, undisturbed, kind):
    result, record = _faulted(
        write_config, tmp_path, "restarted", f"{{at: 1.3 s, component: int, kind: {kind}}}", on_failure="restart"
    )
    assert result.returncode == 0, result.stderr
    assert "restarting from step 1000 (t = 1 s; restart 1 of at most 3)" in result.stderr
    table = pandas.read_parquet(record / "signals.parquet")
    assert table.equals(undisturbed)  # bit for bit, every row once
    events = _events(record)
    fault = next(i for i, e in enumerate(events) if e["event"] == "fault")
    assert events[fault]["component"] == "int" and 1000 <= events[fault]["step"] <= 1301
    assert events[fault + 1].pop("wall_s") > 0
    assert events[fault + 1] == {"event": "restart", "step": 1000, "time": 1.0, "component": "int", "restart": 1}
    assert "run restarted completed after 1 restart: 2000 steps of 2000" in result.stderr
    assert [e["step"] for e in events if e["event"] == "checkpoint"] == [0, 500, 1000, 1500]
    assert events[-1]["status"] == "completed"
    assert sorted(p.name for p in (record / "logs").iterdir()) == ["int.0.log", "int.1.log", "src.0.log", "src.1.log"]


def test_restarts_end_at_run_max_restarts(write_config, tmp_path):
    faults = ", ".join(f"{{at: {t} s, component: int, kind: crash}}" for t in (0.3, 0.6, 0.9))
    result, record = _faulted(write_config, tmp_path, "doomed", faults, on_failure="restart", max_restarts=2)
    assert result.returncode == 1
    assert "(after 2 restarts: run.max_restarts)" in result.stderr, result.stderr
    events = _events(record)
    assert [e["step"] for e in events if e["event"] == "restart"] == [0, 500]
    assert events[-1]["status"] == "failed"


def test_a_nan_is_not_restarted(write_config, tmp_path):
    """A component that reports a fault has judged its own numbers: a restart would repeat them."""
    result, record = _faulted(
        write_config, tmp_path, "nan", "{at: 1.3 s, component: int, kind: nan}", on_failure="restart"
    )
    assert result.returncode == 1 and "non-finite value in output 'x' at step 1300" in result.stderr
    assert not any(e["event"] == "restart" for e in _events(record))


# ------------------------------------------------------------------ in a process group

GROUPED = FAULTED.replace("{{value: 2.0}}}}", "{{value: 2.0}}, process: loop}}").replace(
    "on_failure: {on_failure}}}", "on_failure: {on_failure}, process: loop}}"
)


@pytest.mark.parametrize(
    "kind, message",
    [
        ("crash", "component 'int' (test.integrator), in process group 'loop' with src, died at step"),
        ("hang", "component 'int' did not answer step 1300 within 5 s"),
    ],
)
def test_a_fault_in_a_process_group_names_its_component_and_a_restart_ends_as_if_nothing_happened(
    write_config, tmp_path, undisturbed, kind, message
):
    """src and int share a process (src first: the process's first member is not the one named by
    chance); int fails at 1.3 s. Without a restart the run ends naming int; with one, the group is
    formed again from the checkpoint at 1 s and the numbers are those of the run undisturbed, ungrouped."""
    fault = f"{{at: 1.3 s, component: int, kind: {kind}}}"
    for on_failure in ("stop", "restart"):
        name = f"grouped_{on_failure}"
        config = write_config(
            GROUPED.format(name=name, faults=fault, on_failure=on_failure, max_restarts=3, step_timeout=FAULT_TIMEOUT),
            f"{name}.yaml",
        )
        result = orchestrator("run", config, "--record", tmp_path / name, timeout=120)
        assert not component_processes(f"{name}-")
        logs = sorted(p.name for p in (tmp_path / name / "logs").glob("*.log"))
        assert "injecting a fault" in (tmp_path / name / "logs" / "group.loop.0.log").read_text()
        table = pandas.read_parquet(tmp_path / name / "signals.parquet")
        if on_failure == "stop":
            assert result.returncode == 1 and f"error: {message}" in result.stderr, result.stderr
            assert logs == ["group.loop.0.log"]
            assert 1000 <= len(table) <= 1301 and table.equals(undisturbed.iloc[: len(table)])
        else:
            assert result.returncode == 0, result.stderr
            assert f"warning: {message}" in result.stderr and "restarting from step 1000" in result.stderr
            assert logs == ["group.loop.0.log", "group.loop.1.log"]
            restart = next(e for e in _events(tmp_path / name) if e["event"] == "restart")
            assert restart["component"] == "int" and restart["step"] == 1000
            assert table.equals(undisturbed)


# ------------------------------------------------------------------ the paper's demo, disturbed

DEMO = "configs/humanoid_tracking.yaml"


def _demo(record, *overrides):
    result = orchestrator("run", DEMO, "--record", record, "--set", "run.duration=10 s", *overrides, timeout=300)
    assert result.returncode == 0, result.stderr
    assert not component_processes("humanoid_tracking-")
    return pandas.read_parquet(record / "signals.parquet")


@pytest.fixture(scope="module")
def demo_undisturbed(tmp_path_factory):
    return _demo(tmp_path_factory.mktemp("demo") / "rec")


def test_a_same_type_swap_of_the_demo_controller_at_9_s_changes_nothing(tmp_path, demo_undisturbed):
    """At 9 s the arm is far from where the trajectory was anchored: a restore that re-ran
    initialize's anchoring would fail its reach check or move the path. It must not run it."""
    swapped = _demo(tmp_path / "rec", "--set", "events=[{at: 9 s, swap: controller}]")
    assert swapped.equals(demo_undisturbed)
    swap = next(e for e in _events(tmp_path / "rec") if e["event"] == "swap")
    assert swap["step"] == 9000 and swap["state_handed_over"] is True


GROUPED_DEMO = ("--set", "components.dynamics.process=loop", "--set", "components.controller.process=loop")


@pytest.mark.parametrize("grouping", [(), GROUPED_DEMO], ids=["separate", "grouped"])
def test_a_sigkill_of_the_demo_dynamics_restarts_and_ends_bit_identical(tmp_path, demo_undisturbed, grouping):
    restarted = _demo(
        tmp_path / "rec",
        "--set",
        "components.dynamics.on_failure=restart",
        *grouping,
        "--set",
        "run.checkpoint_every=2 s",
        "--set",
        "faults=[{at: 7.5 s, component: dynamics, kind: crash}]",
    )
    assert restarted.equals(demo_undisturbed)
    events = _events(tmp_path / "rec")
    restart = next(e for e in events if e["event"] == "restart")
    assert restart["step"] == 6000 and restart["component"] == "dynamics"
