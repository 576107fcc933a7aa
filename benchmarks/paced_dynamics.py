"""A stand-in for a dynamics engine of a chosen per-step cost, for bench_pace.py (not a physics model).

Type ``benchmarks.paced_dynamics:PacedDynamics``: ``dynamics.dart``'s parameters and variables,
plus ``replay`` (an .npy file: one row of dynamics.dart's outputs in its output layout per step,
row 0 the initial outputs) and ``cost`` (CPU time per step). A step spends ``cost`` of its
thread's CPU time, then returns row k + 1: the states of a recorded run, so the components it
feeds compute on the states they would see. Its inputs are read and ignored.
"""
from __future__ import annotations

import time

import numpy as np

from components.dynamics.component import DartDynamics
from components.schema import Float
from components.sdk import Component, Parameter, layouts


class PacedDynamics(Component):
    type_name = "bench.paced_dynamics"
    parameters = DartDynamics.parameters + (
        Parameter("replay", "str", description="an .npy of dynamics.dart's output vectors, one row per step from t0"),
        Parameter("cost", Float("s", minimum=0.0), description="CPU time spent per step"),
    )

    @classmethod
    def declare(cls, params):
        return DartDynamics.declare(params)

    def __init__(self, params):
        super().__init__(params)
        self.rows = np.load(params["replay"])
        self.layout = layouts(self.declare(params))[1]
        if self.rows.shape[1] != self.layout.size:
            raise ValueError(f"replay: rows of {self.rows.shape[1]} values, the outputs hold {self.layout.size}")
        self.cost_ns = round(params["cost"] * 1e9)

    def _row(self, k: int) -> dict[str, np.ndarray]:
        return self.layout.unpack(self.rows[min(k, len(self.rows) - 1)])

    def initialize(self, t0_ns, inputs):
        return self._row(0)

    def do_step(self, t_ns, h_ns, inputs):
        until = time.thread_time_ns() + self.cost_ns
        while time.thread_time_ns() < until:
            pass
        return self._row((t_ns + h_ns) // h_ns)
