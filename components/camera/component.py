"""``sensor.camera``: an RGB-D pinhole camera on a link, rendered with OpenGL on EGL (thin wrapper
of :class:`components.camera.camera.Camera`).

Rate and time: one frame per step of the component (its own ``step:`` in the config, a multiple
of run.step). ``do_step(t, h)`` renders the scene from the inputs it holds (the bodies' poses at
t, or when ``input_times_ns`` says) and its outputs at t + h are that frame: the frame outputs
``rgb`` and ``depth`` (frame variables: on the bus to the components connected to them, never in
the rows), ``t_frame`` (when it was taken), ``frame`` (how many frames so far), ``lit`` (1 in
sunlight, 0 in the Earth's shadow) and the camera's constants ``K``, ``D`` and ``T_link_camera``,
which a consumer of the images needs with them. ``initialize`` takes no frame (its images are
zeros, ``t_frame`` 0).

With ``--record DIR`` each frame is written to ``DIR/frames/<component>/<k>.npz`` (k: the component's step, from
0) with ``rgb`` (H, W, 3) uint8, ``depth`` (H, W) float32 (m along the optical axis, 0 where
nothing is hit; absent with ``depth: false``), ``K`` (3x3), ``D`` (plumb_bob, zeros for a pinhole), ``T_link_camera`` and ``T_W_camera``
(4x4), ``t`` (s); see :mod:`components.camera.frames`. Noise: :mod:`components.camera.camera`.
State: the noise generators, the frame count, the last frame's time and light.
"""

from __future__ import annotations

import numpy as np

from components.camera.camera import CAMERA_PARAMETERS, Camera, camera_inputs, check_camera, check_egl
from components.camera.frames import FrameWriter
from components.camera.ros import CAMERA as CAMERA_ROS
from components.camera.view import CameraView
from components.constants import NS_PER_S
from components.sdk import Component, Variable


class CameraComponent(Component):
    """An RGB-D camera (type ``sensor.camera``) on link ``link`` of body ``body``, looking at every
    body of ``bodies`` (their URDF visuals; left out, the dynamics' bodies) lit by the Sun; black sky,
    no Earth in the image.

    Connect each body's base pose and joints from the dynamics (``camera.<body>.position:
    dynamics.<body>.position``, the same for ``orientation`` and ``q``) and the orbit
    (``camera.r_eci: orbit.r_eci``) for the Earth's shadow. The Sun direction comes from
    ``run.epoch`` and the run's time.
    """

    type_name = "sensor.camera"
    view = CameraView
    rosbag = CAMERA_ROS
    parameters = CAMERA_PARAMETERS
    scene_parameter = "bodies"

    @classmethod
    def declare(cls, params, run):
        return (
            camera_inputs(params, run)
            + [
                Variable("t_frame", "output", (), "s", 0.0, "when the latest frame was taken (0 before the first)"),
                Variable(
                    "frame",
                    "output",
                    (),
                    "1",
                    0.0,
                    "frames taken so far (the latest is frames/<component>/<frame - 1>.npz)",
                ),
                Variable(
                    "lit", "output", (), "1", 0.0, "1 when the latest frame was in sunlight, 0 in the Earth's shadow"
                ),
                Variable(
                    "rgb",
                    "output",
                    (params["height"], params["width"], 3),
                    "1",
                    0,
                    "the latest frame's colour image",
                    frame=True,
                    dtype="uint8",
                ),
                Variable("K", "output", (3, 3), "px", 0.0, "the intrinsic matrix (pixel centres at integers)"),
                Variable("D", "output", (5,), "1", 0.0, "plumb_bob distortion [k1, k2, p1, p2, k3] (zeros: a pinhole)"),
                Variable(
                    "T_link_camera", "output", (4, 4), "1", 0.0, "the camera's pose in its link (translation in m)"
                ),
            ]
            + (
                [
                    Variable(
                        "depth",
                        "output",
                        (params["height"], params["width"]),
                        "m",
                        0,
                        "the latest frame's depth along the optical axis (0: nothing hit)",
                        frame=True,
                        dtype="float32",
                    )
                ]
                if params["depth"]
                else []
            )
        )

    @classmethod
    def validate(cls, params, run):
        check_camera(params, run)
        return params

    @classmethod
    def preflight(cls, params, run, step_s, full=False):
        """The camera needs an OpenGL context on EGL: checked by making one, at check and run."""
        check_egl()
        return []

    def __init__(self, params, run):
        self.params = params
        self.camera = Camera(params, run)
        self.writer = FrameWriter(run.frames) if run.frames else None
        self.k = 0  # frames taken
        self.t_frame_ns, self.lit = 0, False
        h, w = params["height"], params["width"]
        self.constants = {"K": self.camera.intrinsics.K, "D": self.camera.D, "T_link_camera": self.camera.T_link_camera}
        self.blank = {"rgb": np.zeros((h, w, 3), np.uint8), "depth": np.zeros((h, w), np.float32)}

    def _outputs(self, frame):
        return {
            "t_frame": self.t_frame_ns / NS_PER_S,
            "frame": float(self.k),
            "lit": float(self.lit),
            "rgb": frame["rgb"],
            "depth": frame.get("depth"),
            **self.constants,
        }

    def initialize(self, t0_ns, inputs):
        return self._outputs(self.blank)

    def take(self, t_ns: int, inputs) -> dict[str, np.ndarray]:
        """The frame of the scene the inputs hold at ``t_ns``: the arrays of its file."""
        taken = self.input_times_ns.get(f"{self.params['body']}.position", t_ns)
        frame = self.camera.frame(taken, inputs)
        self.t_frame_ns, self.lit = taken, frame.pop("lit")
        self.frame_time_ns = taken  # the live views' stamp, as t_frame is the recording's
        if not self.params["depth"]:
            del frame["depth"]
        return frame

    def do_step(self, t_ns, h_ns, inputs):
        frame = self.take(t_ns, inputs)
        if self.writer is not None:
            self.writer.put(self.k, frame)
        self.k += 1
        return self._outputs(frame)

    def terminate(self):
        if self.writer is not None:
            self.writer.close()
        self.camera.release()

    def get_state(self):
        return {
            **self.camera.get_state(),
            "k": np.int64(self.k),
            "t_frame_ns": np.int64(self.t_frame_ns),
            "lit": np.bool_(self.lit),
        }

    def set_state(self, state):
        self.camera.set_state(state)
        self.k, self.t_frame_ns, self.lit = int(state["k"]), int(state["t_frame_ns"]), bool(state["lit"])
