"""CPU time per step of the controllers, in process (no bus), on states of the paper's demo.

    python benchmarks/bench_controller.py [--steps 3000] [--repeat 3]

Rows: the model terms alone (Pinocchio: M, nle, Jacobians, the drift, the Schur complements),
one whole ``ArmController.step`` (terms + trajectory + DLS + law), the same through the
component's ``do_step`` with its inputs and outputs in the fixed float64 layout (what
components/process.py times as a component's compute per step, without the bus), the fixed-base
variant, and ``controller.joint_pd``. The states come from a short closed loop with
``dynamics.dart`` (so velocities and the base motion are realistic).
Each row is the median over batches of ``BATCH`` consecutive states of the thread's CPU time
(``time.thread_time_ns``, so that another process busy on the other core does not count), the
lowest such median of ``--repeat`` passes.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from components.testing.harness import Harness  # noqa: E402

URDF = str(ROOT / "models" / "humanoid_torso.urdf")
ARM = [f"arm_right_{i}_joint" for i in range(1, 8)]
LEFT = [f"arm_left_{i}_joint" for i in range(1, 8)]
START = dict(zip(ARM, [-0.72, -2.29, -1.85, -1.91, -0.79, 0.61, 0.22]))
STATE = ("position", "orientation", "twist", "q", "qd")
MS = 1_000_000
BATCH = 10


def controller(base_model="free_floating"):
    return Harness(
        "controller.computed_torque",
        {
            "urdf": URDF,
            "joints": ARM,
            "end_effector": "arm_right_tool_link",
            "locked_joints": LEFT,
            "base_model": base_model,
            "trajectory": {"type": "parabola", "start": 0.0, "duration": 10.0, "displacement": 0.5, "height": 0.1},
        },
    )


def recorded_states(n: int) -> list[dict]:
    """n states of the demo's first n ms (closed loop, dynamics.dart, Jacobi)."""
    plant = Harness(
        "dynamics.dart",
        {
            "link_outputs": False,
            "tidal_force": False,
            "gravity_gradient": False,
            "bodies": {"humanoid": {"urdf": URDF, "q": START, "locked_joints": LEFT}},
        },
    )
    c = controller()
    state = plant.initialize()
    c.inputs.update({k: state[f"humanoid.{k}"] for k in STATE})
    out = c.initialize()
    states = []
    for _ in range(n):
        plant.inputs["humanoid.tau"] = out["tau"]
        c.inputs.update({k: state[f"humanoid.{k}"] for k in STATE})
        states.append({k: state[f"humanoid.{k}"].copy() for k in STATE})
        out = c.step(MS)
        state = plant.step(MS)
    return states


def timed(label: str, fn, states: list[dict], repeat: int) -> None:
    medians = []
    for _ in range(repeat):
        per_step = []
        for first in range(0, len(states) - BATCH + 1, BATCH):
            started = time.thread_time_ns()
            for k in range(first, first + BATCH):
                fn(k, states[k])
            per_step.append((time.thread_time_ns() - started) / BATCH)
        medians.append(np.median(per_step))
    print(f"  {label:<60}{min(medians) * 1e-3:9.1f} us/step")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    print(
        f"controller CPU time per step ({args.steps} demo states; median of batches of {BATCH}, "
        f"lowest of {args.repeat} passes; "
        f"{platform.processor() or platform.machine()}, Python {platform.python_version()})"
    )
    states = recorded_states(args.steps)

    c = controller()
    c.inputs.update(states[0])
    c.initialize()
    ctl = c.component.controller
    arm = ctl.arm

    def terms(k, s):
        arm.set_state(s["position"], s["orientation"], s["twist"], s["q"], s["qd"])
        arm.compute()

    timed("model terms (M*, C*, J_g, a_drift) incl. state mapping", terms, states, args.repeat)
    timed(
        "ArmController.step (terms + trajectory + DLS + law)", lambda k, s: ctl.step(k * 1e-3, s), states, args.repeat
    )

    def as_the_runner(h: Harness):
        """do_step on inputs unpacked from one float64 vector, outputs packed into another: the
        part of a step components/process.py times (the input vectors are filled beforehand)."""
        vectors = []
        for s in states:
            vector = h.input_layout.start_vector()
            for name, value in s.items():
                vector[h.input_layout.offsets[name]] = np.ravel(value)
            vectors.append(vector)
        outputs = h.output_layout.start_vector()

        def run(k, s):
            h.output_layout.pack(h.component.do_step(k * MS, MS, h.input_layout.unpack(vectors[k])), outputs)

        return run

    timed("controller.computed_torque do_step + input/output layout", as_the_runner(c), states, args.repeat)
    fixed = controller("fixed")
    fixed.inputs.update(states[0])
    fixed.initialize()
    timed("controller.computed_torque, base_model: fixed, the same", as_the_runner(fixed), states, args.repeat)
    pd = Harness("controller.joint_pd", {"urdf": URDF, "gains": {j: {"p": 10.0, "d": 1.0, "i": 0.1} for j in ARM}})
    pd.inputs.update(states[0])
    pd.initialize()
    timed("controller.joint_pd do_step + input/output layout", as_the_runner(pd), states, args.repeat)


if __name__ == "__main__":
    main()
