"""Sensor component types: ``sensor.imu``, ``sensor.force_torque``, ``sensor.relative_pose``,
``sensor.magnetometer``.

Each maps true quantities (inputs, from the dynamics or a frame transform) to measurements
(outputs) with the noise models of :mod:`components.noise`.

Rate: one sample per step of the component, its own ``step:`` in the config (an integer multiple
of run.step; its outputs hold in between). ``do_step(t, h)`` samples the inputs it holds (the
truth at t, or when ``input_times_ns`` says) and its outputs at t + h are that sample (after the
latency, for ``sensor.relative_pose``). ``initialize`` takes no sample: the outputs hold their
start values until the first step (``sensor.relative_pose`` says so with ``valid``).

Noise: seeded, never from the wall clock. The k-th step (k = 0, 1, ... from the start) draws a
fixed block of standard normals from ``numpy.random.Generator(PCG64(seed))``, in a fixed order,
whatever the sigmas: the noise of step k depends only on the seed and k, the same seed replays
the same noise bit for bit, and the same seed with other sigmas gives the same draws scaled
(common random numbers across experiments). White-noise sigmas are 1-sigma per sample (not
densities): the same sigma at another step gives the same per-sample spread. The generator's
state is part of ``get_state``, so a restored instance draws what the original would have.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from components.constants import NS_PER_S
from components.errors import ConfigError
from components.noise import (
    BiasRandomWalk,
    LatencyBuffer,
    NormalStream,
    latency_samples,
    normalized,
    per_axis,
    perturb_quaternion,
    white,
)
from components.rotations import continuous
from components.schema import Duration, Float, Int, OneOf, Vector
from components.sdk import Component, Parameter, RunSettings, Variable
from components.sensors import ros as sensor_ros
from components.sensors.plots import measured_against_true
from components.sensors.view import SensorView
from components.units import DEG

# --------------------------------------------------------------------------- shared declarations


def _seed() -> Parameter:
    return Parameter(
        "seed",
        Int(minimum=0),
        description="seed of the noise (numpy PCG64): the same seed replays the same noise bit for bit",
    )


def _sigma(name: str, unit: str, what: str, plausible: tuple[float, float], default: Any = ...) -> Parameter:
    kind = OneOf((Float(unit, minimum=0.0, plausible=plausible), Vector(3, unit, minimum=0.0, plausible=plausible)))
    description = f"{what}: 1-sigma per sample, one for every axis or one per axis (0: none)"
    if default is ...:
        return Parameter(name, kind, description=description)
    return Parameter(name, kind, default=default, description=description)


def _bias(name: str, unit: str, what: str, plausible: tuple[float, float], default: Any = ...) -> Parameter:
    kind = OneOf((Float(unit, plausible=plausible), Vector(3, unit, plausible=plausible)))
    description = f"{what}: added to every sample, one for every axis or one per axis"
    if default is ...:
        return Parameter(name, kind, description=description)
    return Parameter(name, kind, default=default, description=description)


class _SeededSensor(Component):
    """Shared plumbing: the seeded normal stream, ``DRAWS`` normals per step."""

    #: Its measurements: output -> the input it measures (its plot and its view show them side by side).
    measures: ClassVar[Mapping[str, str]]

    DRAWS = 0

    def __init__(self, params: Mapping[str, Any], run: RunSettings):
        self.params = params
        self.stream = NormalStream(params["seed"])

    def _draw(self) -> np.ndarray:
        return self.stream.draw(self.DRAWS)

    def _base_state(self) -> dict[str, Any]:
        return {"rng": self.stream.get_state()}

    def _set_base_state(self, state: Mapping[str, Any]) -> None:
        self.stream.set_state(state["rng"])


# --------------------------------------------------------------------------- IMU


class ImuComponent(_SeededSensor):
    """An inertial measurement unit (type ``sensor.imu``): gyro and accelerometer, body axes.

    ``rate = rate_true + b_g + n_g`` and ``specific_force = specific_force_true + b_a + n_a``,
    with white noise n (``rate_noise``, ``accel_noise``: 1-sigma per sample) and biases b that
    start at ``rate_bias``, ``accel_bias`` and walk by ``rate_bias_walk``, ``accel_bias_walk``
    (1-sigma increment per sample; 0, the default: constant). The sample of step k uses the
    biases before that step's increment. Specific force is the non-gravitational acceleration
    (an accelerometer at rest on the ground reads +g up; in free fall it reads 0).

    Draws per step: 12 normals, gyro noise (3), accelerometer noise (3), gyro bias increment (3),
    accelerometer bias increment (3). State: the generator and the current biases.
    """

    type_name = "sensor.imu"
    measures: ClassVar[Mapping[str, str]] = {"rate": "rate_true", "specific_force": "specific_force_true"}
    plots = (measured_against_true(measures),)
    view = SensorView
    rosbag = sensor_ros.IMU
    parameters = (
        _seed(),
        # plausible: what a MEMS gyro and accelerometer give at most, a sample at a time
        _sigma("rate_noise", "rad/s", "gyro white noise", (0.0, 10 * DEG)),
        _bias("rate_bias", "rad/s", "gyro bias (its start value when it walks)", (-10 * DEG, 10 * DEG)),
        _sigma("rate_bias_walk", "rad/s", "gyro bias random walk, the increment", (0.0, 1 * DEG), default=0.0),
        _sigma("accel_noise", "m/s^2", "accelerometer white noise", (0.0, 1.0)),
        _bias("accel_bias", "m/s^2", "accelerometer bias (its start value when it walks)", (-1.0, 1.0)),
        _sigma("accel_bias_walk", "m/s^2", "accelerometer bias random walk, the increment", (0.0, 0.1), default=0.0),
    )
    variables = (
        Variable("rate_true", "input", (3,), "rad/s", [0.0] * 3, "true angular rate of the body, body axes"),
        Variable(
            "specific_force_true",
            "input",
            (3,),
            "m/s^2",
            [0.0] * 3,
            "true specific force (non-gravitational acceleration), body axes",
        ),
        Variable(
            "rate", "output", (3,), "rad/s", [0.0] * 3, "measured angular rate, body axes (0 until the first step)"
        ),
        Variable(
            "specific_force",
            "output",
            (3,),
            "m/s^2",
            [0.0] * 3,
            "measured specific force, body axes (0 until the first step)",
        ),
    )
    DRAWS = 12

    def __init__(self, params, run):
        super().__init__(params, run)
        self.rate_noise, self.accel_noise = per_axis(params["rate_noise"]), per_axis(params["accel_noise"])
        self.gyro_bias = BiasRandomWalk(per_axis(params["rate_bias"]), per_axis(params["rate_bias_walk"]))
        self.accel_bias = BiasRandomWalk(per_axis(params["accel_bias"]), per_axis(params["accel_bias_walk"]))
        self.out = {"rate": np.zeros(3), "specific_force": np.zeros(3)}

    def initialize(self, t0_ns, inputs):
        return self.out

    def do_step(self, t_ns, h_ns, inputs):
        z = self._draw()
        rate = inputs["rate_true"] + self.gyro_bias.bias + white(self.rate_noise, z[0:3])
        force = inputs["specific_force_true"] + self.accel_bias.bias + white(self.accel_noise, z[3:6])
        self.gyro_bias.advance(z[6:9])
        self.accel_bias.advance(z[9:12])
        self.out = {"rate": rate, "specific_force": force}
        return self.out

    def get_state(self):
        return {
            **self._base_state(),
            "rate_bias": self.gyro_bias.bias.copy(),
            "accel_bias": self.accel_bias.bias.copy(),
        }

    def set_state(self, state):
        self._set_base_state(state)
        self.gyro_bias.bias = np.array(state["rate_bias"], dtype=np.float64).reshape(3)
        self.accel_bias.bias = np.array(state["accel_bias"], dtype=np.float64).reshape(3)


# --------------------------------------------------------------------------- force/torque


class ForceTorqueComponent(_SeededSensor):
    """A six-axis force/torque sensor (type ``sensor.force_torque``), sensor axes.

    ``wrench = wrench_true + [force_bias, torque_bias] + n`` with white noise n (``force_noise``,
    ``torque_noise``: 1-sigma per sample). The wrench is the force (N), then the torque (N m)
    about the sensor origin, both in sensor axes.

    Draws per step: 6 normals, force noise (3), torque noise (3). State: the generator.
    """

    type_name = "sensor.force_torque"
    measures: ClassVar[Mapping[str, str]] = {"wrench": "wrench_true"}
    plots = (measured_against_true(measures),)
    view = SensorView
    rosbag = sensor_ros.FORCE_TORQUE
    parameters = (
        _seed(),
        _sigma("force_noise", "N", "force white noise", (0.0, 1e3)),
        _sigma("torque_noise", "N*m", "torque white noise", (0.0, 1e3)),
        _bias("force_bias", "N", "force bias", (-1e3, 1e3), default=0.0),
        _bias("torque_bias", "N*m", "torque bias", (-1e3, 1e3), default=0.0),
    )
    variables = (
        Variable(
            "wrench_true",
            "input",
            (6,),
            "N, N*m",
            [0.0] * 6,
            "true force (N), then torque (N m) about the sensor origin, sensor axes",
        ),
        Variable(
            "wrench",
            "output",
            (6,),
            "N, N*m",
            [0.0] * 6,
            "measured force, then torque, sensor axes (0 until the first step)",
        ),
    )
    DRAWS = 6

    def __init__(self, params, run):
        super().__init__(params, run)
        self.sigma = np.concatenate([per_axis(params["force_noise"]), per_axis(params["torque_noise"])])
        self.bias = np.concatenate([per_axis(params["force_bias"]), per_axis(params["torque_bias"])])
        self.out = np.zeros(6)

    def initialize(self, t0_ns, inputs):
        return {"wrench": self.out}

    def do_step(self, t_ns, h_ns, inputs):
        z = self._draw()
        self.out = inputs["wrench_true"] + self.bias + white(self.sigma, z)
        return {"wrench": self.out}

    def get_state(self):
        return self._base_state()

    def set_state(self, state):
        self._set_base_state(state)


# --------------------------------------------------------------------------- relative pose


class RelativePoseComponent(_SeededSensor):
    """A relative pose sensor (type ``sensor.relative_pose``: a camera with pose estimation, a
    lidar): the target frame's pose in the sensor frame, noisy and late.

    A sample is ``p_true + n_p`` (``position_noise``, 1-sigma per axis, sensor axes) and
    ``q_true * exp(phi)`` normalized, phi a small rotation vector of 1-sigma ``angle_noise`` per
    axis in target axes (the angle between q_true and the sample has an RMS of sqrt(3) sigma for
    one sigma on every axis). The step at t publishes the sample taken ``latency`` before (at
    the step t - latency: a latency of 0 publishes the sample of the step itself); its
    ``t_measured`` is when that sample's ``p_true`` was sampled (``input_times_ns``: t under
    Jacobi). ``latency`` must be a whole number of the component's own steps; the component
    learns its step at its first ``do_step`` and stops there with a ConfigError naming
    ``latency`` otherwise. Until the first sample has come through (``valid`` 0), p, q and
    t_measured hold their start values. ``q`` is sign-continuous from one output to the next
    (the first one has the sign of its sample).

    Draws per step: 6 normals, position noise (3), rotation noise (3). State: the generator, the
    step it learnt, the samples in the latency pipeline and the last outputs.
    """

    type_name = "sensor.relative_pose"
    measures: ClassVar[Mapping[str, str]] = {"p": "p_true", "q": "q_true"}
    plots = (measured_against_true(measures),)
    view = SensorView
    rosbag = sensor_ros.RELATIVE_POSE
    parameters = (
        _seed(),
        _sigma("position_noise", "m", "position white noise, sensor axes", (0.0, 1.0)),
        _sigma("angle_noise", "rad", "rotation white noise, a small rotation vector in target axes", (0.0, 10 * DEG)),
        Parameter(
            "latency",
            Duration(positive=False, plausible=(0.0, 10.0)),
            description="age of a measurement when published, a whole number of the component's steps (0 allowed)",
        ),
    )
    variables = (
        Variable("p_true", "input", (3,), "m", [0.0] * 3, "true position of the target frame's origin, sensor frame"),
        Variable("q_true", "input", (4,), "1", [0.0, 0.0, 0.0, 1.0], "true q_sensor_target [x, y, z, w]"),
        Variable("p", "output", (3,), "m", [0.0] * 3, "measured position of the target, sensor frame"),
        Variable(
            "q",
            "output",
            (4,),
            "1",
            [0.0, 0.0, 0.0, 1.0],
            "measured q_sensor_target [x, y, z, w], unit, sign-continuous",
        ),
        Variable("t_measured", "output", (), "s", 0.0, "when the published measurement was taken (before latency)"),
        Variable("valid", "output", (), "1", 0.0, "1 once a measurement has come through the latency, else 0"),
    )
    DRAWS = 6

    @classmethod
    def preflight(cls, params, run, step_s, full=False):
        """The latency must be a whole number of the component's steps: refused before the run
        (check and run alike), not at its first step."""
        latency_samples(int(params["latency"]), round(step_s * NS_PER_S), "latency")
        return []

    def __init__(self, params, run):
        super().__init__(params, run)
        self.position_noise, self.angle_noise = per_axis(params["position_noise"]), per_axis(params["angle_noise"])
        self.latency_ns = int(params["latency"])
        self.step_ns = 0  # learnt at the first do_step
        self.pipeline = LatencyBuffer(7)  # p (3), q (4)
        self.p, self.q = np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0])
        self.t_measured_ns, self.valid = 0, False

    def _outputs(self) -> dict[str, Any]:
        return {"p": self.p, "q": self.q, "t_measured": self.t_measured_ns / NS_PER_S, "valid": float(self.valid)}

    def initialize(self, t0_ns, inputs):
        return self._outputs()

    def do_step(self, t_ns, h_ns, inputs):
        if self.step_ns == 0:
            self.pipeline.delay = latency_samples(self.latency_ns, h_ns, "latency")
            self.step_ns = h_ns
        elif h_ns != self.step_ns:
            raise ConfigError(
                "latency",
                f"counted in steps of {self.step_ns} ns, but this step is {h_ns} ns: "
                "a relative_pose sensor needs a constant step",
            )
        z = self._draw()
        p = inputs["p_true"] + white(self.position_noise, z[0:3])
        q = perturb_quaternion(normalized(inputs["q_true"], "q_true"), white(self.angle_noise, z[3:6]))
        taken = self.input_times_ns.get("p_true", t_ns)
        out = self.pipeline.push(taken, np.concatenate([p, q]))
        if out is not None:
            self.t_measured_ns, sample = out
            self.p = sample[0:3].copy()
            self.q = continuous(sample[3:7], self.q if self.valid else None)
            self.valid = True
        return self._outputs()

    def get_state(self):
        return {
            **self._base_state(),
            **self.pipeline.get_state("pipeline_"),
            "step_ns": np.int64(self.step_ns),
            "p": self.p.copy(),
            "q": self.q.copy(),
            "t_measured_ns": np.int64(self.t_measured_ns),
            "valid": np.bool_(self.valid),
        }

    def set_state(self, state):
        self._set_base_state(state)
        self.pipeline.set_state(state, "pipeline_")
        self.step_ns = int(state["step_ns"])
        self.p = np.array(state["p"], dtype=np.float64).reshape(3)
        self.q = np.array(state["q"], dtype=np.float64).reshape(4)
        self.t_measured_ns, self.valid = int(state["t_measured_ns"]), bool(state["valid"])


# --------------------------------------------------------------------------- magnetometer


class MagnetometerComponent(_SeededSensor):
    """A three-axis magnetometer (type ``sensor.magnetometer``), sensor (body) axes.

    ``b = b_true + bias + n``, white noise n (``noise``: 1-sigma per sample, T) and a constant
    ``bias`` (T). Its ``b_true`` is the dynamics' ``<body>.b_body`` (the Earth's field at the
    base origin, base axes: components/dynamics/magnetic.py). Rate: the component's own step.

    Draws per step: 3 normals, the noise. State: the generator.
    """

    type_name = "sensor.magnetometer"
    measures: ClassVar[Mapping[str, str]] = {"b": "b_true"}
    plots = (measured_against_true(measures),)
    view = SensorView
    parameters = (
        _seed(),
        # plausible: a spacecraft magnetometer's noise is 0.1-100 nT; its bias up to a few uT
        _sigma("noise", "T", "white noise", (0.0, 1e-5)),
        _bias("bias", "T", "bias", (-1e-4, 1e-4), default=0.0),
    )
    variables = (
        Variable("b_true", "input", (3,), "T", [0.0] * 3, "true magnetic field, sensor axes"),
        Variable("b", "output", (3,), "T", [0.0] * 3, "measured magnetic field, sensor axes (0 until the first step)"),
    )
    DRAWS = 3

    def __init__(self, params, run):
        super().__init__(params, run)
        self.sigma, self.bias = per_axis(params["noise"]), per_axis(params["bias"])
        self.out = np.zeros(3)

    def initialize(self, t0_ns, inputs):
        return {"b": self.out}

    def do_step(self, t_ns, h_ns, inputs):
        self.out = inputs["b_true"] + self.bias + white(self.sigma, self._draw())
        return {"b": self.out}

    def get_state(self):
        return self._base_state()

    def set_state(self, state):
        self._set_base_state(state)
