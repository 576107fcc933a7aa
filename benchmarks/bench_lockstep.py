"""Lockstep rate of 3 no-op components, next to the raw Zenoh pub/sub round trip on this machine.

    python benchmarks/bench_lockstep.py [--steps 5000]

The ping-pong uses the same session settings and publishers as the orchestrator (peer mode,
loopback TCP, reliable, BLOCK, express) between two processes, so the two numbers compare.
"""

from __future__ import annotations

import argparse
import io
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from anywhere, installed or not


def pong(endpoint: str) -> None:
    import zenoh

    from components import bus

    session = zenoh.open(bus.session_config(connect=[endpoint]))
    pings = session.declare_subscriber("bench/ping", zenoh.handlers.FifoChannel(64))
    out = bus.publisher(session, "bench/pong")
    token = session.liveliness().declare_token("bench/alive")
    while True:
        payload = pings.recv().payload.to_bytes()
        out.put(payload)
        if payload == b"stop":
            break
    del token
    session.close()


def round_trip(n: int) -> np.ndarray:
    """Round-trip times (s) of n 64-byte messages between this process and a second one."""
    import queue

    import zenoh

    from components import bus
    from orchestrator.hosts.run_bus import resolve_endpoints

    listen, endpoint = resolve_endpoints(["tcp/127.0.0.1:0"])
    session = zenoh.open(bus.session_config(listen=listen))
    inbox: queue.Queue = queue.Queue()
    alive: queue.Queue = queue.Queue()
    sub = session.declare_subscriber("bench/pong", lambda s: inbox.put(s.payload.to_bytes()))
    watch = session.liveliness().declare_subscriber("bench/alive", lambda s: alive.put(1))
    ping = bus.publisher(session, "bench/ping")
    child = subprocess.Popen([sys.executable, __file__, "--pong", endpoint])
    try:
        alive.get(timeout=30)
        payload = bytes(64)
        for _ in range(200):  # warm-up
            ping.put(payload)
            inbox.get(timeout=5)
        times = np.empty(n)
        for i in range(n):
            start = time.perf_counter()
            ping.put(payload)
            inbox.get(timeout=5)
            times[i] = time.perf_counter() - start
        ping.put(b"stop")
        child.wait(timeout=10)
        return times
    finally:
        if child.poll() is None:
            child.kill()
        del sub, watch
        session.close()


def lockstep(steps: int) -> float:
    """Steps per second of the orchestrator with 3 no-op components (jacobi)."""
    from orchestrator.config.load import load
    from orchestrator.run.engine import Run

    config = Path(tempfile.mkdtemp()) / "noop.yaml"
    config.write_text(
        f"run: {{name: bench, epoch: 2022-09-18T12:00:00Z, duration: {steps} ms, step: 1 ms, algorithm: jacobi}}\n"
        "components:\n  a: {type: test.noop}\n  b: {type: test.noop}\n  c: {type: test.noop}\n"
        "connections: {b.u: a.y, c.u: b.y, a.u: c.y}\n"
    )
    run = Run(load(config), out=io.StringIO())
    assert run.execute() == 0
    return steps / run.loop_s


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=5000)
    parser.add_argument("--pong")
    args = parser.parse_args()
    if args.pong:
        pong(args.pong)
        return
    rtt = round_trip(args.steps)
    rate = lockstep(args.steps)
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    )
    print(
        f"zenoh pub/sub round trip: median {np.median(rtt) * 1e6:.0f} us, p99 {np.percentile(rtt, 99) * 1e6:.0f} us "
        f"(-> at most {1 / np.median(rtt):.0f} round trips/s)"
    )
    print(f"lockstep, 3 no-op components, jacobi: {rate:.0f} steps/s ({1e6 / rate:.0f} us/step)")


if __name__ == "__main__":
    main()
