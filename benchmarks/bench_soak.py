"""Long runs stay flat (issue 34): the capture scenario for an hour of simulated time, recorded,
and several runs at once.

    python benchmarks/bench_soak.py soak [--duration 3600] [--every 60]
    python benchmarks/bench_soak.py parallel [--runs 4] [--duration 60]

- soak: one ``orchestrator run configs/capture_tumbling_target.yaml --record``; every ``--every``
  seconds of wall time the resident memory (RSS) of the orchestrator and of each component
  process; at the end each process's growth from its first minute's sample to its last, the rows
  recorded against the steps, and the warnings in events.jsonl.
- parallel: ``--runs`` recorded runs started together; each one's exit code and rows.

Whole runs as a user starts them; psutil reads the memory. The machine is printed first.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "capture_tumbling_target.yaml"


def command(record: Path, duration: float) -> list[str]:
    return [
        sys.executable,
        "-m",
        "orchestrator.cli",
        "run",
        str(CONFIG),
        "--record",
        str(record),
        "--set",
        f"run.duration={duration:g} s",
    ]


def rows_of(record: Path) -> int:
    import pyarrow.parquet as pq

    return pq.read_table(record / "signals.parquet", columns=["step"]).num_rows


def warnings_of(record: Path) -> list[str]:
    lines = (record / "events.jsonl").read_text().splitlines()
    return [json.loads(line).get("message", "") for line in lines if '"event": "warning"' in line]


def processes(root: psutil.Process) -> dict[str, psutil.Process]:
    """The run's processes by role: the orchestrator and its components (their --name)."""
    found = {"orchestrator": root}
    for child in root.children(recursive=True):
        try:
            args = child.cmdline()
        except psutil.Error:
            continue
        if "components.runner" in " ".join(args) and "--name" in args:
            found[args[args.index("--name") + 1]] = child
    return found


def soak(duration: float, every: float) -> int:
    with tempfile.TemporaryDirectory() as tmp:
        record = Path(tmp) / "soak"
        started = time.monotonic()
        run = subprocess.Popen(
            command(record, duration), cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
        )
        root = psutil.Process(run.pid)
        samples: dict[str, list[tuple[float, int]]] = {}
        while run.poll() is None:
            time.sleep(every)
            for role, process in processes(root).items():
                try:
                    rss = process.memory_info().rss
                except psutil.Error:
                    continue
                if rss:  # 0: the process has ended (a zombie)
                    samples.setdefault(role, []).append((time.monotonic() - started, rss))
        err = run.stderr.read()
        wall = time.monotonic() - started
        print(
            f"soak: exit {run.returncode}, {duration:g} s simulated in {wall:.0f} s of wall; {err.strip().splitlines()[-1:]}"
        )
        steps = round(duration / 0.01)
        print(f"rows {rows_of(record)} of {steps + 1}; warnings in events.jsonl: {warnings_of(record) or 'none'}")
        print(f"{'process':<14}{'RSS at ~1 min (MB)':>20}{'RSS at the end (MB)':>22}{'growth':>9}")
        worst = 0.0
        for role, series in samples.items():
            first = next((rss for t, rss in series if t >= 60.0), series[0][1])
            last = series[-1][1]
            growth = last / first - 1.0
            worst = max(worst, growth)
            print(f"{role:<14}{first / 1e6:>20.1f}{last / 1e6:>22.1f}{growth * 100:>8.1f}%")
        print(f"largest growth {worst * 100:.1f}%")
        return run.returncode


def parallel(runs: int, duration: float) -> int:
    with tempfile.TemporaryDirectory() as tmp:
        records = [Path(tmp) / f"run{i}" for i in range(runs)]
        started = time.monotonic()
        procs = [
            subprocess.Popen(
                command(r, duration), cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
            )
            for r in records
        ]
        codes = [p.wait() for p in procs]
        wall = time.monotonic() - started
        steps = round(duration / 0.01)
        for i, (code, record) in enumerate(zip(codes, records)):
            print(f"run {i}: exit {code}, rows {rows_of(record)} of {steps + 1}, warnings {len(warnings_of(record))}")
        print(f"{runs} runs of {duration:g} s at once: {wall:.0f} s of wall")
        return max(codes)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="what", required=True)
    one = sub.add_parser("soak")
    one.add_argument("--duration", type=float, default=3600.0, help="simulated seconds")
    one.add_argument("--every", type=float, default=60.0, help="wall seconds between memory samples")
    many = sub.add_parser("parallel")
    many.add_argument("--runs", type=int, default=4)
    many.add_argument("--duration", type=float, default=60.0, help="simulated seconds each")
    args = parser.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, {platform.platform()}")
    return soak(args.duration, args.every) if args.what == "soak" else parallel(args.runs, args.duration)


if __name__ == "__main__":
    sys.exit(main())
