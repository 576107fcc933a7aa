"""Time per step of the dynamics.dart physics for the humanoid torso (Table 1 model).

    python benchmarks/bench_dynamics.py [--steps 2000] [--step 1e-3]

For each integrator (rk4, dart) and environment (none; tidal + gravity gradient in a 6778 km
orbit), prints the wall time per communication step of OrbitalWorld.step alone and of the whole
component step (inputs, step, all outputs) through the in-process harness. The arm follows
a PD law towards a moving posture
(within the joint limits). A benchmark, not a test: numbers depend on the machine.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from components.dynamics.component import DartDynamics  # noqa: E402
from components.dynamics.world import BodySpec, OrbitalWorld  # noqa: E402
from components.testing.harness import Harness  # noqa: E402

URDF = ROOT / "models" / "humanoid_torso.urdf"
R0, V0 = np.array([6778e3, 0.0, 0.0]), np.array([0.0, 7668.6, 0.0])
START = {"arm_right_1_joint": -0.4, "arm_right_2_joint": -0.3, "arm_right_4_joint": -1.0,
         "arm_left_1_joint": -0.4, "arm_left_2_joint": 0.3, "arm_left_4_joint": -1.0}


REF = np.array([START.get(f"arm_{s}_{i}_joint", 0.0) for s in ("left", "right") for i in range(1, 8)])


def torques(k: int, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """A PD towards a slowly moving posture: the arms move, no joint reaches a limit."""
    ref = REF + 0.3 * np.sin(1.3e-3 * k + np.arange(14))
    return 2.0 * (ref - q) - 0.5 * qd


def bench_world(integrator: str, environment: bool, steps: int, h: float) -> float:
    world = OrbitalWorld([BodySpec("humanoid", URDF, q=START)], integrator=integrator,
                         tidal_force=environment, gravity_gradient=environment)
    if environment:
        world.set_orbit(R0, V0)
    world.reset_bodies()
    started = time.perf_counter()
    body = world.bodies["humanoid"]
    for k in range(steps):
        world.set_torques("humanoid", torques(k, body.joint_positions(), body.joint_velocities()))
        world.step(h)
    return (time.perf_counter() - started) / steps


def bench_component(integrator: str, environment: bool, steps: int, h: float) -> float:
    harness = Harness(DartDynamics, {"integrator": integrator, "tidal_force": environment,
                                     "gravity_gradient": environment,
                                     "bodies": {"humanoid": {"urdf": str(URDF), "q": START}}})
    if environment:
        harness.inputs["r_eci"], harness.inputs["v_eci"] = R0, V0
    harness.initialize()
    h_ns = int(round(h * 1e9))
    started = time.perf_counter()
    out = harness.outputs
    for k in range(steps):
        harness.inputs["humanoid.tau"] = torques(k, out["humanoid.q"], out["humanoid.qd"])
        out = harness.step(h_ns)
    return (time.perf_counter() - started) / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--step", type=float, default=1e-3, help="communication step, s")
    args = parser.parse_args()
    print(f"humanoid torso, 20 DOF (6 base + 14 arm), step {args.step * 1e3:g} ms, {args.steps} steps")
    print(f"{'integrator':<11}{'environment':<22}{'world.step':>12}{'component step':>16}")
    for integrator in ("rk4", "dart"):
        for environment in (False, True):
            world = bench_world(integrator, environment, args.steps, args.step)
            component = bench_component(integrator, environment, args.steps, args.step)
            label = "tidal + gravity grad." if environment else "none"
            print(f"{integrator:<11}{label:<22}{world * 1e6:>9.0f} us{component * 1e6:>13.0f} us")


if __name__ == "__main__":
    main()
