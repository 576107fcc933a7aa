"""``controller.capture``'s inputs and outputs (its ``declare``): the servicer's state, the
relative-pose measurement, ``captured``, the IMU's rate and the wrist's wrench in; the torques,
``close``, the phase and the estimate and errors behind them out."""

from __future__ import annotations

from components.sdk import Variable
from components.signals import BODY_STATE, body_signals, torque_signal


def capture_variables(model) -> list[Variable]:
    """The inputs, then the outputs, of a capture controller of the servicer ``model``."""
    return capture_inputs(model) + capture_outputs(model)


def capture_inputs(model) -> list[Variable]:
    """The servicer's state, the grasp frame's measurement, ``captured``, ``rate_imu``, ``wrench``."""
    return body_signals("input", model, names=BODY_STATE) + [
        Variable(
            "grasp_p",
            "input",
            (3,),
            "m",
            [0.0] * 3,
            "measured position of the grasp frame's origin relative to the end effector, EE axes",
        ),
        Variable(
            "grasp_q",
            "input",
            (4,),
            "1",
            [0.0, 0.0, 0.0, 1.0],
            "measured orientation of the grasp frame, q_ee_grasp [x, y, z, w]",
        ),
        Variable("grasp_t", "input", (), "s", -1.0, "time the measurement was taken (it arrives late)"),
        Variable("grasp_valid", "input", (), "1", 0.0, "1 when the measurement is valid, else 0"),
        Variable("captured", "input", (), "1", 0.0, "1 once the grasp holds the target (from the dynamics)"),
        Variable("rate_imu", "input", (3,), "rad/s", [0.0] * 3, "the bus's angular rate measured by the IMU, bus axes"),
        Variable(
            "wrench", "input", (6,), "N, N*m", [0.0] * 6, "wrench measured at the wrist: force then torque, EE axes"
        ),
    ]


def capture_outputs(model) -> list[Variable]:
    """The torques (arm and wheels), ``close`` and the phase, the errors behind ``close`` and the estimate."""
    return [
        torque_signal("output", model, note="arm and wheels; zero on other joints"),
        Variable("close", "output", (), "1", 0.0, "1: close the grasp (the estimated errors stayed within tolerance)"),
        Variable(
            "phase",
            "output",
            (),
            "1",
            0.0,
            "0 wait, 1 approach, 2 closing, 3 track, 4 retreat, 5 captured, 6 aborted",
        ),
        Variable("attempt", "output", (), "1", 0.0, "approaches started so far"),
        Variable(
            "close_errors",
            "output",
            (4,),
            "m, rad, m/s, rad/s",
            [0.0] * 4,
            "estimated errors behind close (closing and track; else 0): position, attitude angle, "
            "linear velocity, angular velocity",
        ),
        Variable(
            "close_within",
            "output",
            (4,),
            "1",
            [0.0] * 4,
            "1 where close_errors is within its tolerance (position, attitude, velocity, rate)",
        ),
        Variable(
            "grasp_distance",
            "output",
            (),
            "m",
            0.0,
            "estimated distance from the end effector to the grasp frame (the last measured one before "
            "the first estimate)",
        ),
        Variable(
            "ee_error",
            "output",
            (6,),
            "m, rad",
            [0.0] * 6,
            "reference minus end effector: position (m), then log(R_ref R_ee^T) (rad), W; the reference "
            "is the blend in approach, the estimated grasp frame after",
        ),
        Variable("grasp_position_est", "output", (3,), "m", [0.0] * 3, "estimated grasp frame origin, W"),
        Variable("grasp_velocity_est", "output", (3,), "m/s", [0.0] * 3, "its estimated velocity, W"),
        Variable(
            "grasp_rate_est", "output", (3,), "rad/s", [0.0] * 3, "estimated angular velocity of the grasp frame, W"
        ),
    ]
