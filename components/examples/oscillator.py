"""A user-written component: a mass on a spring, as docs/guides/writing-a-component.md shows it."""

from components.constants import NS_PER_S
from components.sdk import Component, Parameter, Variable


class Oscillator(Component):
    """x'' = (force - stiffness * x) / mass, by semi-implicit Euler over each step."""

    type_name = "example.oscillator"
    parameters = (
        Parameter("mass", "float", unit="kg", plausible=(1e-3, 1e6), description="moving mass"),
        Parameter("stiffness", "float", unit="N/m", plausible=(0.0, 1e9), description="spring constant"),
        Parameter("x0", "float", unit="m", default=0.0, plausible=(-100.0, 100.0), description="initial position"),
    )

    @classmethod
    def declare(cls, params, run):
        return [
            Variable("force", "input", (), "N", 0.0, "external force"),
            Variable("x", "output", (), "m", params["x0"], "position"),
            Variable("v", "output", (), "m/s", 0.0, "velocity"),
        ]

    def __init__(self, params, run):
        self.m, self.k, self.x, self.v = params["mass"], params["stiffness"], params["x0"], 0.0

    def initialize(self, t0_ns, inputs):
        return {"x": self.x, "v": self.v}

    def do_step(self, t_ns, h_ns, inputs):
        h = h_ns / NS_PER_S  # integer ns -> s: a division (components/constants.py)
        self.v += h * (float(inputs["force"]) - self.k * self.x) / self.m
        self.x += h * self.v
        return {"x": self.x, "v": self.v}

    def get_state(self):
        return {"x": self.x, "v": self.v}

    def set_state(self, state):
        self.x, self.v = float(state["x"]), float(state["v"])
