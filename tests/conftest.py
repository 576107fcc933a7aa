"""Shared helpers: run the real `orchestrator` CLI in a subprocess and find leftover processes."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def component_processes(run_tag: str = "") -> list[str]:
    """Command lines of live component processes (optionally only those of one run). Only this
    test's: a test runs its runs with its own ZENORBIT_RUNTIME_DIR, which their processes inherit,
    so another test session on the machine running the same config is not counted."""
    out = subprocess.run(["ps", "-ww", "-eo", "pid=,args="], capture_output=True, text=True).stdout
    found = [line for line in out.splitlines() if "components.runner" in line and run_tag in line]
    runtime = os.environ.get("ZENORBIT_RUNTIME_DIR")
    if runtime is None:
        return found
    mine = f"ZENORBIT_RUNTIME_DIR={runtime}".encode()

    def ours(line: str) -> bool:
        try:
            return mine in Path(f"/proc/{line.split()[0]}/environ").read_bytes().split(b"\0")
        except OSError:  # gone since ps listed it (or not ours to read): not a leftover of this test
            return False

    return [line for line in found if ours(line)]


def start_run(config, record, **popen) -> subprocess.Popen:
    """`orchestrator run CONFIG --record DIR` in the background (text pipes for its output)."""
    return subprocess.Popen(
        [sys.executable, "-m", "orchestrator.cli", "run", str(config), "--record", str(record)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **popen,
    )


def wait_for_components(run_tag: str, count: int, timeout: float = 60.0) -> list[str]:
    """Wait until ``count`` component processes of a run are up; return their command lines."""
    deadline = time.monotonic() + timeout
    while len(found := component_processes(run_tag)) < count and time.monotonic() < deadline:
        time.sleep(0.2)
    return found


def wait_until(condition, what: str, timeout: float = 120.0, run: subprocess.Popen | None = None):
    """Poll ``condition()`` until it returns something true, and return that. A test waits on an
    event (a line in a file, a row count, a process state) rather than sleeping for a guess of
    how long it takes: ``timeout`` is only there to end a test that would hang, and is generous
    (a machine with every core busy is slow, not broken). ``run``: a run that must not end first."""
    deadline = time.monotonic() + timeout
    while True:
        found = condition()
        if found:
            return found
        if run is not None and run.poll() is not None:
            raise AssertionError(f"the run ended (exit {run.returncode}) before {what}")
        if time.monotonic() > deadline:
            raise AssertionError(f"no {what} within {timeout:g} s")
        time.sleep(0.1)


def wait_for_step(name: str, step: int, timeout: float = 120.0, run: subprocess.Popen | None = None) -> int:
    """Wait until the live run named ``name`` has recorded row ``step`` (the run's own answer to
    a status query, as `orchestrator ps` asks it); return the row it had reached."""
    from components import bus, queries
    from orchestrator.run import runs

    entry = wait_until(lambda: runs.find(name), f"run {name} registered", timeout, run)[0]
    session = bus.open_session(connect=[entry["endpoint"]], secret=entry["secret"], settings=entry.get("settings"))

    def reached():
        for reply in session.get(bus.control_key(entry["run_id"]), payload=queries.Status().encode(), timeout=10.0):
            if reply.ok is not None:
                status = queries.decode_control_answer(reply.ok.payload.to_bytes())
                return status.step if status.step >= step else None
        return None

    try:
        return wait_until(reached, f"step {step} of run {name}", timeout, run)
    finally:
        session.close()


def part_files(parquet: Path) -> list[Path]:
    """The part files of a recording's signals.parquet (each written under a hidden name, then
    renamed into place; the last may be the unfinished chunk, replaced as it grows)."""
    return (
        sorted(p for p in Path(parquet).glob("*.parquet") if not p.name.startswith("."))
        if Path(parquet).is_dir()
        else []
    )


def recorded_rows(parquet: Path) -> int:
    """The rows on disk in a recording's signals.parquet now (0 while a part is being replaced)."""
    import pyarrow.parquet as pq

    try:
        return sum(pq.ParquetFile(path).metadata.num_rows for path in part_files(parquet))
    except (OSError, ValueError):
        return 0


def signal_files(record: Path) -> dict[str, bytes]:
    """The bytes of each part file of a recording's signals.parquet (a dataset directory)."""
    return {part.name: part.read_bytes() for part in sorted((Path(record) / "signals.parquet").iterdir())}


