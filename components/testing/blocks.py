"""Small components with closed-form behaviour, for tests, benchmarks and examples."""

from __future__ import annotations

import os
import signal
import time

import numpy as np

from components.constants import NS_PER_S
from components.sdk import Component, Parameter, Variable


class Counter(Component):
    """Counts its steps."""

    type_name = "test.counter"
    variables = (Variable("n", "output", (), "1", 0.0, "number of steps done"),)

    def __init__(self, params, run):
        self.n = 0

    def initialize(self, t0_ns, inputs):
        return {"n": self.n}

    def do_step(self, t_ns, h_ns, inputs):
        self.n += 1
        return {"n": self.n}

    def get_state(self):
        return {"n": np.int64(self.n)}

    def set_state(self, state):
        self.n = int(state["n"])


class Constant(Component):
    """Outputs a constant."""

    type_name = "test.constant"
    parameters = (Parameter("value", "float", unit="1", description="the constant output"),)

    @classmethod
    def declare(cls, params, run):
        return [Variable("y", "output", (), "1", params["value"], "the parameter value")]

    def __init__(self, params, run):
        self.value = params["value"]

    def initialize(self, t0_ns, inputs):
        return {"y": self.value}

    def do_step(self, t_ns, h_ns, inputs):
        return {"y": self.value}

    def get_state(self):
        return {}

    def set_state(self, state):
        pass


class Integrator(Component):
    """x' = gain * u by explicit Euler: x(t + h) = x(t) + gain * u * h."""

    type_name = "test.integrator"
    parameters = (
        Parameter("gain", "float", unit="1", default=1.0, description="multiplies u"),
        Parameter("x0", "float", unit="1", default=0.0, description="initial value of x"),
    )

    @classmethod
    def declare(cls, params, run):
        return [
            Variable("u", "input", (), "1", 0.0, "rate (held over the step)"),
            Variable("x", "output", (), "1", params["x0"], "integral of gain * u"),
            Variable(
                "u_time",
                "output",
                (),
                "s",
                0.0,
                "when the u it last stepped on was sampled (input_times_ns; t if unconnected)",
            ),
        ]

    def __init__(self, params, run):
        self.gain, self.x = params["gain"], params["x0"]

    def initialize(self, t0_ns, inputs):
        return {"x": self.x, "u_time": self.input_times_ns.get("u", t0_ns) / NS_PER_S}

    def do_step(self, t_ns, h_ns, inputs):
        self.x += self.gain * float(inputs["u"]) * (h_ns / NS_PER_S)
        return {"x": self.x, "u_time": self.input_times_ns.get("u", t_ns) / NS_PER_S}

    def get_state(self):
        return {"x": np.float64(self.x)}

    def set_state(self, state):
        self.x = float(state["x"])


class NoOp(Component):
    """Does nothing with a small input and output vector; for measuring the lockstep overhead."""

    type_name = "test.noop"
    parameters = (Parameter("size", "int", default=1, description="length of u and y"),)

    @classmethod
    def declare(cls, params, run):
        n = params["size"]
        return [Variable("u", "input", (n,), "1", 0.0, "ignored"), Variable("y", "output", (n,), "1", 0.0, "zeros")]

    def __init__(self, params, run):
        self.y = np.zeros(params["size"])

    def initialize(self, t0_ns, inputs):
        return {"y": self.y}

    def do_step(self, t_ns, h_ns, inputs):
        return {"y": self.y}

    def get_state(self):
        return {}

    def set_state(self, state):
        pass


class Faulty(Component):
    """Misbehaves at a chosen step, to test how the orchestrator handles failures.

    State: the number of steps done (a restored instance misbehaves at the same step).
    """

    type_name = "test.faulty"
    parameters = (
        Parameter("fault", "str", choices=("raise", "exit", "kill", "hang", "nan"), description="what goes wrong"),
        Parameter("at_step", "int", description="the step (0-based) at which it goes wrong"),
    )

    variables = (Variable("y", "output", (), "1", 0.0, "the step count, or NaN at the faulty step with fault: nan"),)

    def __init__(self, params, run):
        self.fault, self.at_step, self.k = params["fault"], params["at_step"], 0

    def initialize(self, t0_ns, inputs):
        return {"y": 0.0}

    def do_step(self, t_ns, h_ns, inputs):
        if self.k == self.at_step:
            if self.fault == "raise":
                raise RuntimeError(f"deliberate failure at step {self.k}")
            if self.fault == "exit":
                os._exit(3)
            if self.fault == "kill":
                os.kill(os.getpid(), signal.SIGKILL)
            if self.fault == "hang":
                while True:
                    time.sleep(1.0)
            if self.fault == "nan":
                return {"y": float("nan")}
        self.k += 1
        return {"y": float(self.k)}

    def get_state(self):
        return {"k": np.int64(self.k)}

    def set_state(self, state):
        self.k = int(state["k"])


