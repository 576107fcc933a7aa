"""Sensor components through the in-process harness (and one config through the in-process run
loop): noise statistics against the declared sigmas, biases, the noise of step k equal to numpy's
PCG64 draws for the seed, replay from the same seed, state hand-over to a never-initialized
instance, the relative pose's latency, t_measured, valid and quaternion noise and continuity,
and bad parameters as ConfigErrors naming the key.

Statistical tolerances: 20000 samples give a relative standard error of 0.5 % on a standard
deviation and 0.3 % on an RMS angle, so the 3 % bounds are ~6 standard errors (the seeds are
fixed: the tests are deterministic anyway); a mean is held to 4 sigma / sqrt(N)."""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest

from components.bus import decode_state
from components.constants import NS_PER_S
from components.errors import ConfigError
from components.rotations import exp_so3, log_so3, matrix_to_quat, quat_to_matrix
from components.testing.harness import Harness

MS = 1_000_000
N = 20000

IMU = {
    "seed": 11,
    "rate_noise": [0.01, 0.02, 0.005],
    "rate_bias": [0.001, -0.002, 0.003],
    "accel_noise": "0.05 m/s^2",
    "accel_bias": -0.2,
}
FT = {
    "seed": 12,
    "force_noise": "0.5 N",
    "torque_noise": [0.02, 0.03, 0.04],
    "force_bias": [1.0, 0.0, -1.0],
    "torque_bias": "0.1 N*m",
}
POSE = {"seed": 13, "position_noise": "1 cm", "angle_noise": "0.5 deg", "latency": "30 ms"}


def run(h: Harness, steps: int, h_ns: int = 10 * MS, truth=None) -> dict[str, np.ndarray]:
    """Step ``steps`` times; ``truth(k)`` (a dict of inputs) before step k; outputs stacked by name."""
    out = {}
    for k in range(steps):
        if truth is not None:
            h.inputs.update(truth(k))
        for name, value in h.step(h_ns).items():
            out.setdefault(name, []).append(value)
    return {name: np.array(values) for name, values in out.items()}


def draws(seed: int, per_step: int, steps: int) -> np.ndarray:
    """The standard normals a sensor draws: ``per_step`` a step, from numpy's PCG64(seed)."""
    return np.random.Generator(np.random.PCG64(seed)).standard_normal(steps * per_step).reshape(steps, per_step)


