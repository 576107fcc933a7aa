"""CPU time per step of the dynamics components (dynamics.dart, dynamics.pinocchio), in process (no bus).

    python benchmarks/bench_dynamics.py [--steps 3000] [--repeat 3] [--engines dart pinocchio]
                                        [--link-outputs] [--table]

Rows, each for every engine given (``--engines``, default both), engines alternating row by row:
the paper's demo, the ``dynamics`` parameters of configs/humanoid_tracking.yaml as they are
(humanoid torso, left arm locked, rk4, tidal force and gravity-gradient torque, 1 ms steps); a
rigid box (models/target.urdf: one body, no joints, rk4, tidal force and gravity-gradient
torque); the servicer (models/capture/servicer.urdf: six arm joints and three wheels, the same
environment). Each driven by a circular 6778 km orbit and a PD law holding the start posture.
Timed as components/process.py times a component's compute: unpacking the inputs, ``do_step``
and packing the outputs in the fixed float64 layout. ``--link-outputs`` adds the demo with
``link_outputs: true``; ``--table`` adds rk4 and dart, with and without the environment, on an
unlocked humanoid (link_outputs false; dart engine).

Each row is the median over the steps of the thread's CPU time (``time.thread_time_ns``, so
that another process busy on the other core does not count), the lowest such median of
``--repeat`` passes. A benchmark, not a test: the numbers depend on the machine.
"""

from __future__ import annotations

import argparse
import math
import platform
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from components.constants import MU_EARTH  # noqa: E402
from components.testing.harness import Harness  # noqa: E402

CONFIGS = ROOT / "configs"
DEMO = CONFIGS / "humanoid_tracking.yaml"
URDF = str(ROOT / "models" / "humanoid_torso.urdf")
BOX = {
    "integrator": "rk4",
    "tidal_force": True,
    "gravity_gradient": True,
    "bodies": {
        "box": {
            "urdf": str(ROOT / "models" / "target.urdf"),
            "frame": "lvlh",
            "orientation": [0, 0, 0.0087265355, 0.9999619231],
        }
    },
}
SERVICER = {
    "integrator": "rk4",
    "tidal_force": True,
    "gravity_gradient": True,
    "bodies": {
        "servicer": {
            "urdf": str(ROOT / "models" / "capture" / "servicer.urdf"),
            "frame": "lvlh",
            "q": {
                "arm_1_joint": -0.9,
                "arm_2_joint": 0.2,
                "arm_3_joint": 1.6,
                "arm_4_joint": -0.3,
                "arm_5_joint": 1.2,
                "arm_6_joint": 0.3,
            },
        }
    },
}
A = 6778e3
MS = 1_000_000


def circular_orbit(t: float) -> dict[str, np.ndarray]:
    """The orbit inputs of dynamics.dart on an equatorial circular orbit of radius A at time t."""
    n = math.sqrt(MU_EARTH / A**3)
    th = n * t
    return {
        "r_eci": A * np.array([math.cos(th), math.sin(th), 0.0]),
        "v_eci": A * n * np.array([-math.sin(th), math.cos(th), 0.0]),
        "q_eci_lvlh": np.array([0.0, 0.0, math.sin(th / 2), math.cos(th / 2)]),
        "w_lvlh": np.array([0.0, 0.0, n]),
    }


def step_times(engine: str, params: dict, steps: int) -> np.ndarray:
    """CPU time (ns) of each of ``steps`` component steps of 1 ms of ``dynamics.<engine>``, as the
    runner times them."""
    harness = Harness(f"dynamics.{engine}", params, config_dir=CONFIGS)
    component, inputs, outputs = harness.component, harness.input_layout, harness.output_layout
    body = next(iter(params["bodies"]))
    input_vector, output_vector = inputs.start_vector(), outputs.start_vector()
    harness.inputs.update(circular_orbit(0.0))
    out = harness.initialize()
    posture = out[f"{body}.q"].copy()
    times = np.empty(steps)
    for k in range(steps):
        values = {
            **circular_orbit(k * 1e-3),
            f"{body}.tau": 0.5 * (posture - out[f"{body}.q"]) - 0.2 * out[f"{body}.qd"],
        }
        for name, value in values.items():
            input_vector[inputs.offsets[name]] = value
        started = time.thread_time_ns()
        result = component.do_step(k * MS, MS, inputs.unpack(input_vector))
        outputs.pack(result, output_vector)
        times[k] = time.thread_time_ns() - started
        out = outputs.unpack(output_vector)
    return times


def timed(label: str, params: dict, steps: int, repeat: int, engines=("dart",)) -> None:
    """One row: the best median of ``repeat`` passes per engine, the engines alternating pass by pass."""
    medians = {engine: np.inf for engine in engines}
    for _ in range(repeat):
        for engine in engines:
            medians[engine] = min(medians[engine], np.median(step_times(engine, params, steps)))
    print(f"  {label:<46}" + "".join(f"{engine:>11} {medians[engine] * 1e-3:7.1f} us" for engine in engines))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--link-outputs", action="store_true", help="also time the demo with link_outputs: true")
    parser.add_argument("--table", action="store_true", help="also time rk4 and dart, with and without environment")
    parser.add_argument("--engines", nargs="+", default=["dart", "pinocchio"], choices=("dart", "pinocchio"))
    args = parser.parse_args()
    print(
        f"dynamics compute per 1 ms step, CPU time, median of {args.steps} steps, best of {args.repeat} "
        f"({platform.processor() or platform.machine()}, Python {platform.python_version()})"
    )
    demo = yaml.safe_load(DEMO.read_text())["components"]["dynamics"]["parameters"]
    engines = tuple(args.engines)
    timed(f"demo ({DEMO.name})", demo, args.steps, args.repeat, engines)
    timed("rigid box (target.urdf), rk4, tidal + gg", BOX, args.steps, args.repeat, engines)
    timed("servicer (capture/servicer.urdf), rk4, tidal + gg", SERVICER, args.steps, args.repeat, engines)
    if args.link_outputs:
        timed("demo, link_outputs true", {**demo, "link_outputs": True}, args.steps, args.repeat, engines)
    if args.table:
        humanoid = {"urdf": URDF, "q": dict(demo["bodies"]["humanoid"]["q"])}
        for integrator in ("rk4", "dart"):
            for environment in (False, True):
                params = {
                    "integrator": integrator,
                    "tidal_force": environment,
                    "gravity_gradient": environment,
                    "link_outputs": False,
                    "bodies": {"humanoid": humanoid},
                }
                label = f"{integrator}, unlocked, {'tidal + gravity gradient' if environment else 'no environment'}"
                timed(label, params, args.steps, args.repeat)


if __name__ == "__main__":
    main()