def orchestrator(*args, timeout=300, cwd=None, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "orchestrator.cli", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=cwd or ROOT,
        **kw,
    )


def needs(extra: str, feature: str = "this test"):
    """Skip a test whose feature needs pyproject's ``extra`` when it is not installed, saying which
    and how to install it ([test] brings them all, so CI runs these tests)."""
    from components.extras import missing

    problem = missing(extra, feature)
    return pytest.mark.skipif(problem is not None, reason=str(problem))


#: the shipped configs that need an extra beyond the default install (tests/unit/test_extras.py checks it)
CONFIG_EXTRAS = {"panda_on_bus.yaml": "robots", "capture_vision.yaml": "vision", "reaction_wheel_fmu.yaml": "fmi"}
SHIPPED = sorted((ROOT / "configs").glob("*.yaml"))


def config_missing(path: Path) -> str | None:
    """Why a shipped config cannot run here (the extra it needs is not installed), or None."""
    from components.extras import missing

    extra = CONFIG_EXTRAS.get(path.name)
    return missing(extra, path.name) if extra else None


def shipped_configs() -> list:
    """configs/*.yaml as test parameters, each skipped when its extra is not installed."""
    return [
        pytest.param(path, id=path.name, marks=needs(CONFIG_EXTRAS[path.name], path.name))
        if path.name in CONFIG_EXTRAS
        else pytest.param(path, id=path.name)
        for path in SHIPPED
    ]


@pytest.fixture
def write_config(tmp_path):
    """Write a YAML config text to a file in tmp_path and return its path."""

    def write(text: str, name: str = "config.yaml") -> Path:
        path = tmp_path / name
        path.write_text(text)
        return path

    return write


@pytest.fixture(scope="session", autouse=True)
def _session_runtime_dir(tmp_path_factory):
    """The runs of module fixtures (started before any test's own dir is set) register in this
    session's own runtime dir: component_processes then counts only this session's processes, not
    those of another xdist worker running the same config at the same time."""
    patch = pytest.MonkeyPatch()
    patch.setenv("ZENORBIT_RUNTIME_DIR", str(tmp_path_factory.mktemp("runtime")))
    yield
    patch.undo()


@pytest.fixture(autouse=True)
def _isolated_runtime_dir(tmp_path, monkeypatch):
    """Each test registers its runs in its own runtime dir (for `ps`/`stop`)."""
    monkeypatch.setenv("ZENORBIT_RUNTIME_DIR", str(tmp_path / "runtime"))


# what the suite starts and must not leave behind: component runners, orchestrators, viewers
LEFTOVER_MARKS = ("components.runner", "orchestrator", "components.viewer.observer", "rerun")


def suite_processes(root: str) -> list[str]:
    """'pid args' of live processes this test session started: their environment carries a
    ZENORBIT_RUNTIME_DIR under the session's base temporary directory ``root`` (every test sets
    one there, and the processes of its runs inherit it: those of another session, or of a
    user's runs, do not), and their command line is one of LEFTOVER_MARKS."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            environ = (entry / "environ").read_bytes().split(b"\0")
            args = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace").strip()
        except OSError:  # gone, or not ours to read
            continue
        runtime = next(
            (
                v[len(b"ZENORBIT_RUNTIME_DIR=") :].decode(errors="replace")
                for v in environ
                if v.startswith(b"ZENORBIT_RUNTIME_DIR=")
            ),
            None,
        )
        if runtime and runtime.startswith(root) and args and any(mark in args for mark in LEFTOVER_MARKS):
            found.append(f"{entry.name} {args}")
    return found


def pytest_sessionfinish(session, exitstatus):
    """The suite leaves no process behind: a component runner, orchestrator or viewer that a test
    started and that is still alive (after 15 s of grace for those ending now) fails the run; it
    is listed, then killed."""
    factory = getattr(session.config, "_tmp_path_factory", None)
    if factory is not None and not hasattr(session.config, "workerinput"):
        root = str(factory.getbasetemp())
        deadline = time.monotonic() + 15.0
        while (left := suite_processes(root)) and time.monotonic() < deadline:
            time.sleep(0.2)
        if left:
            print(
                "\nerror: the test session left these processes running (failing the run):\n  " + "\n  ".join(left),
                file=sys.stderr,
            )
            for line in left:
                try:
                    os.kill(int(line.split()[0]), 9)
                except OSError:
                    pass
            session.exitstatus = 1