def bit_equal(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(np.asarray(a[k]).tobytes() == np.asarray(b[k]).tobytes() for k in a)


# --------------------------------------------------------------------------- IMU

RATE = np.array([0.1, -0.05, 0.02])
FORCE = np.array([0.0, 0.3, -0.1])


def imu_truth(k):
    return {"rate_true": RATE, "specific_force_true": FORCE}


def test_imu_noise_and_bias_statistics_match_the_declared_sigmas():
    out = run(Harness("sensor.imu", IMU), N, truth=imu_truth)
    rate_error, force_error = out["rate"] - RATE, out["specific_force"] - FORCE
    assert np.allclose(rate_error.std(axis=0), IMU["rate_noise"], rtol=0.03)
    assert np.allclose(force_error.std(axis=0), 0.05, rtol=0.03)
    assert np.all(np.abs(rate_error.mean(axis=0) - IMU["rate_bias"]) < 4 * np.array(IMU["rate_noise"]) / math.sqrt(N))
    assert np.all(np.abs(force_error.mean(axis=0) + 0.2) < 4 * 0.05 / math.sqrt(N))


def test_imu_step_k_is_truth_plus_bias_plus_sigma_times_the_kth_draws():
    """The draws of step k: gyro noise, accelerometer noise, gyro and accelerometer bias increments."""
    params = {**IMU, "rate_bias_walk": "0.001 rad/s", "accel_bias_walk": [0.0, 0.01, 0.02]}
    steps = 50
    out = run(Harness("sensor.imu", params), steps, truth=imu_truth)
    z = draws(11, 12, steps)
    gyro_bias = np.array(IMU["rate_bias"]) + 0.001 * np.vstack([np.zeros(3), np.cumsum(z[:-1, 6:9], axis=0)])
    accel_bias = -0.2 + np.array([0.0, 0.01, 0.02]) * np.vstack([np.zeros(3), np.cumsum(z[:-1, 9:12], axis=0)])
    assert np.allclose(out["rate"], RATE + gyro_bias + np.array(IMU["rate_noise"]) * z[:, 0:3], rtol=0, atol=1e-15)
    assert np.allclose(out["specific_force"], FORCE + accel_bias + 0.05 * z[:, 3:6], rtol=0, atol=1e-15)


def test_imu_outputs_are_zero_until_the_first_step_and_initialize_draws_nothing():
    a, b = Harness("sensor.imu", IMU), Harness("sensor.imu", IMU)
    a.inputs.update(imu_truth(0))
    assert all(not v.any() for v in a.initialize().values())
    b.inputs.update(imu_truth(0))
    assert bit_equal(a.step(10 * MS), b.step(10 * MS))  # b never initialized by hand: same draws


def test_imu_with_zero_sigmas_is_truth_plus_bias():
    params = {"seed": 1, "rate_noise": 0, "rate_bias": 0, "accel_noise": "0 m/s^2", "accel_bias": [0.1, 0.2, 0.3]}
    out = run(Harness("sensor.imu", params), 5, truth=imu_truth)
    assert np.array_equal(out["rate"], np.tile(RATE, (5, 1)))
    assert np.array_equal(out["specific_force"], np.tile(FORCE + [0.1, 0.2, 0.3], (5, 1)))


# --------------------------------------------------------------------------- force/torque

WRENCH = np.array([10.0, -5.0, 2.0, 0.5, -0.2, 0.1])


def test_force_torque_noise_and_bias_statistics_match_the_declared_sigmas():
    out = run(Harness("sensor.force_torque", FT), N, truth=lambda k: {"wrench_true": WRENCH})
    error = out["wrench"] - WRENCH
    sigma = np.array([0.5, 0.5, 0.5, 0.02, 0.03, 0.04])
    bias = np.array([1.0, 0.0, -1.0, 0.1, 0.1, 0.1])
    assert np.allclose(error.std(axis=0), sigma, rtol=0.03)
    assert np.all(np.abs(error.mean(axis=0) - bias) < 4 * sigma / math.sqrt(N))
    z = draws(12, 6, N)
    assert np.allclose(out["wrench"], WRENCH + bias + sigma * z, rtol=0, atol=1e-13)


def test_force_torque_biases_default_to_zero():
    out = run(
        Harness("sensor.force_torque", {"seed": 3, "force_noise": 0, "torque_noise": 0}),
        3,
        truth=lambda k: {"wrench_true": WRENCH},
    )
    assert np.array_equal(out["wrench"], np.tile(WRENCH, (3, 1)))


# --------------------------------------------------------------------------- determinism and state


def pose_truth(k):
    """A tumbling target that approaches: q_true flips sign every step (the same rotation), to
    check that q stays sign-continuous."""
    q = matrix_to_quat(exp_so3(np.array([0.02, -0.01, 0.03]) * k))
    return {"p_true": np.array([2.0 - 0.01 * k, 0.1, -0.05]), "q_true": q * (-1.0) ** k}


CASES = [
    ("sensor.imu", IMU, imu_truth),
    ("sensor.force_torque", FT, lambda k: {"wrench_true": WRENCH * k}),
    ("sensor.relative_pose", POSE, pose_truth),
]


@pytest.mark.parametrize("type_name, params, truth", CASES)
def test_same_seed_replays_bit_for_bit_and_another_seed_differs(type_name, params, truth):
    a = run(Harness(type_name, params), 40, truth=truth)
    b = run(Harness(type_name, params), 40, truth=truth)
    c = run(Harness(type_name, {**params, "seed": params["seed"] + 1}), 40, truth=truth)
    assert bit_equal(a, b)
    measured = [k for k in a if k not in ("valid", "t_measured")]
    assert all(not np.array_equal(a[k], c[k]) for k in measured)


@pytest.mark.parametrize("type_name, params, truth", CASES)
@pytest.mark.parametrize("at", [0, 1, 2, 17])  # before the first step, inside and past the latency
def test_state_into_a_fresh_instance_continues_bit_for_bit(type_name, params, truth, at):
    if type_name == "sensor.imu":
        params = {**params, "rate_bias_walk": 1e-3, "accel_bias_walk": 1e-2}
    a = Harness(type_name, params)
    a.inputs.update(truth(0))
    a.initialize()
    run(a, at, truth=truth)
    blob = a.get_state()
    b = Harness(type_name, params, t0_ns=a.t_ns)  # constructed, never initialized
    b.set_state(blob)
    state_a, state_b = decode_state(blob), decode_state(b.get_state())
    assert sorted(state_a) == sorted(state_b)
    assert all(state_a[k].dtype == state_b[k].dtype and state_a[k].tobytes() == state_b[k].tobytes() for k in state_a)
    shifted = lambda k: truth(k + at)  # noqa: E731
    assert bit_equal(run(a, 30, truth=shifted), run(b, 30, truth=shifted))
    assert a.get_state() == b.get_state()


# --------------------------------------------------------------------------- relative pose

EXACT = {"seed": 5, "position_noise": 0, "angle_noise": 0}


@pytest.mark.parametrize("step_ms, latency_ms", [(10, 0), (10, 30), (1, 200), (100, 200)])
def test_latency_publishes_the_truth_of_latency_over_step_steps_before(step_ms, latency_ms):
    n = latency_ms // step_ms
    steps = n + 12
    h = Harness("sensor.relative_pose", {**EXACT, "latency": f"{latency_ms} ms"})
    start = h.initialize()
    assert start["valid"] == 0 and start["p"].tolist() == [0.0] * 3 and start["q"].tolist() == [0, 0, 0, 1]
    out = run(h, steps, h_ns=step_ms * MS, truth=pose_truth)
    assert out["valid"].tolist() == [0.0] * n + [1.0] * (steps - n)  # valid from step n on
    assert not out["p"][:n].any() and np.all(out["q"][:n] == [0, 0, 0, 1]) and not out["t_measured"][:n].any()
    for k in range(n, steps):
        truth = pose_truth(k - n)
        assert np.array_equal(out["p"][k], truth["p_true"])
        assert np.allclose(out["q"][k], truth["q_true"] * np.sign(out["q"][k] @ truth["q_true"]), rtol=0, atol=1e-15)
        assert out["t_measured"][k] == (k - n) * step_ms * MS / NS_PER_S


def test_t_measured_is_when_the_truth_was_sampled():
    """Under Gauss-Seidel the dynamics' output at the end of its step feeds this step: the
    measurement is of t + h, and t_measured says so."""
    h = Harness("sensor.relative_pose", {**EXACT, "latency": "20 ms"})
    times = []
    for _k in range(6):
        h.input_times_ns = {"p_true": h.t_ns + 10 * MS, "q_true": h.t_ns + 10 * MS}
        times.append(float(h.step(10 * MS)["t_measured"]))
    assert times == [0.0, 0.0, 0.01, 0.02, 0.03, 0.04]


def test_q_is_unit_and_sign_continuous_when_the_truth_flips_sign():
    out = run(Harness("sensor.relative_pose", POSE), 300, truth=pose_truth)
    q = out["q"][out["valid"] == 1]
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, rtol=0, atol=1e-15)
    assert np.all(np.einsum("ij,ij->i", q[1:], q[:-1]) > 0.9)
    first = pose_truth(0)["q_true"]
    assert q[0] @ first > 0  # the first one keeps the sign of its sample