class Imager(Component):
    """Makes an image and a depth frame each step (frame variables) from its input and its step
    count, every pixel different: ``rgb[i, j, c] = (n + 3 i + 5 j + 7 c + floor(1000 u)) mod 256``,
    ``depth[i, j] = u + n + (i W + j) / 2^16`` (float32), n the frames made so far (0 at initialize).
    """

    type_name = "test.imager"
    parameters = (
        Parameter("width", "int", description="frame width (pixels)"),
        Parameter("height", "int", description="frame height (pixels)"),
    )

    @classmethod
    def declare(cls, params, run):
        h, w = params["height"], params["width"]
        return [
            Variable("u", "input", (), "1", 0.0, "shifts every pixel"),
            Variable("rgb", "output", (h, w, 3), "1", 0, "the image", frame=True, dtype="uint8"),
            Variable("depth", "output", (h, w), "m", 0, "the depth", frame=True, dtype="float32"),
            Variable("n", "output", (), "1", 0.0, "frames made so far"),
        ]

    def __init__(self, params, run):
        h, w = params["height"], params["width"]
        i, j, c = np.meshgrid(np.arange(h), np.arange(w), np.arange(3), indexing="ij")
        self.pattern = 3 * i + 5 * j + 7 * c
        self.ramp = np.arange(h * w).reshape(h, w) / 65536.0
        self.n = 0

    def _outputs(self, u: float):
        rgb = ((self.n + self.pattern + int(np.floor(1000.0 * u))) % 256).astype(np.uint8)
        return {"rgb": rgb, "depth": (u + self.n + self.ramp).astype(np.float32), "n": float(self.n)}

    def initialize(self, t0_ns, inputs):
        return self._outputs(float(inputs["u"]))

    def do_step(self, t_ns, h_ns, inputs):
        self.n += 1
        return self._outputs(float(inputs["u"]))


class ImageSum(Component):
    """Reads an image and a depth frame (frame inputs): ``s``, the image's pixels weighted by
    their index (so a pixel out of place changes it) mod 1, and ``d``, the depth's sum; ``t_image``
    when the image was made (its ``input_times_ns``).
    """

    type_name = "test.image_sum"
    parameters = (
        Parameter("width", "int", description="frame width (pixels)"),
        Parameter("height", "int", description="frame height (pixels)"),
    )

    @classmethod
    def declare(cls, params, run):
        h, w = params["height"], params["width"]
        return [
            Variable("rgb", "input", (h, w, 3), "1", 0, "an image", frame=True, dtype="uint8"),
            Variable("depth", "input", (h, w), "m", 0, "a depth", frame=True, dtype="float32"),
            Variable("s", "output", (), "1", 0.0, "the weighted pixel sum, mod 1"),
            Variable("d", "output", (), "m", 0.0, "the depth's sum"),
            Variable("t_image", "output", (), "s", 0.0, "when the image was made"),
        ]

    def __init__(self, params, run):
        self.weights = np.arange(params["height"] * params["width"] * 3, dtype=np.float64) + 1.0

    def _outputs(self, inputs):
        rgb, depth = inputs["rgb"], inputs["depth"]
        s = float(self.weights @ rgb.ravel().astype(np.float64)) / 9973.0 % 1.0
        t = self.input_times_ns.get("rgb", 0) / NS_PER_S
        return {"s": s, "d": float(depth.astype(np.float64).sum()), "t_image": t}

    def initialize(self, t0_ns, inputs):
        return self._outputs(inputs)

    def do_step(self, t_ns, h_ns, inputs):
        if inputs["rgb"].flags.writeable:
            raise ValueError("a frame input must be read-only")
        return self._outputs(inputs)

    def get_state(self):
        return {}

    def set_state(self, state):
        pass
