"""The ``controller.capture`` component type: a thin wrapper around
:mod:`components.controller.capture` (the phases; the estimator, the planner and the laws are in
the modules it names). Its parameters are declared in :mod:`components.controller.capture_parameters`,
checked against the URDF in :mod:`components.controller.capture_setup`, and its inputs and outputs
are :mod:`components.controller.capture_variables`.

Connections (a capture run): the servicer's state from the dynamics (``position``,
``orientation``, ``twist``, ``q``, ``qd`` as for ``controller.computed_torque``), the relative-pose
sensor (``grasp_p``, ``grasp_q``, ``grasp_t``, ``grasp_valid``), the dynamics' ``captured``, the
IMU's ``rate_imu`` and the wrist force-torque sensor's ``wrench``; ``tau`` goes to the dynamics'
``<servicer>.tau`` and ``close`` to whatever closes the grasp.

Time: ``do_step(t, h)`` reads the state measured at t (its sample time, ``input_times_ns``) and
returns the torques to apply from t + h on, as ``controller.computed_torque`` does.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from components.constants import NS_PER_S
from components.controller import plots as controller_plots
from components.controller.capture_parameters import PARAMETERS
from components.controller.capture_setup import CaptureSetup, capture_settings, check_setup
from components.controller.capture_variables import capture_variables
from components.controller.view import ControllerView
from components.sdk import Component, Outcome

if TYPE_CHECKING:
    from components.controller.capture import CaptureController


class CaptureComponent(Component):
    """Capture of a tumbling target by a free-floating servicer's arm, then detumbling of the
    assembly with reaction wheels (type ``controller.capture``; issue 23, see
    :mod:`components.controller.capture` for the estimator and the laws).

    From measurements of the target's grasp frame relative to the end effector (delayed: each
    carries its time), it estimates the grasp frame's motion in W (fading-memory least squares
    over the last ``estimator_window`` measurements, the end-effector pose taken at each
    measurement's time), blends the end effector onto the moving grasp frame over
    ``approach_time`` (phase 0), tracks it (phase 1) with the Generalized-Jacobian computed-torque
    law and feed-forward, and sets ``close`` once the estimated errors have stayed within the
    tolerances for ``tolerance_time``. When ``captured`` is 1 (phase 2) the arm holds its joint
    configuration (a joint PD in torque units, ``captured_kp``/``captured_kd``: the target's
    inertia is not in the servicer's model) and the wheels damp the bus rate measured by the IMU,
    within their effort and speed limits and scaled down to keep the wrist wrench within the grasp
    limits. Before the first estimate the arm holds its initial joint configuration.

    A grasp point beyond the arm's reach (from the shoulder, the first joint of ``joints``), or
    one whose following needs joint rates beyond the URDF velocity limits or torques beyond the
    effort limits for longer than ``limit_window``, makes the arm retreat to its posture (a
    ``capture_retreat`` event naming the limit, the figure and the limit) and try the next window;
    after ``attempts`` approaches, ``capture_aborted``. The run goes on either way.

    Outputs: ``tau`` (arm and wheels; zero elsewhere), ``close``, ``phase``, ``grasp_distance``,
    ``ee_error`` (the reference minus the end effector: the blend in approach, the estimated grasp
    frame in track and after capture), the estimated grasp frame's position, velocity and angular
    velocity (W); ``describe`` lists them.

    State (``get_state``): the estimator's measurements and fit, the end-effector pose history,
    the phase, ``close``, the approach's anchor, the hold configurations, the tolerance and limit
    timers and the wheel-torque factor: ``set_state`` on a fresh instance continues bit for bit.
    """

    type_name = "controller.capture"
    plots = (controller_plots.TORQUES, controller_plots.PHASES)
    view = ControllerView
    # the controller's own events: a capture the grasp lost again (capture_retreat) is undecided again
    outcomes = (
        Outcome(
            "undecided",
            "undecided: neither captured nor aborted by {end:g} s",
            ("capture_retreat",),
            "neither captured nor aborted at the end (or the grasp opened again after a capture)",
        ),
        Outcome(
            "captured",
            "captured at {time:g} s",
            ("capture_closed",),
            "the dynamics closed the grasp and it held to the end",
        ),
        Outcome(
            "aborted",
            "capture aborted at {time:g} s: {reason}",
            ("capture_aborted",),
            "the capture was given up (attempts, no window, capture_timeout)",
        ),
    )
    parameters = PARAMETERS

    @classmethod
    def validate(cls, params, run) -> CaptureSetup:
        """What the parameters mean for this URDF, checked."""
        return check_setup(params, run)

    @classmethod
    def declare(cls, params, run):
        return capture_variables(params.model)

    def __init__(self, params, run):
        from components.controller.computed_torque import compile_kernels

        super().__init__(params.checked, run)
        self.config = params
        self.controller = self._build()
        warm = self._build()  # the first control step comes with the approach, seconds into the run
        compile_kernels(warm.arm, warm.law)

    def _build(self) -> CaptureController:
        from components.controller.capture import CaptureController
        from components.controller.computed_torque import ComputedTorqueLaw
        from components.controller.free_floating_arm import FreeFloatingArm

        c, p = self.config, self.params
        arm = FreeFloatingArm(c.model, c.model.movable_joints, c.joints, p["end_effector"])
        law = ComputedTorqueLaw(
            c.kp, c.kd, c.null_kp, c.null_kd, c.effort, dls_threshold=p["dls_threshold"], dls_damping=p["dls_damping"]
        )
        return CaptureController(arm, law, capture_settings(c), c.wheels)

    def _idle_outputs(self) -> dict[str, np.ndarray | float]:
        z3 = np.zeros(3)
        return {
            "tau": np.zeros(self.controller.arm.n_body),
            "close": 0.0,
            "phase": 0.0,
            "attempt": 0.0,
            "grasp_distance": 0.0,
            "ee_error": np.zeros(6),
            "close_errors": np.zeros(4),
            "close_within": np.zeros(4),
            "grasp_position_est": z3,
            "grasp_velocity_est": z3,
            "grasp_rate_est": z3,
        }

    def initialize(self, t0_ns, inputs):
        self.controller = self._build()
        if "q" not in self.input_times_ns:
            # the state holds its start values (the dynamics initializes later in config order, or a
            # harness said nothing): take the initial configuration at the first step
            return self._idle_outputs()
        self.controller.start(inputs)
        return self._step(self.input_times_ns["q"] / NS_PER_S, 0.0, inputs)

    def do_step(self, t_ns, h_ns, inputs):
        if not self.controller.started:
            self.controller.start(inputs)
        t_state = self.input_times_ns.get("q", t_ns)
        return self._step(t_state / NS_PER_S, h_ns / NS_PER_S, inputs)

    def _step(self, t, h, inputs):
        outputs = self.controller.step(t, h, inputs)
        for kind, fields in self.controller.take_events():
            self.emit(kind, **fields)
        return outputs

    def get_state(self):
        return self.controller.get_state()

    def set_state(self, state):
        """Restore on a fresh instance (``initialize`` is not called): the estimator, the history,
        the phase and every timer as they were; the next steps are those of the saved instance."""
        self.controller = self._build()
        self.controller.set_state(state)