def test_q_noise_rms_angle_is_sqrt3_sigma_and_position_noise_matches():
    sigma = math.radians(0.5)
    out = run(Harness("sensor.relative_pose", {**POSE, "latency": 0}), N, truth=lambda k: pose_truth(7))
    truth = pose_truth(7)
    R_true = quat_to_matrix(truth["q_true"])
    angles = np.array([np.linalg.norm(log_so3(R_true.T @ quat_to_matrix(q))) for q in out["q"]])
    assert math.sqrt(np.mean(angles**2)) == pytest.approx(math.sqrt(3) * sigma, rel=0.03)
    # the rotation vectors, in target axes, have sigma on each axis
    phis = np.array([log_so3(R_true.T @ quat_to_matrix(q)) for q in out["q"][:4000]])
    assert np.allclose(phis.std(axis=0), sigma, rtol=0.05)
    assert np.allclose((out["p"] - truth["p_true"]).std(axis=0), 0.01, rtol=0.03)
    assert np.all(np.abs((out["p"] - truth["p_true"]).mean(axis=0)) < 4 * 0.01 / math.sqrt(N))


def test_latency_that_is_not_a_multiple_of_the_step_is_a_config_error_naming_it():
    h = Harness("sensor.relative_pose", {**EXACT, "latency": "25 ms"})
    h.initialize()
    with pytest.raises(ConfigError) as error:
        h.step(10 * MS)
    assert error.value.key == "latency"
    assert "multiple of the component's step (10 ms" in str(error.value) and "got 25 ms" in str(error.value)


