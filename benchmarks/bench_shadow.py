"""The cost of a shadow: the paper's demo over the bus with and without a shadow controller
(controller.computed_torque with softer gains), runs alternated so that a busy machine weighs on
all alike.

    python benchmarks/bench_shadow.py [--seconds 5] [--rounds 3]

Each round runs the demo without a shadow, then with one. Prints each run's real-time factor (stepping loop only, start-up excluded) and CPU time (all its processes,
start-up included: on a busy machine a steadier figure of the cost than the wall time), then
the medians: the ratio of the real-time factors with / without, the extra CPU time, and the
compute per step of the dynamics, the controller and the shadow (wall time of do_step,
preemption included).
"""

from __future__ import annotations

import argparse
import io
import os
import resource
import sys
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))


def shadow_override() -> str:
    """``--set`` text giving the demo's controller a shadow of softer gains (kp 64, kd 16)."""
    raw = yaml.safe_load((ROOT / "configs" / "humanoid_tracking.yaml").read_text())
    parameters = {**raw["components"]["controller"]["parameters"], "kp": [64] * 6, "kd": [16] * 6}
    shadow = {"type": "controller.computed_torque", "parameters": parameters}
    return "components.controller.shadow=" + yaml.safe_dump(shadow, default_flow_style=True, width=10**6).strip()


def cpu_s() -> float:
    """CPU time of this process and its children that have ended (the run's component processes)."""
    return sum(
        r.ru_utime + r.ru_stime for r in map(resource.getrusage, (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    )


def demo(seconds: float, more: list[str]) -> tuple[float, float, dict[str, float]]:
    """(real-time factor, CPU seconds, {component: compute per step, s}) of one bus run of the demo."""
    from orchestrator.config.load import load
    from orchestrator.run.engine import Run

    before = cpu_s()
    run = Run(
        load(ROOT / "configs" / "humanoid_tracking.yaml", [f"run.duration={seconds} s", *more]),
        out=io.StringIO(),
    )
    if run.execute() != 0:
        raise RuntimeError("the demo failed over the bus")
    return (
        seconds / run.loop_s,
        cpu_s() - before,
        {m.name: m.compute_s / max(m.steps, 1) for m in run.state.members.values()},
    )


def main() -> None:
    from bench_performance import machine

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="simulated time of each run")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of runs, without and with a shadow")
    args = parser.parse_args()
    print(f"machine: {machine()}; load average {os.getloadavg()[0]:.2f} at the start")
    variants = {"without": [], "with a shadow": [shadow_override()]}
    results: dict[str, list] = {name: [] for name in variants}
    for i in range(args.rounds):
        for name, overrides in variants.items():
            results[name].append(demo(args.seconds, overrides))
            factor, cpu, _ = results[name][-1]
            print(f"round {i + 1}, {name}: real-time factor {factor:.2f}, CPU {cpu:.1f} s", flush=True)
    print(f"medians over {args.rounds} rounds (load average {os.getloadavg()[0]:.2f} at the end):")
    plain = results["without"]
    for name, runs in results.items():
        line = f"  {name}: real-time factor {np.median([r[0] for r in runs]):.2f}, CPU {np.median([r[1] for r in runs]):.1f} s"
        if variants[name]:
            ratio = np.median([r[0] / p[0] for r, p in zip(runs, plain)])
            extra = np.median([r[1] - p[1] for r, p in zip(runs, plain)])
            compute = {
                c: np.median([r[2][c] for r in runs]) * 1e6 for c in ("dynamics", "controller", "controller_shadow")
            }
            line += f"; ratio to without {ratio:.2f} (same round), +{extra:.1f} CPU s; compute per step: " + ", ".join(
                f"{c} {us:.0f} us" for c, us in compute.items()
            )
        print(line)


if __name__ == "__main__":
    main()
