"""A pythonfmu3 (FMI 3.0) test model: y += k * u * h over each step."""

from pythonfmu3 import Float64, Fmi3Causality, Fmi3Slave, Fmi3Variability


class Integrator3(Fmi3Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.time = 0.0
        self.k = 2.0
        self.u = 0.0
        self.y = 0.0
        self.register_variable(
            Float64("time", causality=Fmi3Causality.independent, variability=Fmi3Variability.continuous)
        )
        self.register_variable(Float64("k", causality=Fmi3Causality.parameter, variability=Fmi3Variability.tunable))
        self.register_variable(Float64("u", causality=Fmi3Causality.input))
        self.register_variable(Float64("y", causality=Fmi3Causality.output))

    def do_step(self, current_time, step_size):
        self.y += self.k * self.u * step_size
        return True