def test_a_step_that_changes_is_refused():
    h = Harness("sensor.relative_pose", {**EXACT, "latency": "20 ms"})
    h.step(10 * MS)
    with pytest.raises(ConfigError, match="constant step"):
        h.step(20 * MS)


def test_a_q_true_that_is_no_rotation_says_so():
    h = Harness("sensor.relative_pose", {**EXACT, "latency": 0})
    h.inputs["q_true"] = [0.0, 0.0, 0.0, 0.0]
    with pytest.raises(ValueError, match="q_true"):
        h.step(10 * MS)


# --------------------------------------------------------------------------- in a run


def test_in_a_run_at_its_own_slower_step_it_equals_the_harness(tmp_path):
    """run.step 1 ms, the sensor's step 10 ms, latency 30 ms: its outputs hold between its
    steps, the sample of its step at 0 is published by its step at 30 ms and recorded from
    t = 40 ms (the end of that step) on; the values equal the harness stepped at 10 ms."""
    from orchestrator.config.load import load
    from orchestrator.config.yaml_file import ConfigErrors
    from orchestrator.run.inprocess import run_in_process

    config = tmp_path / "sensor.yaml"
    config.write_text(
        textwrap.dedent("""\
        run: {name: sensor, epoch: 2022-09-18T12:00:00Z, duration: 100 ms, step: 1 ms}
        components:
          camera:
            type: sensor.relative_pose
            step: 10 ms
            parameters: {seed: 3, position_noise: 1 cm, angle_noise: 1 deg, latency: 30 ms}
        """)
    )
    rows = run_in_process(load(config))
    valid, t_measured, p = rows[:, 8], rows[:, 7], rows[:, 0:3]
    assert valid.tolist() == [0.0] * 40 + [1.0] * 61
    assert t_measured[40:50].tolist() == [0.0] * 10 and t_measured[50] == 0.01 and t_measured[100] == 0.06
    h = Harness(
        "sensor.relative_pose", {"seed": 3, "position_noise": "1 cm", "angle_noise": "1 deg", "latency": "30 ms"}
    )
    reference = run(h, 10)
    assert np.array_equal(rows[10::10, 0:3], reference["p"]) and np.array_equal(rows[10::10, 3:7], reference["q"])
    assert np.array_equal(p[41:50], np.tile(p[40], (9, 1)))  # held between its steps

    bad = tmp_path / "bad.yaml"
    bad.write_text(config.read_text().replace("latency: 30 ms", "latency: 35 ms"))
    with pytest.raises(
        ConfigErrors,
        match=r"components\.camera\.parameters\.latency: must be a non-negative integer multiple of the component's step",
    ):
        load(bad)  # refused before the run (check and run alike), not at its first step


