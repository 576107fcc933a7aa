"""Cost per step of the magnetic field and magnetorquers in the dynamics, in process.

    python -m benchmarks.bench_magnetic

``dynamics.dart`` with one rigid body (models/target.urdf, the detumble's), tidal force and
gravity gradient on, stepped by the harness at 50 ms: without ``magnetic_field`` (today's path),
with the dipole, with the WMM, and with the WMM and magnetorquers. Prints the median of five
batches of 400 steps, per step (us), as a Markdown table. Never asserted in tests.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CASES = {
    "off (no magnetic_field)": {},
    "dipole": {"magnetic_field": {"model": "dipole"}},
    "wmm": {"magnetic_field": {"model": "wmm"}},
    "wmm + magnetorquers": {"magnetic_field": {"model": "wmm"}, "magnetorquers": {"target": {"max_dipole": 100.0}}},
}


def per_step_us(extra: dict, batches: int = 5, steps: int = 400) -> float:
    from components.testing.harness import Harness

    params = {
        "bodies": {"target": {"urdf": str(ROOT / "models" / "target.urdf"), "twist": [0, 0, 0, 0.03, -0.05, 0.07]}},
        **extra,
    }
    h = Harness("dynamics.dart", params, epoch="2026-03-20T00:00:00Z")
    h.inputs.update(
        r_eci=np.array([2100e3, -6200e3, 2300e3]),
        v_eci=np.array([6900.0, 1800.0, -1500.0]),
        q_eci_lvlh=np.array([0.0, 0.0, 0.0, 1.0]),
        w_lvlh=np.zeros(3),
    )
    if "magnetorquers" in extra:
        h.inputs["target.dipole"] = np.array([20.0, -30.0, 10.0])
    for _ in range(50):
        h.step(50_000_000)
    times = []
    for _ in range(batches):
        start = time.perf_counter()
        for _ in range(steps):
            h.step(50_000_000)
        times.append((time.perf_counter() - start) / steps * 1e6)
    return statistics.median(times)


def main() -> None:
    rows = {name: per_step_us(extra) for name, extra in CASES.items()}
    base = rows["off (no magnetic_field)"]
    print("| dynamics.dart, one rigid body | per step | added |\n|---|---|---|")
    for name, us in rows.items():
        print(f"| {name} | {us:.0f} us | {us - base:+.0f} us |")


if __name__ == "__main__":
    main()
