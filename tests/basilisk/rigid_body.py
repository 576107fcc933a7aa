"""Basilisk's rigid spacecraft: the libration config's box under point-mass gravity and its gravity gradient.

Run in Basilisk's venv by ``python -m tests.basilisk rigid_body``; prints one JSON document (the
case and Basilisk's attitudes). The spacecraft is benchmarks/basilisk_rigid_body.py's (a Spacecraft
hub, the Earth's point-mass gravity, GravityGradientEffector, RK4, one task at the step), started
where Zenorbit's body of configs/gravity_gradient_libration.yaml starts (the CASE below: the
orbit.kepler point, the box's velocity there, its attitude q_N_B [x, y, z, w] and rate in body
axes; tests/unit/test_dynamics_rigid.py checks that Zenorbit starts there). Basilisk integrates
the orbit itself; Zenorbit's dynamics gets orbit.kepler's point each step.
"""

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from basilisk_rigid_body import quaternions, spacecraft_sim

CASE = {
    "mass": 200.0,
    "inertia": [[33.33333333, 0.0, 0.0], [0.0, 59.33333333, 0.0], [0.0, 0.0, 59.33333333]],
    "mu": 3.986004418e14,
    "r": [6778000.0, 0.0, 0.0],
    "v": [0.0, 4759.159193444191, 6013.183590276433],
    "q": [0.4355287591556245, -0.0038008019007964035, 0.007855337468129794, 0.9001325166477071],
    "w": [0.0, 0.0, 0.0011314009553257084],
    "step_ns": 1_000_000_000,
    "steps": 1200,
    "sample_every": 60,
}


def main() -> None:
    from importlib.metadata import version

    sim, recorder = spacecraft_sim(CASE, record=True)
    sim.ConfigureStopTime(CASE["steps"] * CASE["step_ns"])
    sim.ExecuteSimulation()
    print(json.dumps({"version": version("bsk"), "case": CASE, "q": quaternions(recorder.sigma_BN)}))


if __name__ == "__main__":
    main()