# --------------------------------------------------------------------------- bad parameters


@pytest.mark.parametrize(
    "type_name, params, change, key, message",
    [
        ("sensor.imu", IMU, {"rate_noise": -0.1}, "rate_noise", ">= 0"),
        ("sensor.imu", IMU, {"accel_noise": [0.1, -0.1, 0.1]}, "accel_noise[1]", ">= 0"),
        ("sensor.imu", IMU, {"rate_bias": [0.1, 0.2]}, "rate_bias", "expected 3 values, got 2"),
        ("sensor.imu", IMU, {"seed": None}, "seed", "missing required parameter"),
        ("sensor.imu", IMU, {"seed": 1.5}, "seed", "expected an integer"),
        ("sensor.imu", IMU, {"seed": -1}, "seed", ">= 0"),
        ("sensor.imu", IMU, {"accel_noise": None}, "accel_noise", "missing required parameter"),
        ("sensor.imu", IMU, {"rate_bias": None}, "rate_bias", "missing required parameter"),
        ("sensor.imu", IMU, {"rate_noise": "1 m/s"}, "rate_noise", "does not measure rad/s"),
        ("sensor.imu", IMU, {"rate_bias_walk": -1.0}, "rate_bias_walk", ">= 0"),
        ("sensor.force_torque", FT, {"torque_noise": "1 N"}, "torque_noise", "does not measure N*m"),
        ("sensor.force_torque", FT, {"force_bias": [1, 2, 3, 4]}, "force_bias", "expected 3 values, got 4"),
        ("sensor.force_torque", FT, {"force_noise": None}, "force_noise", "missing required parameter"),
        ("sensor.relative_pose", POSE, {"latency": "-10 ms"}, "latency", ">= 0"),
        ("sensor.relative_pose", POSE, {"latency": None}, "latency", "missing required parameter"),
        ("sensor.relative_pose", POSE, {"angle_noise": -0.01}, "angle_noise", ">= 0"),
        ("sensor.relative_pose", POSE, {"position_noise": [0.1, 0.1]}, "position_noise", "expected 3 values, got 2"),
        ("sensor.relative_pose", POSE, {"range": 3.0}, "range", "unknown parameter"),
    ],
)
def test_bad_parameters_are_config_errors_naming_the_key(type_name, params, change, key, message):
    params = {k: v for k, v in {**params, **change}.items() if v is not None}
    with pytest.raises(ConfigError) as error:
        Harness(type_name, params)
    assert error.value.key == key and message in error.value.message


def test_wrong_input_shape_is_refused_naming_the_input():
    h = Harness("sensor.imu", IMU)
    h.inputs["rate_true"] = [0.1, 0.2]
    with pytest.raises(ConfigError) as error:
        h.step(10 * MS)
    assert error.value.key == "rate_true"


@pytest.mark.parametrize("type_name", ["sensor.imu", "sensor.force_torque", "sensor.relative_pose"])
def test_docstrings_carry_the_parameter_and_variable_tables_with_units(type_name):
    from components import registry

    doc = registry.load(type_name).__doc__
    assert "| seed | int | required |" in doc and "| variable | causality | shape | unit | description |" in doc
    for unit in {
        "sensor.imu": ("rad/s", "m/s^2"),
        "sensor.force_torque": ("N*m", "N, N*m"),
        "sensor.relative_pose": ("| m |", "| s |", "duration"),
    }[type_name]:
        assert unit in doc
