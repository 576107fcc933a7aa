"""One case of a campaign: its own ``orchestrator run`` process, stopped cleanly, its metrics read."""

from __future__ import annotations

import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from orchestrator.campaigns.metrics import Metric

STOP_GRACE_S = 20.0  # a stopped case's run gets this long to stop cleanly before it is killed
MAX_EVENTS = 1000  # event names kept per case (the outcome is decided from them)


def _libc_prctl():
    try:
        import ctypes

        return ctypes.CDLL("libc.so.6", use_errno=True).prctl
    except (OSError, AttributeError):
        return None


_PRCTL = _libc_prctl()  # resolved here, not in the forked child (which must not import or load anything)


def _die_with_parent() -> None:
    """In the child: SIGTERM if the process that started it dies (a Dask worker killed outright)."""
    if _PRCTL is not None:
        _PRCTL(1, signal.SIGTERM)  # PR_SET_PDEATHSIG


def _affinity(cpus):
    def setup():
        _die_with_parent()
        if cpus:
            try:
                os.sched_setaffinity(0, cpus)
            except OSError:
                pass

    return setup


def read_events(recording: Path) -> list[dict]:
    """events.jsonl of a recording ([] when there is none; a line cut short by a kill is skipped)."""
    import json

    path = recording / "events.jsonl"
    events = []
    if path.exists():
        for line in path.read_text().splitlines():
            try:
                events.append(json.loads(line))
            except ValueError:
                continue
    return events


def metric_values(recording: Path, metrics: list[Metric]) -> dict[str, float | str]:
    """Each metric of a recording (NaN for a signal's when it has no rows)."""
    import pyarrow.parquet as pq

    if not metrics:
        return {}
    events = read_events(recording)
    columns = sorted({"time", *(c for m in metrics for c in m.columns)})
    if any(m.event is None for m in metrics):
        table = pq.read_table(recording / "signals.parquet", columns=columns)
        data = {name: table.column(name).to_numpy() for name in table.column_names}
    else:
        data = {"time": np.zeros(0)}
    t = data["time"]
    return {m.name: m.value(t, data, events) for m in metrics}


def execute_case(
    index: int,
    config_file: Path,
    record_dir: Path,
    metrics: list[Metric],
    keep: str,
    stop: threading.Event | None = None,
    cpus=None,
    stopped=None,
) -> dict:
    """Run one case as ``orchestrator run CONFIG --record DIR``; its result: status (completed,
    failed, interrupted), error, metrics (from the recording, failed or not), the names of its
    events in order, the outcome its components declare ('' for none), wall_time, host. ``stop`` set: the run is stopped
    cleanly (SIGINT), then killed after STOP_GRACE_S. The recording is removed unless ``keep``
    wants it."""
    if record_dir.exists():
        shutil.rmtree(record_dir)
    record_dir.parent.mkdir(parents=True, exist_ok=True)
    rc, interrupted, stderr, wall = _run(config_file, record_dir, stop, cpus, stopped)
    status, error = _status(rc, interrupted, stderr)
    values: dict[str, float | str] = {m.name: math.nan for m in metrics}
    events: list[str] = []
    outcome = ""
    if status != "interrupted" and record_dir.exists():
        # a failed run's recording holds its rows up to the failure: its metrics are read too
        recorded = read_events(record_dir)
        events = [e.get("event", "") for e in recorded][-MAX_EVENTS:]
        # the outcome the run's components declare (orchestrator/run/outcome.py), on its end event
        outcome = next((e["outcome"] for e in reversed(recorded) if e.get("event") == "end" and e.get("outcome")), "")
        try:
            values = metric_values(record_dir, metrics)
        except Exception as e:  # an unreadable recording: the case failed, the campaign goes on
            values = {m.name: math.nan for m in metrics}
            if status == "completed":
                status, error = "failed", f"metrics: {type(e).__name__}: {e}"
    kept = status != "interrupted" and (keep == "all" or (keep == "failed" and status == "failed"))
    if not kept and record_dir.exists():
        shutil.rmtree(record_dir, ignore_errors=True)
    return {
        "case": index,
        "status": status,
        "error": error,
        "metrics": values,
        "events": events,
        "outcome": outcome,
        "wall_time": wall,
        "host": socket.gethostname(),
        "kept": kept,
        "attempts": 1,
    }


def _run(config_file: Path, record_dir: Path, stop, cpus, stopped) -> tuple[int, bool, str, float]:
    """``orchestrator run CONFIG --record DIR`` in a process of its own, stopped when ``stop`` is set
    or ``stopped()`` says so: its exit code, whether it was stopped, its stderr, its wall time."""
    command = [sys.executable, "-m", "orchestrator.cli", "run", str(config_file), "--record", str(record_dir)]
    start = time.perf_counter()
    process = subprocess.Popen(
        command,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        start_new_session=True,
        preexec_fn=_affinity(cpus),
    )
    chunks: list[bytes] = []
    stderr = process.stderr
    assert stderr is not None, "opened with stderr=PIPE"
    reader = threading.Thread(target=lambda: chunks.extend(iter(lambda: stderr.read(4096), b"")), daemon=True)
    reader.start()
    interrupted = False
    while True:
        try:
            rc = process.wait(timeout=0.2)
            break
        except subprocess.TimeoutExpired:
            pass
        if (stop is not None and stop.is_set()) or (stopped is not None and stopped()):
            interrupted = True
            _stop(process)
    reader.join(timeout=5)
    wall = time.perf_counter() - start
    return rc, interrupted, b"".join(chunks).decode(errors="replace"), wall


def _status(rc: int, interrupted: bool, stderr: str) -> tuple[str, str]:
    """A case's status (completed, interrupted, failed) and error, from how its run ended."""
    if rc == 0 and not interrupted:
        return "completed", ""
    if interrupted or rc == 130:
        return "interrupted", "stopped (Ctrl-C)"
    lines = [ln.strip() for ln in stderr.splitlines() if ln.strip().startswith("error:")]
    error = (
        lines[0][len("error:") :].strip()
        if lines
        else (f"killed by signal {-rc}" if rc < 0 else f"exit code {rc}: {stderr.strip().splitlines()[-1:] or ''}")
    )
    return "failed", error


def _stop(process: subprocess.Popen) -> None:
    """SIGINT (the run stops cleanly and stops its components), then the whole group killed."""
    try:
        process.send_signal(signal.SIGINT)
        process.wait(timeout=STOP_GRACE_S)
    except subprocess.TimeoutExpired:
        try:
            os.killpg(process.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        process.wait()
    except ProcessLookupError:
        pass
