"""Cost per step of solar radiation pressure in the dynamics: off, a cannonball, six facets.

    python benchmarks/bench_srp.py [--steps 2000] [--rounds 3]

Bodies: models/target.urdf (one link, 200 kg box) and models/capture/servicer.urdf (bus, six-joint
arm, three wheels), on a circular 6778 km orbit, rk4 with tidal force and gravity gradient on,
1 s steps, each engine (``dynamics.dart``, ``dynamics.pinocchio``), stepped in this process
through components.testing.harness.Harness. SRP variants: off (the default), ``srp_area`` on the
base link (cannonball), and six facets of a 2 m box on the base link (``srp_facets``); eclipse
conical (Earth and Moon). The figure is the process's CPU time per step, the median over batches
of 100 steps and then over the rounds (the variants alternate). A benchmark, never run by the
tests; it prints the machine and its load.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from components.constants import MU_EARTH  # noqa: E402
from components.testing.harness import Harness  # noqa: E402

BATCH = 100
EPOCH = "2024-03-20T06:00:00Z"
BOX = [
    {"area": 4.0, "normal": n, "centre": [c * 1.0 for c in n], "specular": 0.2, "diffuse": 0.3}
    for n in ([1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1])
]
BODIES = {"target": ("../models/target.urdf", "target"), "servicer": ("../models/capture/servicer.urdf", "bus")}
VARIANTS = {"off": {}, "cannonball": {"srp_area": 4.0}, "facets": {"srp_facets": "BOX"}}


def orbit(t: float, a: float = 6778e3) -> dict[str, np.ndarray]:
    n = math.sqrt(MU_EARTH / a**3)
    th = n * t
    return {
        "r_eci": a * np.array([math.cos(th), math.sin(th), 0.0]),
        "v_eci": a * n * np.array([-math.sin(th), math.cos(th), 0.0]),
        "q_eci_lvlh": np.array([0.0, 0.0, math.sin(th / 2), math.cos(th / 2)]),
        "w_lvlh": np.array([0.0, 0.0, n]),
    }


def harness(engine: str, body: str, variant: str) -> Harness:
    urdf, root = BODIES[body]
    extra = dict(VARIANTS[variant])
    if extra.get("srp_facets") == "BOX":
        extra["srp_facets"] = {root: BOX}
    params = {
        "srp": variant != "off",
        "bodies": {body: {"urdf": urdf, "frame": "lvlh", "orientation": [0.1, 0.2, 0.3, 0.93], **extra}},
    }
    h = Harness(f"dynamics.{engine}", params, config_dir=ROOT / "configs", epoch=EPOCH)
    h.inputs.update(orbit(0.0))
    h.initialize()
    return h


def per_step(h: Harness, steps: int) -> float:
    """Median CPU seconds per step over batches of BATCH steps."""
    batches = []
    for _b in range(steps // BATCH):
        start = time.process_time()
        for _k in range(BATCH):
            t = h.t_ns / 1e9
            h.inputs.update(orbit(t))
            h.step(1_000_000_000)
        batches.append((time.process_time() - start) / BATCH)
    return statistics.median(batches)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    compare("SRP", VARIANTS, harness, args.steps, args.rounds)


def compare(what: str, variants, make, steps: int, rounds: int) -> None:
    """Prints the table: per engine and body, each variant's CPU time per step (``make(engine,
    body, variant)`` gives its Harness; the variants alternate over the rounds) against "off"."""
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cpus, load {os.getloadavg()[0]:.2f}"
    )
    print(f"| engine | body | {what} | us per step | vs off |")
    print("|---|---|---|---|---|")
    for engine in ("dart", "pinocchio"):
        for body in BODIES:
            harnesses = {v: make(engine, body, v) for v in variants}
            figures = {v: [] for v in variants}
            for _ in range(rounds):
                for v, h in harnesses.items():
                    figures[v].append(per_step(h, steps))
            off = statistics.median(figures["off"])
            for v in variants:
                value = statistics.median(figures[v])
                print(
                    f"| dynamics.{engine} | {body} | {v} | {value * 1e6:.1f} | {(value - off) * 1e6:+.1f} us ({value / off:.2f}x) |"
                )
    print(f"load after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
