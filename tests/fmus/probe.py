"""A pythonfmu test model with what real FMUs have: vector elements p[0]..p[2], an Integer input,
a name Zenorbit cannot hold (der(q)), a parameter and a failing step.

p += gain * (mode + 1) * u * h over each step; der(q) = gain * u[0]; count = steps taken.
At current_time >= fail_at the step returns an error.
"""

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Status


class Probe(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.gain = 1.0
        self.fail_at = 1e9
        self.mode = 0
        self.count = 0
        self.u = [0.0, 0.0, 0.0]
        self.p = [0.0, 0.0, 0.0]
        self.rate = 0.0
        for name in ("gain", "fail_at"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        for i in range(3):
            self.register_variable(
                Real(
                    f"u[{i}]",
                    causality=Fmi2Causality.input,
                    description="drive",
                    getter=lambda i=i: self.u[i],
                    setter=lambda v, i=i: self.u.__setitem__(i, v),
                ),
                nested=False,
            )
        self.register_variable(
            Integer("mode", causality=Fmi2Causality.input, variability=Fmi2Variability.discrete, description="gear")
        )
        for i in range(3):
            self.register_variable(
                Real(
                    f"p[{i}]",
                    causality=Fmi2Causality.output,
                    description="integral",
                    getter=lambda i=i: self.p[i],
                    setter=lambda v, i=i: self.p.__setitem__(i, v),
                ),
                nested=False,
            )
        self.register_variable(
            Real(
                "der(q)",
                causality=Fmi2Causality.output,
                description="rate",
                getter=lambda: self.rate,
                setter=lambda v: setattr(self, "rate", v),
            ),
            nested=False,
        )
        self.register_variable(
            Integer(
                "count", causality=Fmi2Causality.output, variability=Fmi2Variability.discrete, description="steps taken"
            )
        )

    def do_step(self, current_time, step_size):
        if current_time >= self.fail_at:
            self.log(f"probe: told to fail at t = {current_time}", Fmi2Status.error)
            return False
        for i in range(3):
            self.p[i] += self.gain * (self.mode + 1) * self.u[i] * step_size
        self.rate = self.gain * self.u[0]
        self.count += 1
        return True
