"""Cost per step of the drag's atmosphere, in process: ``python -m benchmarks.bench_atmosphere``.

One body (models/target.urdf, one link with a drag area) on an ISS orbit, tidal force and
gravity gradient on, 1 s steps, on each engine: drag off, drag with the exponential table (the
default), drag with NRLMSISE-00 (one model call per step). Prints the best of 7 batches of 300
steps, us per step (the machine's other load only adds).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from components.constants import MU_EARTH, R_EARTH
from components.dynamics.world import BodySpec, OrbitalWorld
from components.space.atmosphere import LocalExponential, Nrlmsise00

ROOT = Path(__file__).resolve().parents[1]


def orbit(t: float, a: float = R_EARTH + 420e3, inclination: float = math.radians(51.6)):
    n = math.sqrt(MU_EARTH / a**3)
    c, s, ci, si = math.cos(n * t), math.sin(n * t), math.cos(inclination), math.sin(inclination)
    return a * np.array([c, s * ci, s * si]), a * n * np.array([-s, c * ci, c * si])


def per_step(engine: str, drag: bool, atmosphere) -> float:
    spec = BodySpec("sat", str(ROOT / "models" / "target.urdf"), drag_area={"target": 2.0}, drag_cd=2.2)
    world = OrbitalWorld([spec], engine=engine, drag=drag, atmosphere=atmosphere)
    world.set_orbit(*orbit(0.0))
    world.reset_bodies()
    best, k = math.inf, 0
    for batch in range(8):
        start = time.perf_counter()
        for _ in range(300):
            world.set_orbit(*orbit(float(k)))
            world.orbit_time = float(k)
            world.step(1.0)
            k += 1
        if batch:  # (the first batch warms up)
            best = min(best, (time.perf_counter() - start) / 300)
    return best * 1e6


def main() -> None:
    for engine in ("pinocchio", "dart"):
        off = per_step(engine, False, None)
        table = per_step(engine, True, None)
        msis = per_step(engine, True, LocalExponential(Nrlmsise00(150.0, 150.0, 4.0), "2026-03-20T08:00:00Z"))
        print(
            f"{engine}: drag off {off:.0f} us/step, exponential table {table:.0f}, NRLMSISE-00 {msis:.0f} "
            f"(+{msis - table:.0f})"
        )


if __name__ == "__main__":
    main()
