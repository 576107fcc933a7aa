"""A rigid spacecraft in Zenorbit and in Basilisk: per-step cost side by side, and how far apart
the two attitudes end.

    python benchmarks/bench_basilisk.py [--type dynamics.pinocchio] [--step 1] [--orbits 2] [--rounds 5]

The body and the orbit are configs/gravity_gradient_libration.yaml's (models/target.urdf: a
200 kg box, one link, no joints; a circular 6778 km orbit at 51.64 deg; the box starts pitched
1 deg from LVLH and co-rotating with it), simulated for ``--orbits`` orbits at ``--step``:

- Zenorbit: the component ``--type`` (``dynamics.pinocchio``, whose rigid body steps in one
  compiled call, ``pinocchio_kernels.rk4_rigid``; or any type with its parameters, e.g. the
  config's ``dynamics.dart``) with the config's parameters (rk4, tidal force and gravity-gradient
  torque), stepped in this process through its layouts as components/process.py steps it, its
  orbit inputs from ``orbit.kepler`` with the config's elements (the orbit's own cost not counted).
- Basilisk (``bsk``, in the virtual environment of its fixtures, made on first use:
  ``~/.cache/zenorbit/basilisk`` or ``ZENORBIT_BASILISK_VENV``, see tests/basilisk;
  benchmarks/basilisk_rigid_body.py): a Spacecraft hub with the same mass and inertia, started
  at the same position, velocity, attitude and rate as Zenorbit's body at t = 0, Earth's
  point-mass gravity with the same mu, its GravityGradientEffector and its RK4 integrator, one
  task at the same step. Basilisk integrates the orbit itself.

Per-step cost: the process's CPU time per step of batches of ``BATCH`` steps (Basilisk steps on
a thread of its own, so the thread's time would miss it), the median over the batches of a run;
the two alternate ``--rounds`` times, and the figure is the median over the rounds (wall time
too). Attitude: the largest angle between the two bodies' attitudes over the run, at every
``SAMPLE`` steps. A benchmark, never run by the tests: the numbers depend on the machine, which
it names, with its load average before and after.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from components.constants import MU_EARTH, NS_PER_S  # noqa: E402
from components.testing.harness import Harness  # noqa: E402
from tests.basilisk.__main__ import basilisk_python  # noqa: E402

CONFIG = ROOT / "configs" / "gravity_gradient_libration.yaml"
BASILISK = ROOT / "benchmarks" / "basilisk_rigid_body.py"
BATCH = 100  # steps per timed batch
SAMPLE = 60  # steps between compared attitudes


def machine() -> str:
    model = platform.processor() or platform.machine()
    for line in Path("/proc/cpuinfo").read_text().splitlines() if Path("/proc/cpuinfo").exists() else ():
        if line.startswith("model name"):
            model = line.split(":", 1)[1].strip()
            break
    return (
        f"{model}, {os.cpu_count()} cores, {platform.system()} {platform.release()}, Python {platform.python_version()}"
    )


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def rigid_body(urdf: Path) -> tuple[float, list[list[float]]]:
    """Mass and inertia (about the CoM, link axes) of a one-link URDF whose CoM is its origin."""
    links = ET.parse(urdf).getroot().findall("link")
    inertial = links[0].find("inertial") if len(links) == 1 else None
    origin = inertial.find("origin") if inertial is not None else None
    if inertial is None or (
        origin is not None and any(float(x) for a in ("xyz", "rpy") for x in origin.get(a, "0 0 0").split())
    ):
        raise SystemExit(f"{urdf}: expected one link with its inertial at the link origin")
    i = {k: float(v) for k, v in inertial.find("inertia").attrib.items()}
    return float(inertial.find("mass").get("value")), [
        [i["ixx"], i["ixy"], i["ixz"]],
        [i["ixy"], i["iyy"], i["iyz"]],
        [i["ixz"], i["iyz"], i["izz"]],
    ]


class Scenario:
    """The config's orbit and body, at ``step_ns`` for ``steps`` steps."""

    def __init__(self, component_type: str, step_ns: int, orbits: float):
        config = yaml.safe_load(CONFIG.read_text())
        self.epoch = str(config["run"]["epoch"]).replace(" ", "T").replace("+00:00", "Z")
        self.orbit = config["components"]["orbit"]["parameters"]
        self.dynamics = config["components"]["dynamics"]["parameters"]
        ((self.body, spec),) = self.dynamics["bodies"].items()
        self.mass, self.inertia = rigid_body((CONFIG.parent / spec["urdf"]).resolve())
        a = Harness("orbit.kepler", self.orbit, epoch=self.epoch).params["semi_major_axis"]
        self.type, self.step_ns = component_type, step_ns
        self.steps = round(orbits * 2 * math.pi * math.sqrt(a**3 / MU_EARTH) / (step_ns * 1e-9))

    def zenorbit(self) -> tuple[dict, list[float], list[float], np.ndarray]:
        """(the initial state for Basilisk, process CPU and wall ns per step of each batch, the
        body's q_W_base at every SAMPLE steps)."""
        orbit = Harness("orbit.kepler", self.orbit, epoch=self.epoch, config_dir=CONFIG.parent)
        plant = Harness(self.type, self.dynamics, epoch=self.epoch, config_dir=CONFIG.parent)
        component, inputs, outputs = plant.component, plant.input_layout, plant.output_layout
        orbit_out = orbit.initialize()
        plant.inputs.update(orbit_out)
        plant.input_times_ns = {name: 0 for name in orbit_out}
        out = plant.initialize()
        twist = out[f"{self.body}.twist"]
        R = _matrix(out[f"{self.body}.orientation"])
        start = {
            "r": orbit_out["r_eci"].tolist(),
            "v": (orbit_out["v_eci"] + twist[:3]).tolist(),
            "q": out[f"{self.body}.orientation"].tolist(),
            "w": (R.T @ twist[3:]).tolist(),
        }
        input_vector, output_vector = inputs.start_vector(), outputs.start_vector()
        orientation = outputs.offsets[f"{self.body}.orientation"]
        attitude = [out[f"{self.body}.orientation"].copy()]
        cpu_ns, wall_ns = [], []
        h = self.step_ns
        for first in range(0, self.steps, BATCH):
            n = min(BATCH, self.steps - first)
            cpu, wall = 0, 0
            for k in range(first, first + n):
                for name, value in orbit_out.items():
                    input_vector[inputs.offsets[name]] = value
                component.input_times_ns = {name: k * h for name in orbit_out}
                started_cpu, started_wall = time.process_time_ns(), time.perf_counter_ns()
                outputs.pack(component.do_step(k * h, h, inputs.unpack(input_vector)), output_vector)
                cpu += time.process_time_ns() - started_cpu
                wall += time.perf_counter_ns() - started_wall
                orbit_out = orbit.step(h)
                if (k + 1) % SAMPLE == 0:
                    attitude.append(output_vector[orientation].copy())
            cpu_ns.append(cpu / n)
            wall_ns.append(wall / n)
        return start, cpu_ns, wall_ns, np.array(attitude)

    def basilisk(self, python: Path, start: dict) -> dict:
        spec = {
            "mass": self.mass,
            "inertia": self.inertia,
            "mu": MU_EARTH,
            **start,
            "step_ns": self.step_ns,
            "steps": self.steps,
            "batch": BATCH,
            "sample_every": SAMPLE,
        }
        result = subprocess.run(
            [str(python), str(BASILISK)], input=json.dumps(spec), capture_output=True, text=True, timeout=3600
        )
        if result.returncode != 0:
            raise SystemExit(f"the Basilisk run failed:\n{result.stderr[-3000:]}")
        return json.loads(result.stdout)


