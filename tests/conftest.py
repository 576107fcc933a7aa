"""Shared helpers: run the real `orchestrator` CLI in a subprocess and find leftover processes."""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def component_processes(run_tag: str = "") -> list[str]:
    """Command lines of live component processes (optionally only those of one run)."""
    out = subprocess.run(["ps", "-ww", "-eo", "pid=,args="], capture_output=True, text=True).stdout
    return [line for line in out.splitlines() if "components.runner" in line and run_tag in line]


def start_run(config, record, **popen) -> subprocess.Popen:
    """`orchestrator run CONFIG --record DIR` in the background (text pipes for its output)."""
    return subprocess.Popen([sys.executable, "-m", "orchestrator.cli", "run", str(config), "--record", str(record)],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **popen)


def wait_for_components(run_tag: str, count: int, timeout: float = 60.0) -> list[str]:
    """Wait until ``count`` component processes of a run are up; return their command lines."""
    deadline = time.monotonic() + timeout
    while len(found := component_processes(run_tag)) < count and time.monotonic() < deadline:
        time.sleep(0.2)
    return found


def signal_files(record: Path) -> dict[str, bytes]:
    """The bytes of each part file of a recording's signals.parquet (a dataset directory)."""
    return {part.name: part.read_bytes() for part in sorted((Path(record) / "signals.parquet").iterdir())}


def orchestrator(*args, timeout=300, cwd=None, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "orchestrator.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout, cwd=cwd or ROOT, **kw)


@pytest.fixture
def write_config(tmp_path):
    """Write a YAML config text to a file in tmp_path and return its path."""
    def write(text: str, name: str = "config.yaml") -> Path:
        path = tmp_path / name
        path.write_text(text)
        return path
    return write


@pytest.fixture(autouse=True)
def _isolated_runtime_dir(tmp_path, monkeypatch):
    """Each test registers its runs in its own runtime dir (for `ps`/`stop`)."""
    monkeypatch.setenv("ZENORBIT_RUNTIME_DIR", str(tmp_path / "runtime"))


_exit_status = {}


def pytest_sessionfinish(session, exitstatus):
    _exit_status["code"] = int(exitstatus)


def pytest_unconfigure(config):
    """pythonfmu 0.7's binary, loaded into this process by the FMU tests, can corrupt the heap in
    its static destructors at exit once another C++ library (DART) bound to it (abort, exit 134,
    after every test passed). End the process without running them."""
    import os
    import sys

    held = getattr(sys.modules.get("components.fmi.exported"), "_HELD_BINARIES", None)
    if held and "code" in _exit_status:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_exit_status["code"])
