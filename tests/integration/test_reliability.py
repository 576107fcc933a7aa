"""Nothing lost, nothing crashes (real processes, real Zenoh on loopback): a stranger publishing
garbage on a run's keys does not end it, and a kill -9 of the orchestrator leaves a recording
that reads with pandas and no process behind."""
import json
import signal
import time

import numpy as np
import pandas
import pytest

from components import bus
from orchestrator import runs
from tests.conftest import component_processes, start_run, wait_for_components

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


def _registered(name: str, timeout: float = 30.0) -> dict:
    deadline = time.monotonic() + timeout
    while not (found := runs.find(name)) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert found, f"run {name} never registered"
    return found[0]


def test_a_stranger_publishing_garbage_on_the_run_keys_does_not_end_it(write_config, tmp_path):
    import zenoh

    config, record = write_config(PACED.format(name="stranger", duration=3)), tmp_path / "rec"
    run = start_run(config, record)
    try:
        assert len(wait_for_components("stranger-", 2)) == 2
        entry = _registered("stranger")
        rid = entry["run_id"]
        good = np.zeros((1, 2))   # integrator outputs: x, u_time
        garbage = {
            bus.batch_key(rid, "int"): [b"\x00\x01\x02", b"B" + bytes(30), bus.encode_batch(7, np.array([1]), good[:, :2], good),
                                         bus.encode_batch(0, np.array([1]), good[:, :2], np.zeros((1, 5)))],
            bus.batch_key(rid, "ghost"): [bus.encode_batch(0, np.array([1]), good[:, :2], good)],
            bus.component_key(rid, "int", 0, "out"): [b"R\xff\xff\xff\xff{", b"E" + bytes(8),
                                                      bus.encode_message(bus.FAULT, {"op": "step"})],
            bus.component_key(rid, "int", 99, "out"): [bus.encode_message(bus.FAULT, {"op": "step", "k": 1, "error": "x"})],
            bus.run_key(rid, "c", "int", "x", "out"): [b"junk"],
            bus.output_key(rid, "int", "src"): [b"\x00\x01\x02", bus.encode_output(0, 5, np.zeros(0)), b"Qxx"],
            bus.output_key(rid, "int", "ghost"): [bus.encode_output(0, 5, np.zeros(1))],
            bus.command_key(rid, "int", 0): [b"\x00\x01\x02", bus.encode_message(bus.CONTROL, {"op": "explode"}),
                                            b"C\x05\x00\x00\x00nope!"],
        }
        with zenoh.open(bus.session_config(connect=[entry["endpoint"]], mesh=True)) as session:   # reaches every peer
            time.sleep(0.5)
            for _ in range(3):
                for key, payloads in garbage.items():
                    for payload in payloads:
                        session.put(key, payload)
                time.sleep(0.2)
        _, err = run.communicate(timeout=60)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 0, err
    table = pandas.read_parquet(record / "signals.parquet")
    assert table["step"].tolist() == list(range(3001))                           # every row
    assert table["int.x"].iloc[-1] == pytest.approx(0.5 * 2.0 * 3.0, rel=1e-9)   # x = gain u t: untouched
    events = _events(record)
    dropped = [e["message"] for e in events if e["event"] == "warning" and "dropped a message" in e["message"]]
    assert any("r/int" in m for m in dropped) and any("r/ghost" in m for m in dropped), dropped
    assert any("c/int/99/out" in m for m in dropped) and any("c/int/0/out" in m for m in dropped), dropped
    assert events[-1]["event"] == "end" and events[-1]["status"] == "completed"
    component_log = (record / "logs" / "int.0.log").read_text()
    assert "dropped a message" in component_log and "/o/ghost" in component_log and "/c/0" in component_log
    assert not component_processes("stranger-")


def test_kill_9_of_the_orchestrator_leaves_a_readable_recording_and_no_process(write_config, tmp_path):
    config, record = write_config(PACED.format(name="killed", duration=60)), tmp_path / "rec"
    run = start_run(config, record)
    try:
        assert len(wait_for_components("killed-", 2)) == 2
        time.sleep(3.5)                        # > 3 chunks of 1000 rows at real time
        run.send_signal(signal.SIGKILL)
        run.communicate(timeout=30)
        deadline = time.monotonic() + 30
        while component_processes("killed-") and time.monotonic() < deadline:
            time.sleep(0.2)
    finally:
        if run.poll() is None:
            run.kill()
    assert not component_processes("killed-"), "components outlived their orchestrator"
    table = pandas.read_parquet(record / "signals.parquet")
    steps = table["step"].to_numpy()
    assert len(steps) >= 2000 and len(steps) % 1000 == 0 and np.array_equal(steps, np.arange(len(steps)))
    assert np.allclose(table["int.x"], 0.5 * 2.0 * steps * 1e-3, rtol=1e-9, atol=1e-12)
    events = _events(record)
    assert events[0]["event"] == "start" and not any(e["event"] == "end" for e in events), events[-1]
