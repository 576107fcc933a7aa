"""A reaction wheel as a pythonfmu model: torque command in, wheel speed and torques out.

The motor follows the command through a first-order lag (time constant ``time_constant``),
clipped to ``max_torque``; at ``max_speed`` it gives no more torque that would spin the wheel
faster. The wheel speed is inertial, integrated from the motor torque held over each step (the
torque the dynamics applies over that step under Jacobi). Outputs at the end of a step:
``motor_torque`` (on the wheel, N m), ``reaction_torque`` (on the bus, -motor_torque, N m) and
``wheel_speed`` (rad/s).

Build the FMU (pythonfmu, nothing compiled; the state is the registered variables):

    python models/reaction_wheel.py -o reaction_wheel.fmu

A config may also name this file as the FMU's path: Zenorbit builds it on first use.
"""

import math
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class Quantity(Real):
    """A Real with a unit (pythonfmu writes none)."""

    def __init__(self, name, unit, **kwargs):
        super().__init__(name, **kwargs)
        self.unit = unit

    def to_xml(self) -> Element:
        node = super().to_xml()
        node.find("Real").set("unit", self.unit)
        return node


class ReactionWheel(Fmi2Slave):
    author = "Zenorbit"
    description = "Reaction wheel: lagged, torque- and speed-limited motor on a spinning inertia"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.inertia = 0.05  # kg m^2, spin axis
        self.max_torque = 0.2  # N m
        self.max_speed = 600.0  # rad/s
        self.time_constant = 0.05  # s
        self.torque_command = 0.0  # N m
        self.motor_torque = 0.0
        self.reaction_torque = 0.0
        self.wheel_speed = 0.0  # rad/s, also the initial speed
        for name, unit, what in (
            ("inertia", "kg.m2", "wheel spin inertia"),
            ("max_torque", "N.m", "motor torque limit"),
            ("max_speed", "rad/s", "wheel speed limit"),
            ("time_constant", "s", "motor torque lag"),
        ):
            self.register_variable(
                Quantity(
                    name, unit, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable, description=what
                )
            )
        self.register_variable(
            Quantity("torque_command", "N.m", causality=Fmi2Causality.input, description="commanded motor torque")
        )
        for name, unit, what in (
            ("motor_torque", "N.m", "torque of the motor on the wheel"),
            ("reaction_torque", "N.m", "torque on the bus about the wheel axis"),
            ("wheel_speed", "rad/s", "inertial wheel speed"),
        ):
            self.register_variable(Quantity(name, unit, causality=Fmi2Causality.output, description=what))

    def to_xml(self, model_options: dict[str, str] | None = None) -> Element:
        """The model description, with the UnitDefinitions FMI 2.0 requires for the units used."""
        root = super().to_xml(model_options or {})
        units = Element("UnitDefinitions")
        for unit in sorted({v.unit for v in self.vars.values() if isinstance(v, Quantity)}):
            SubElement(units, "Unit", name=unit)
        root.insert(list(root).index(root.find("CoSimulation")) + 1, units)
        return root

    def do_step(self, current_time, step_size):
        self.wheel_speed += self.motor_torque / self.inertia * step_size  # the torque held over the step
        target = max(-self.max_torque, min(self.max_torque, self.torque_command))
        self.motor_torque += (target - self.motor_torque) * (1.0 - math.exp(-step_size / self.time_constant))
        if abs(self.wheel_speed) >= self.max_speed and self.motor_torque * self.wheel_speed > 0.0:
            self.motor_torque = 0.0
        self.reaction_torque = -self.motor_torque
        return True


if __name__ == "__main__":
    import argparse
    import shutil
    import sys
    from pathlib import Path

    parser = argparse.ArgumentParser(description="Build the reaction wheel FMU (FMI 2.0 co-simulation).")
    parser.add_argument("-o", "--output", default="reaction_wheel.fmu", help="the .fmu to write")
    out = Path(parser.parse_args().output)
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from components.fmi.fmu_file import build_python_model

    shutil.copyfile(build_python_model(Path(__file__).resolve()), out)
    print(f"wrote {out}")
