"""The cost of a step through FMI against a native component, in-process (no bus).

    python benchmarks/bench_fmu.py [--steps 20000]

1. The reaction wheel of models/reaction_wheel.py as an FMU (pythonfmu's binary, FMPy's ctypes)
   against the same arithmetic as a native component: the FMI round trip per step.
2. When ``orchestrator export-fmu`` is there: orbit.kepler native against its exported FMU
   imported back as type ``fmu`` (both FMI layers around the same model).
Medians of 5 repeats of ``--steps`` steps each, alternated; the machine is printed.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from components.constants import NS_PER_S  # noqa: E402
from components.sdk import Component, Parameter, Variable  # noqa: E402
from components.testing.harness import Harness  # noqa: E402

H_NS = 10_000_000


class NativeWheel(Component):
    """models/reaction_wheel.py's arithmetic as a native component (the benchmark's reference)."""

    type_name = "bench.native_wheel"
    parameters = tuple(
        Parameter(n, "float", default=d)
        for n, d in (("inertia", 0.05), ("max_torque", 0.2), ("max_speed", 600.0), ("time_constant", 0.05))
    )
    variables = (
        Variable("torque_command", "input", (), "N*m", 0.0, ""),
        Variable("motor_torque", "output", (), "N*m", 0.0, ""),
        Variable("reaction_torque", "output", (), "N*m", 0.0, ""),
        Variable("wheel_speed", "output", (), "rad/s", 0.0, ""),
    )

    def initialize(self, t0_ns, inputs):
        self.tau = self.w = 0.0
        return {"motor_torque": 0.0, "reaction_torque": 0.0, "wheel_speed": 0.0}

    def do_step(self, t_ns, h_ns, inputs):
        p, h = self.params, h_ns / NS_PER_S
        self.w += self.tau / p["inertia"] * h
        target = max(-p["max_torque"], min(p["max_torque"], float(inputs["torque_command"])))
        self.tau += (target - self.tau) * (1.0 - math.exp(-h / p["time_constant"]))
        if abs(self.w) >= p["max_speed"] and self.tau * self.w > 0.0:
            self.tau = 0.0
        return {"motor_torque": self.tau, "reaction_torque": -self.tau, "wheel_speed": self.w}


def per_step_us(harness: Harness, steps: int) -> float:
    harness.initialize()
    began = time.perf_counter()
    for _ in range(steps):
        harness.step(H_NS)
    return (time.perf_counter() - began) / steps * 1e6


def compare(label: str, make_native, make_fmu, steps: int) -> None:
    native, fmu = [], []
    for _ in range(5):
        native.append(per_step_us(make_native(), steps))
        fmu.append(per_step_us(make_fmu(), steps))
    n, f = statistics.median(native), statistics.median(fmu)
    print(f"{label}: native {n:.1f} us/step, through FMI {f:.1f} us/step (+{f - n:.1f} us/step, x{f / n:.2f})")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=20000)
    steps = parser.parse_args().steps
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}")
    from components.fmi.fmu_file import build_python_model

    wheel = build_python_model(ROOT / "models" / "reaction_wheel.py")
    compare(
        "reaction wheel",
        lambda: Harness(NativeWheel, {"inertia": 0.05}),
        lambda: Harness("fmu", {"path": str(wheel), "start_values": {"torque_command": 0.1}}),
        steps,
    )
    try:
        from components.fmi.exported import export_fmu
    except ImportError:
        return
    kepler = {
        "semi_major_axis": "6778 km",
        "eccentricity": 0.0004,
        "inclination": "51.64 deg",
        "raan": "236.55 deg",
        "arg_perigee": "262.44 deg",
        "mean_anomaly": "0 deg",
        "j2": True,
    }
    epoch = "2022-09-18T12:00:00Z"
    with tempfile.TemporaryDirectory() as tmp:
        out = export_fmu("orbit.kepler", kepler, Path(tmp) / "kepler.fmu", epoch, ROOT)
        compare(
            "orbit.kepler",
            lambda: Harness("orbit.kepler", kepler, epoch=epoch),
            lambda: Harness("fmu", {"path": str(out)}),
            steps // 4,
        )


if __name__ == "__main__":
    main()