def _matrix(q) -> np.ndarray:
    from components.rotations import quat_to_matrix

    return quat_to_matrix(np.asarray(q, dtype=float))


def largest_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """The largest rotation (deg) between matching rows of two arrays of quaternions [x, y, z, w]."""
    n = min(len(a), len(b))
    a, b = a[:n] / np.linalg.norm(a[:n], axis=1, keepdims=True), b[:n] / np.linalg.norm(b[:n], axis=1, keepdims=True)
    dot = np.abs(np.einsum("ij,ij->i", a, b))
    # 2 asin |vec(a^-1 b)|: exact for small angles, where 2 acos |a.b| loses everything
    w = a[:, 3:] * b[:, :3] - b[:, 3:] * a[:, :3] - np.cross(a[:, :3], b[:, :3])
    return float(np.degrees(2.0 * np.arcsin(np.minimum(np.linalg.norm(w, axis=1), 1.0))).max()) if dot.size else 0.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--type", default="dynamics.pinocchio", help="the Zenorbit dynamics type (dynamics.pinocchio)")
    parser.add_argument("--step", type=float, default=1.0, help="step, s (1)")
    parser.add_argument("--orbits", type=float, default=2.0, help="simulated orbits (2)")
    parser.add_argument("--rounds", type=int, default=5, help="alternating rounds (5)")
    args = parser.parse_args()
    from components.errors import ConfigError
    from components.registry import load as load_type

    try:
        load_type(args.type)
    except ConfigError as e:
        parser.error(f"--type: {e.message}")
    python = basilisk_python()
    scenario = Scenario(args.type, round(args.step * NS_PER_S), args.orbits)
    print(f"machine: {machine()}; load average {load()}")
    print(
        f"{scenario.body} ({scenario.mass:g} kg, I = diag{tuple(round(scenario.inertia[i][i], 2) for i in range(3))} "
        f"kg m^2) from {CONFIG.name}, {scenario.steps} steps of {args.step:g} s ({args.orbits:g} orbits), "
        f"rk4, gravity gradient on"
    )
    rows = []
    for r in range(args.rounds):
        start, z_cpu, z_wall, z_attitude = scenario.zenorbit()
        b = scenario.basilisk(python, start)
        rows.append((np.median(z_cpu), np.median(z_wall), np.median(b["cpu_ns"]), np.median(b["wall_ns"])))
        print(
            f"  round {r + 1}: {args.type} {rows[-1][0] * 1e-3:8.1f} us   Basilisk {rows[-1][2] * 1e-3:6.1f} us   "
            f"ratio {rows[-1][0] / rows[-1][2]:5.1f}   (CPU per step; load {load()})"
        )
    z_cpu, z_wall, b_cpu, b_wall = np.median(np.array(rows), axis=0)
    angle = largest_angle_deg(z_attitude, np.array(b["q"]))
    print(
        f"\nBasilisk {b['version']} against {args.type}, medians of {args.rounds} alternating rounds "
        f"(the median of {math.ceil(scenario.steps / BATCH)} batches of {BATCH} steps each):"
    )
    print(f"| | {args.type} | Basilisk | ratio |\n|---|---|---|---|")
    print(f"| CPU time per step (process) | {z_cpu * 1e-3:.1f} us | {b_cpu * 1e-3:.1f} us | {z_cpu / b_cpu:.1f}x |")
    print(f"| wall time per step | {z_wall * 1e-3:.1f} us | {b_wall * 1e-3:.1f} us | {z_wall / b_wall:.1f}x |")
    print(
        f"attitudes over {args.orbits:g} orbits: at most {angle:.2g} deg apart "
        f"(every {SAMPLE} steps, {min(len(z_attitude), len(b['q']))} samples); load average {load()}"
    )


if __name__ == "__main__":
    main()
