"""CPU time per step of ``orbit.kepler``, in process (no bus), with the demo's orbital elements.

    python benchmarks/bench_orbit.py [--steps 5000] [--repeat 5]

Rows: ``KeplerOrbit.state`` alone, then ``do_step`` plus packing its outputs into the float64
layout (what a component's process spends per step, as components/process.py times it), with and
without J2. The elements are those of configs/humanoid_tracking.yaml; 1 ms steps from t = 0.
Each row is the median over batches of ``BATCH`` consecutive steps of the thread's CPU time
(``time.thread_time_ns``), so that another process busy on the other core does not count; the
lowest such median of ``--repeat`` passes (on a shared machine CPU time still varies from pass
to pass, with the caches and the other core's load).
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from components.testing.harness import Harness  # noqa: E402

DEMO = ROOT / "configs" / "humanoid_tracking.yaml"
MS = 1_000_000
BATCH = 10


def cpu_time_per_step(step, steps: int, repeat: int) -> float:
    """CPU time (s) of ``step(k)``, k = 0 .. steps - 1: median over batches of BATCH calls,
    lowest of ``repeat`` passes."""
    medians = []
    for _ in range(repeat):
        per_step = []
        for first in range(0, steps - BATCH + 1, BATCH):
            started = time.thread_time_ns()
            for k in range(first, first + BATCH):
                step(k)
            per_step.append((time.thread_time_ns() - started) / BATCH)
        medians.append(np.median(per_step))
    return float(min(medians)) * 1e-9


def kepler(j2: bool) -> Harness:
    config = yaml.safe_load(DEMO.read_text())
    params = {**config["components"]["orbit"]["parameters"], "j2": j2}
    harness = Harness("orbit.kepler", params, epoch=str(config["run"]["epoch"]))
    harness.initialize()
    return harness


def timed_steps(harness):
    """(label, step(k)) pairs: the orbit's state alone, and a component step with its output packing."""
    component, orbit = harness.component, harness.component.orbit
    outputs = harness.output_layout.start_vector()

    def do_step(k):
        harness.output_layout.pack(component.do_step(k * MS, MS, {}), outputs)

    return (("KeplerOrbit.state", lambda k: orbit.state(k * 1e-3)), ("do_step + output packing", do_step))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=5000)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    print(
        f"orbit.kepler CPU time per step ({args.steps} steps of 1 ms; median of batches of {BATCH}, "
        f"lowest of {args.repeat} passes; "
        f"{platform.processor() or platform.machine()}, Python {platform.python_version()})"
    )
    for j2 in (True, False):
        for label, step in timed_steps(kepler(j2)):
            us = cpu_time_per_step(step, args.steps, args.repeat) * 1e6
            print(f"  j2 {str(j2).lower():<6}{label:<40}{us:9.1f} us/step")


if __name__ == "__main__":
    main()
