"""Component processes: start them, tell how they died, make sure none is left behind."""
from __future__ import annotations

import signal
import socket
import subprocess
import sys
from pathlib import Path


def child_setup() -> None:
    """In a component process: leave Ctrl-C to the orchestrator (which stops everyone in order),
    and die with the orchestrator even if it is SIGKILLed (Linux PR_SET_PDEATHSIG)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        import ctypes
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def resolve_endpoints(listen: list[str]) -> tuple[list[str], str]:
    """Fill port 0 with a free port; return (listen endpoints, the one local components connect to)."""
    resolved = []
    for endpoint in listen:
        proto, _, address = endpoint.partition("/")
        host, _, port = address.rpartition(":")
        if port == "0":
            port = str(free_port())
        resolved.append(f"{proto}/{host}:{port}")
    proto, _, address = resolved[0].partition("/")
    host, _, port = address.rpartition(":")
    local_host = "127.0.0.1" if host in ("0.0.0.0", "[::]") else host
    return resolved, f"{proto}/{local_host}:{port}"


def runner_arguments(endpoint: str, run_id: str, name: str, generation: int) -> list[str]:
    return ["--connect", endpoint, "--run-id", run_id, "--name", name, "--generation", str(generation)]


def start_component(arguments: list[str], log_path: Path) -> subprocess.Popen:
    """``python -m components.runner ARGS`` with stdout and stderr in ``log_path``."""
    with open(log_path, "wb") as log:
        return subprocess.Popen([sys.executable, "-m", "components.runner", *arguments],
                                stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                preexec_fn=child_setup)


def reap(process: subprocess.Popen | None, timeout: float) -> None:
    """Wait for a process that was asked to exit; kill it after ``timeout`` seconds."""
    if process is None:
        return
    try:
        process.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


def last_words(log_path: Path | None) -> str:
    """``; last output: <line>`` from a component's log, or ``""``."""
    if log_path and log_path.exists():
        lines = [line for line in log_path.read_text(errors="replace").splitlines() if line.strip()]
        if lines:
            return f"; last output: {lines[-1].strip()}"
    return ""
