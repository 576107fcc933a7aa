"""The performance table of the README: every figure taken in one run on this machine.

    python benchmarks/bench_performance.py               # full table (~3 min on 2 cores)
    python benchmarks/bench_performance.py --quick       # shorter runs, same rows
    python benchmarks/bench_performance.py --no-mosaik   # without the mosaik 3 comparison

Rows:
- the paper's demo (configs/humanoid_tracking.yaml) over the bus: real-time factor;
- the same components stepped one after another in this process (orchestrator/run/inprocess.py), no bus;
- the demo over the bus again, its dynamics sharing the CPUs (``dedicated_cpu`` off);
- 3 no-op components in a loop (a -> b -> c -> a, Jacobi) next to the raw Zenoh pub/sub round trip;
- the no-op chain a -> b -> c against mosaik 3 (one process per simulator; mosaik is installed in
  a virtual environment of its own, ``--mosaik-venv``, made on first use);
- steps/s for 1, 2, 4 and 8 no-op components in a loop, and us/step against the payload size.
Steps/s count the stepping loop only (start-up excluded); figures are medians of ``--repeat`` runs.
"""

from __future__ import annotations

import argparse
import io
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))


def machine() -> str:
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    from importlib.metadata import version

    return (
        f"{model}, {os.cpu_count()} cores, Python {platform.python_version()}, eclipse-zenoh {version('eclipse-zenoh')}"
    )


def run_config(text: str, name: str = "bench.yaml") -> float:
    """Steps/s of the stepping loop of a config given as YAML text."""
    from orchestrator.config.load import load
    from orchestrator.run.engine import Run

    path = Path(tempfile.mkdtemp()) / name
    path.write_text(text)
    config = load(path)
    run = Run(config, out=io.StringIO())
    if run.execute() != 0:
        raise RuntimeError(f"benchmark run failed: {path}")
    return config.steps / run.loop_s


def noop_loop(count: int, steps: int, size: int = 1, closed: bool = True) -> str:
    names = [f"n{i}" for i in range(count)]
    components = "".join(f"  {n}: {{type: test.noop, parameters: {{size: {size}}}}}\n" for n in names)
    pairs = [(names[(i + 1) % count], names[i]) for i in range(count if closed else count - 1)]
    connections = ", ".join(f"{d}.u: {s}.y" for d, s in pairs)
    return (
        f"run: {{name: bench, epoch: 2022-09-18T12:00:00Z, duration: {steps} ms, step: 1 ms, algorithm: jacobi}}\n"
        f"components:\n{components}connections: {{{connections}}}\n"
    )


def demo(seconds: float, repeat: int, more: list[str] = ()) -> tuple[float, float]:
    """(real-time factor over the bus, real-time factor of the in-process loop); ``more``: extra
    overrides of the bus runs."""
    from orchestrator.config.load import load
    from orchestrator.run.engine import Run
    from orchestrator.run.inprocess import run_in_process

    config_path = ROOT / "configs" / "humanoid_tracking.yaml"
    overrides = [f"run.duration={seconds} s"]
    bus = []
    for _ in range(repeat):
        run = Run(load(config_path, [*overrides, *more]), out=io.StringIO())
        if run.execute() != 0:
            raise RuntimeError("the demo failed over the bus")
        bus.append(seconds / run.loop_s)
    local = []
    for _ in range(repeat):
        config = load(config_path, overrides)
        timing: dict = {}
        run_in_process(config, timing=timing)
        local.append(seconds / timing["loop_s"])
    return float(np.median(bus)), float(np.median(local))


def mosaik_rate(venv: Path, steps: int) -> float | None:
    python = venv / "bin" / "python"
    if not python.exists():
        print(f"(making the mosaik 3 environment in {venv})", file=sys.stderr)
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        subprocess.run([str(python), "-m", "pip", "install", "-q", "mosaik>=3,<4"], check=True)
    result = subprocess.run(
        [str(python), str(ROOT / "benchmarks" / "mosaik_chain.py"), "--steps", str(steps)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    if result.returncode != 0:
        print(f"mosaik run failed:\n{result.stderr[-2000:]}", file=sys.stderr)
        return None
    return float(result.stdout.strip().splitlines()[-1])


def median_rate(text: str, repeat: int) -> float:
    return float(np.median([run_config(text) for _ in range(repeat)]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs (rough figures)")
    parser.add_argument("--repeat", type=int, default=3, help="runs per figure (median)")
    parser.add_argument("--no-mosaik", action="store_true")
    parser.add_argument("--mosaik-venv", type=Path, default=ROOT / "benchmarks" / ".venv-mosaik")
    args = parser.parse_args()
    steps = 2000 if args.quick else 10000
    demo_s = 3.0 if args.quick else 15.0
    repeat = 1 if args.quick else args.repeat

    from bench_lockstep import round_trip

    print(f"machine: {machine()}")
    rtt = float(np.median(round_trip(steps)))
    print(f"zenoh pub/sub round trip (2 processes, 64 B): {rtt * 1e6:.0f} us median")

    bus_rtf, local_rtf = demo(demo_s, repeat)
    shared_rtf = demo(demo_s, repeat, ["components.dynamics.dedicated_cpu=false"])[0]
    print("\n| figure | value |\n|---|---|")
    print(f"| paper's demo over the bus ({demo_s:g} s, 1 kHz, rk4, Jacobi) | real-time factor {bus_rtf:.2f} |")
    print(f"| same components in one process, one after another | real-time factor {local_rtf:.2f} |")
    print(f"| bus / one process | {bus_rtf / local_rtf:.2f}x |")
    print(
        f"| the demo over the bus without dedicated_cpu | real-time factor {shared_rtf:.2f} "
        f"({shared_rtf / local_rtf:.2f}x one process) |"
    )

    loop3 = median_rate(noop_loop(3, steps), repeat)
    print(
        f"| 3 no-op components in a loop | {loop3:.0f} steps/s = {1e6 / loop3:.0f} us/step "
        f"= {1 / loop3 / rtt:.2f}x the round trip |"
    )

    chain3 = median_rate(noop_loop(3, steps, closed=False), repeat)
    if not args.no_mosaik:
        rate = mosaik_rate(args.mosaik_venv, min(steps, 5000))
        if rate:
            print(
                f"| 3 no-op chain a->b->c: Zenorbit / mosaik 3 | {chain3:.0f} / {rate:.0f} steps/s "
                f"= {chain3 / rate:.1f}x |"
            )
    else:
        print(f"| 3 no-op chain a->b->c | {chain3:.0f} steps/s |")

    for count in (1, 2, 4, 8):
        rate = median_rate(noop_loop(count, steps), repeat)
        print(
            f"| {count} no-op component{'s' if count > 1 else ''} in a loop | {rate:.0f} steps/s "
            f"({1e6 / rate:.0f} us/step) |"
        )
    for size in (1, 10, 100, 1000, 10000):
        rate = median_rate(noop_loop(3, steps // 2, size=size), repeat)
        print(f"| 3 in a loop, {size} float64 per output | {1e6 / rate:.0f} us/step |")


if __name__ == "__main__":
    main()
