"""The cost of a shadow: the paper's demo over the bus with and without a shadow controller
(controller.computed_torque with softer gains), runs alternated so that a busy machine weighs on
both alike.

    python benchmarks/bench_shadow.py [--seconds 5] [--pairs 3]

Prints each pair's real-time factors (stepping loop only, start-up excluded), their ratio, the
median ratio, and the compute per step of the controller and its shadow.
"""
from __future__ import annotations

import argparse
import os
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


def demo(seconds: float, more: list[str]) -> tuple[float, dict[str, float]]:
    """(real-time factor, {component: compute per step, s}) of one bus run of the demo."""
    from orchestrator.config import load
    from orchestrator.engine import Run

    run = Run(load(ROOT / "configs" / "humanoid_tracking.yaml", [f"run.duration={seconds} s", *more]),
              out=open(os.devnull, "w"))
    if run.execute() != 0:
        raise RuntimeError("the demo failed over the bus")
    return seconds / run.loop_s, {m.name: m.compute_s / max(m.steps, 1) for m in run.members.values()}


def main() -> None:
    from bench_performance import machine

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="simulated time of each run")
    parser.add_argument("--pairs", type=int, default=3, help="pairs of runs, without and with a shadow")
    args = parser.parse_args()
    print(f"machine: {machine()}; load average {os.getloadavg()[0]:.2f} at the start")
    shadowed = [shadow_override()]
    ratios, compute = [], []
    for i in range(args.pairs):
        plain, _ = demo(args.seconds, [])
        shadow, per_step = demo(args.seconds, shadowed)
        ratios.append(shadow / plain)
        compute.append(per_step)
        print(f"pair {i + 1}: real-time factor {plain:.2f} without, {shadow:.2f} with a shadow "
              f"(ratio {shadow / plain:.2f})", flush=True)
    print(f"median ratio with / without a shadow: {np.median(ratios):.2f} "
          f"(load average {os.getloadavg()[0]:.2f} at the end)")
    for name in ("dynamics", "controller", "controller_shadow"):
        print(f"  {name}: {np.median([c[name] for c in compute]) * 1e6:.0f} us compute per step")


if __name__ == "__main__":
    main()
