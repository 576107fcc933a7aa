"""Component processes (one component's, or a process group's): start them, tell how they died,
make sure none is left behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from dataclasses import dataclass
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


def runner_arguments(endpoint: str, run_id: str, members: list[tuple[str, int]]) -> list[str]:
    """The runner's arguments for one component, or a process group's (name, generation) each."""
    if len(members) == 1:
        ((name, generation),) = members
        return ["--connect", endpoint, "--run-id", run_id, "--name", name, "--generation", str(generation)]
    return ["--connect", endpoint, "--run-id", run_id, *(f"--member={n}:{g}" for n, g in members)]


@dataclass(frozen=True)
class Placement:
    """Which CPUs the processes of a run use: ``dedicated`` {component: cpu} for the stepping
    threads of the components that asked for a CPU of their own (with ``dedicated_cpu: process``
    their whole processes); ``shared`` for every other thread of the run (orchestrator, other
    components, Zenoh's threads, the viewer); ``unplaced``: components that asked but found no
    CPU to spare."""

    dedicated: dict[str, int]
    shared: frozenset[int]
    unplaced: tuple[str, ...]


def place(asking: list[list[str]], available: set[int]) -> Placement:
    """Give each process of ``asking`` (in order; each the names of the components it runs: one,
    or a process group's) a CPU of its own, from the highest-numbered one down, keeping at least
    one CPU for the rest of the run.

    Why: on a loaded machine each wake-up of another thread on a component's CPU costs it far more
    than the wake-up itself (caches and branch predictors go cold); measured on 2 cores, the
    demo's dynamics computes a step in 330 us on a CPU of its own against 400 us shared. Its own
    bus threads follow it there with ``dedicated_cpu: process`` (members.Crew): a hand-over
    between its threads then wakes no other CPU, which pays when it idles much of each step
    (benchmarks/bench_pace.py: the demo with a 100 us dynamics 3.0x real time against 2.6x)."""
    cpus = sorted(available, reverse=True)
    spare = max(len(cpus) - 1, 0)
    dedicated = {name: cpu for names, cpu in zip(asking[:spare], cpus) for name in names}
    return Placement(
        dedicated,
        frozenset(available) - frozenset(dedicated.values()),
        tuple(name for names in asking[spare:] for name in names),
    )


def keep_to(cpus: frozenset[int], pid: int = 0) -> None:
    """Restrict a thread (``pid`` 0: the calling one) to ``cpus``; threads it starts inherit that."""
    os.sched_setaffinity(pid, cpus)


def start_component(arguments: list[str], log_path: Path, cpus: frozenset[int], env: dict) -> subprocess.Popen:
    """``python -m components.runner ARGS`` on ``cpus`` in ``env``, with stdout and stderr in ``log_path``."""
    with open(log_path, "wb") as log:
        process = subprocess.Popen(
            [sys.executable, "-m", "components.runner", *arguments],
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=subprocess.STDOUT,
            preexec_fn=child_setup,
            env=env,
        )
    keep_to(cpus, process.pid)  # Popen returns after exec: the child has one thread yet, all inherit
    return process


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
