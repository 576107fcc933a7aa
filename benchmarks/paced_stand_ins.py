"""Stand-ins of a chosen per-step cost for the demo's dynamics and controller, for bench_pace.py
(not physics, not control).

Types ``benchmarks.paced_stand_ins:PacedDynamics`` and ``benchmarks.paced_stand_ins:PacedController``:
the parameters and variables of ``dynamics.dart`` and ``controller.computed_torque``, plus ``replay``
(an .npy file: one row of the real type's outputs in its output layout per step, row 0 the initial
outputs) and ``cost`` (CPU time per step). A step spends ``cost`` of its thread's CPU time, then
returns row k + 1: the values of a recorded run, so that what they feed computes on the values it
would see. Their inputs are read and ignored.
"""

from __future__ import annotations

import time

import numpy as np

from components.constants import NS_PER_S
from components.controller.computed_torque_component import ComputedTorqueComponent
from components.dynamics.component import DartDynamics
from components.schema import Float
from components.sdk import Component, Parameter, layouts

STAND_IN_PARAMETERS = (
    Parameter("replay", "str", description="an .npy of the real type's output vectors, one row per step from t0"),
    Parameter("cost", Float("s", minimum=0.0), description="CPU time spent per step"),
)


class _Paced(Component):
    real: type[Component]

    @classmethod
    def declare(cls, params, run):
        return cls.real.declare(params, run)

    def __init__(self, params, run):
        super().__init__(params, run)
        self.rows = np.load(params["replay"])
        self.layout = layouts(self.declare(params, run))[1]
        if self.rows.shape[1] != self.layout.size:
            raise ValueError(f"replay: rows of {self.rows.shape[1]} values, the outputs hold {self.layout.size}")
        self.cost_ns = round(params["cost"] * NS_PER_S)

    def _row(self, k: int) -> dict[str, np.ndarray]:
        return self.layout.unpack(self.rows[min(k, len(self.rows) - 1)])

    def initialize(self, t0_ns, inputs):
        return self._row(0)

    def do_step(self, t_ns, h_ns, inputs):
        until = time.thread_time_ns() + self.cost_ns
        while time.thread_time_ns() < until:
            pass
        return self._row((t_ns + h_ns) // h_ns)


class PacedDynamics(_Paced):
    type_name = "bench.paced_dynamics"
    real = DartDynamics
    parameters = DartDynamics.parameters + STAND_IN_PARAMETERS


class PacedController(_Paced):
    type_name = "bench.paced_controller"
    real = ComputedTorqueComponent
    parameters = ComputedTorqueComponent.parameters + STAND_IN_PARAMETERS
