"""What recovery costs, on the paper's demo (configs/humanoid_tracking.yaml).

    python benchmarks/bench_recovery.py [--duration 8] [--repeat 3]

- swap: the wall time a same-type swap of the controller holds the run (the swap event's wall_s);
- detection: from a SIGKILL of the dynamics process, sent by this script, to the ``fault`` line
  in events.jsonl (the file is polled every millisecond);
- restart: the wall time from that detection until the run goes on again (the restart event's
  wall_s), and the wall time the whole run lost against an undisturbed one;
- checkpoints: what taking them (every second of simulated time) costs a run that never fails.

Whole runs, as a user starts them (``orchestrator run``); medians of ``--repeat`` runs, alternated.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DEMO = "configs/humanoid_tracking.yaml"


def events(record: Path) -> list[dict]:
    path = record / "events.jsonl"
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.endswith("}")]


def run(record: Path, duration: float, *overrides: str, kill_at_step: int | None = None) -> dict:
    """One run; with ``kill_at_step``, SIGKILL the dynamics once the checkpoint of that step is taken."""
    command = [
        sys.executable,
        "-m",
        "orchestrator.cli",
        "run",
        DEMO,
        "--record",
        str(record),
        "--set",
        f"run.duration={duration} s",
        *overrides,
    ]
    start = time.perf_counter()
    process = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    killed_at = detected_at = None
    try:
        if kill_at_step is not None:
            while not any(e["event"] == "checkpoint" and e["step"] == kill_at_step for e in events(record)):
                time.sleep(0.001)
            pid = dynamics_pid(record)
            killed_at = time.perf_counter()
            os.kill(pid, signal.SIGKILL)
            while not any(e["event"] == "fault" for e in events(record)):
                time.sleep(0.001)
            detected_at = time.perf_counter()
        _, err = process.communicate(timeout=600)
    finally:
        if process.poll() is None:
            process.kill()
    wall = time.perf_counter() - start
    if process.returncode != 0:
        raise SystemExit(f"run failed: {err}")
    found = events(record)
    return {"wall": wall, "events": found, "detection": None if killed_at is None else detected_at - killed_at}


def dynamics_pid(record: Path) -> int:
    run_id = events(record)[0]["run_id"]
    out = subprocess.run(["ps", "-ww", "-eo", "pid=,args="], capture_output=True, text=True).stdout
    for line in out.splitlines():
        if "components.runner" in line and run_id in line and "--name dynamics " in line:
            return int(line.split()[0])
    raise SystemExit("no dynamics process found")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--duration", type=float, default=8.0, help="simulated seconds per run")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    half = int(args.duration / 2 * 1000)  # the demo steps 1 ms
    restartable = ["--set", "components.dynamics.on_failure=restart", "--set", "run.checkpoint_every=1 s"]
    kinds = {
        "undisturbed": ([], None),
        "checkpointed": (restartable, None),
        "swapped": (["--set", f"events=[{{at: {half} ms, swap: controller}}]"], None),
        "killed": (restartable, half),
    }
    results: dict[str, list[dict]] = {k: [] for k in kinds}
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.repeat):
            for kind, (overrides, kill) in kinds.items():
                results[kind].append(run(Path(tmp) / f"{kind}{i}", args.duration, *overrides, kill_at_step=kill))

    def median(kind, value):
        return float(np.median([value(r) for r in results[kind]]))

    def event(kind, name, key):
        return median(kind, lambda r: next(e[key] for e in r["events"] if e["event"] == name))

    base = median("undisturbed", lambda r: r["wall"])
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}; {DEMO}, {args.duration:g} s simulated, medians of {args.repeat}"
    )
    print(f"undisturbed run: {base:.2f} s wall")
    print(
        f"checkpoints every 1 s: {median('checkpointed', lambda r: r['wall']) - base:+.2f} s wall "
        f"({int(args.duration)} checkpoints)"
    )
    print(
        f"same-type swap of the controller: holds the run {event('swapped', 'swap', 'wall_s'):.2f} s "
        f"(whole run {median('swapped', lambda r: r['wall']) - base:+.2f} s)"
    )
    print(
        f"SIGKILL of the dynamics: detected in {median('killed', lambda r: r['detection']) * 1e3:.1f} ms; "
        f"restart {event('killed', 'restart', 'wall_s'):.2f} s; "
        f"whole run {median('killed', lambda r: r['wall']) - base:+.2f} s "
        f"(re-runs the steps since the last checkpoint)"
    )


if __name__ == "__main__":
    main()
