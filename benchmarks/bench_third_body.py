"""Cost per step of the Sun's and the Moon's tidal force on every link (``third_bodies``) in the dynamics.

    python benchmarks/bench_third_body.py [--steps 2000] [--rounds 3]

The bodies, orbit, steps and measure of ``bench_srp.py`` (models/target.urdf, one link;
models/capture/servicer.urdf, 13 links; rk4 with tidal force and gravity gradient on, 1 s steps,
in this process through components.testing.harness.Harness, CPU time per step, the median over
batches of 100 steps and over the rounds, the variants alternating), each engine. Variants:
``third_bodies`` off (the default), [sun], [sun, moon]. A benchmark, never run by the tests.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_srp import BODIES, EPOCH, compare, orbit  # noqa: E402
from components.testing.harness import Harness  # noqa: E402

VARIANTS = {"off": [], "sun": ["sun"], "sun, moon": ["sun", "moon"]}


def harness(engine: str, body: str, variant: str) -> Harness:
    params = {
        "third_bodies": VARIANTS[variant],
        "bodies": {body: {"urdf": BODIES[body][0], "frame": "lvlh", "orientation": [0.1, 0.2, 0.3, 0.93]}},
    }
    h = Harness(f"dynamics.{engine}", params, config_dir=ROOT / "configs", epoch=EPOCH)
    h.inputs.update(orbit(0.0))
    h.initialize()
    return h


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    compare("third_bodies", VARIANTS, harness, args.steps, args.rounds)


if __name__ == "__main__":
    main()
