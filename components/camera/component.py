"""``sensor.camera``: an RGB-D pinhole camera on a link, rendered with OpenGL on EGL (thin wrapper
of :class:`components.camera.model.CameraModel`).

Rate and time: one frame per step of the component (its own ``step:`` in the config, a multiple
of run.step). ``do_step(t, h)`` renders the scene from the inputs it holds (the bodies' poses at
t, or when ``input_times_ns`` says) and its outputs at t + h describe that frame: ``t_frame``
(when it was taken), ``frame`` (how many frames so far) and ``lit`` (1 in sunlight, 0 in the
Earth's shadow). ``initialize`` takes no frame.

The image and the depth do not travel as variables (a 640x480 frame is 1.2 MB): with ``--record
DIR`` each frame is written to ``DIR/frames/<component>/<k>.npz`` (k: the component's step, from
0) with ``rgb`` (H, W, 3) uint8, ``depth`` (H, W) float32 (m along the optical axis, 0 where
nothing is hit; absent with ``depth: false``), ``K`` (3x3), ``T_link_camera`` and ``T_W_camera``
(4x4), ``t`` (s); see :mod:`components.camera.frames`.

Noise: seeded, never from the wall clock. Pixel noise and depth noise have a generator each,
``numpy.random.Generator(PCG64(SeedSequence([seed, 0])))`` and ``[seed, 1]``; a frame draws H*W*3
standard normals (float32) from the first when ``pixel_noise`` > 0 and H*W from the second when
``depth_noise`` > 0 (a frame's 1.2 million normals at 640x480 cost more than its render, so none
are drawn for a sigma of 0). The noise of frame k depends only on the seed and k, and another
non-zero sigma scales the same draws. The generators' states are part of ``get_state``.
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from components.camera.frames import FrameWriter
from components.camera.render import EGL_PACKAGES, egl_problem
from components.camera.view import CameraView
from components.constants import NS_PER_S
from components.errors import ConfigError
from components.robots.model import read_model
from components.schema import Bool, Float, Int, MapOf, Str, Vector
from components.sdk import Component, Parameter, Variable
from components.sensors.noise import NormalStream, normalized
from components.signals import body_signals

MAX_SIZE = 8192


def _models(params: Mapping[str, Any]):
    return {name: read_model(urdf, params.get("_config_dir"), f"bodies.{name}", params.get("_packages"))
            for name, urdf in params["bodies"].items()}


class CameraComponent(Component):
    """An RGB-D camera (type ``sensor.camera``) on link ``link`` of body ``body``, looking at every
    body of ``bodies`` (their URDF visuals) lit by the Sun; black sky, no Earth in the image.

    Connect each body's base pose and joints from the dynamics (``camera.<body>.position:
    dynamics.<body>.position``, the same for ``orientation`` and ``q``) and the orbit
    (``camera.r_eci: orbit.r_eci``) for the Earth's shadow. The Sun direction comes from
    ``run.epoch`` and the run's time.
    """
    type_name = "sensor.camera"
    view = CameraView
    parameters = (
        Parameter("bodies", MapOf(Str(hint="a URDF file path"), "body name", min_items=1),
                  description="the bodies in the scene: name (as the dynamics names it) -> its URDF, relative to the config"),
        Parameter("body", Str(), description="the body carrying the camera"),
        Parameter("link", Str(), description="the link of that body the camera is fixed to"),
        Parameter("position", Vector(3, "m"), description="camera origin in the link frame"),
        Parameter("orientation", Vector(4), description="q_link_camera [x, y, z, w]; camera axes: z forward, x right, y down"),
        Parameter("width", Int(minimum=1), description=f"image width (pixels, at most {MAX_SIZE})"),
        Parameter("height", Int(minimum=1), description=f"image height (pixels, at most {MAX_SIZE})"),
        Parameter("fx", Float(positive=True), description="focal length along x (pixels)"),
        Parameter("fy", Float(positive=True), description="focal length along y (pixels)"),
        Parameter("cx", Float(), description="principal point x (pixels; pixel centres at integers, OpenCV's convention)"),
        Parameter("cy", Float(), description="principal point y (pixels)"),
        Parameter("near", Float("m", positive=True), description="nearest distance drawn, along the optical axis"),
        Parameter("far", Float("m", positive=True), description="farthest distance drawn, along the optical axis"),
        Parameter("depth", Bool(), default=True, description="record the depth image beside the colour image"),
        Parameter("ambient", Float(minimum=0.0, maximum=1.0), default=0.0,
                  description="light without the Sun, a fraction of a surface's colour (0: unlit faces and eclipse are black)"),
        Parameter("seed", Int(minimum=0), description="seed of the noise (numpy PCG64)"),
        Parameter("pixel_noise", Float(minimum=0.0), description="white noise on each colour channel, 1-sigma (counts of 0..255)"),
        Parameter("depth_noise", Float("m", minimum=0.0), description="white noise on the depth, 1-sigma, where something is hit"),
    )

    @classmethod
    def declare(cls, params):
        variables = [Variable("r_eci", "input", (3,), "m", 0.0,
                              "position of W's origin (the orbit point) in ECI, for the Earth's shadow; all zero: always lit")]
        for name, model in _models(params).items():
            variables += body_signals("input", model, name, ("position", "orientation", "q"))
        return variables + [
            Variable("t_frame", "output", (), "s", 0.0, "when the latest frame was taken (0 before the first)"),
            Variable("frame", "output", (), "1", 0.0, "frames taken so far (the latest is frames/<component>/<frame - 1>.npz)"),
            Variable("lit", "output", (), "1", 0.0, "1 when the latest frame was in sunlight, 0 in the Earth's shadow"),
        ]

    @classmethod
    def validate(cls, params):
        models = _models(params)
        if params["body"] not in models:
            raise ConfigError("body", f"expected one of bodies ({', '.join(models)}), got {params['body']!r}")
        links = models[params["body"]].link_names
        if params["link"] not in links:
            raise ConfigError("link", f"expected a link of {params['body']} ({', '.join(links)}), got {params['link']!r}")
        try:
            normalized(params["orientation"], "orientation")
        except ValueError as e:
            raise ConfigError("orientation", str(e)) from None
        for key in ("width", "height"):
            if params[key] > MAX_SIZE:
                raise ConfigError(key, f"expected 1 to {MAX_SIZE} pixels, got {params[key]}")
        for key, size in (("cx", params["width"]), ("cy", params["height"])):
            if not -0.5 <= params[key] <= size - 0.5:
                raise ConfigError(key, f"expected a principal point within the image (-0.5 to {size - 0.5:g} pixels "
                                       f"for {size} pixels), got {params[key]:g}")
        if not params["far"] > params["near"]:
            raise ConfigError("far", f"expected more than near ({params['near']:g} m), got {params['far']:g} m")

    @classmethod
    def preflight(cls, params, step_s, full=False):
        """The camera needs an OpenGL context on EGL (checked by making one) and the run's epoch."""
        problem = egl_problem()
        if problem is not None:
            raise ConfigError("", f"sensor.camera renders with OpenGL on EGL, which this machine lacks: {problem} "
                                      f"(Debian packages: {EGL_PACKAGES})")
        return []

    def __init__(self, params):
        from components.camera.model import CameraModel, Intrinsics, mount_transform
        from components.camera.sun import SunClock
        from components.viewer.robot import read_geometry

        self.params = params
        if not params.get("_epoch"):
            raise ConfigError("_epoch", "sensor.camera needs the run's epoch (run.epoch) for the Sun")
        models = _models(params)
        geometries = {name: read_geometry(model.path, params.get("_packages")) for name, model in models.items()}
        self.intrinsics = Intrinsics(params["width"], params["height"], params["fx"], params["fy"], params["cx"],
                                     params["cy"], params["near"], params["far"])
        self.T_link_camera = mount_transform(params["position"], params["orientation"])
        self.model = CameraModel(geometries, params["body"], params["link"], self.T_link_camera, self.intrinsics,
                                 params["ambient"])
        self.sun = SunClock(params["_epoch"])
        self.pixel_stream = NormalStream(np.random.SeedSequence([params["seed"], 0]))
        self.depth_stream = NormalStream(np.random.SeedSequence([params["seed"], 1]))
        self.joints = {name: len(model.movable_joints) for name, model in models.items()}
        self.writer = FrameWriter(params["_frames"]) if params.get("_frames") else None
        self.k = 0                       # frames taken
        self.t_frame_ns, self.lit = 0, False

    def _outputs(self):
        return {"t_frame": self.t_frame_ns / NS_PER_S, "frame": float(self.k), "lit": float(self.lit)}

    def initialize(self, t0_ns, inputs):
        return self._outputs()

    def take(self, t_ns: int, inputs) -> dict[str, np.ndarray]:
        """The frame of the scene the inputs hold at ``t_ns``, noise added: the arrays of its file."""
        from components.camera.model import add_depth_noise, add_pixel_noise
        from components.camera.sun import in_earth_shadow

        taken = self.input_times_ns.get(f"{self.params['body']}.position", t_ns)
        sun_W = self.sun.direction(taken)
        lit = not in_earth_shadow(inputs["r_eci"], sun_W)
        states = {name: (inputs[f"{name}.position"], inputs[f"{name}.orientation"], inputs[f"{name}.q"])
                  for name in self.joints}
        rgb, depth, T_W_camera = self.model.render(states, sun_W if lit else None)
        pixel_sigma, depth_sigma = self.params["pixel_noise"], self.params["depth_noise"]
        if pixel_sigma > 0.0:
            rgb = add_pixel_noise(rgb, self.pixel_stream.rng.standard_normal(rgb.shape, dtype=np.float32), pixel_sigma)
        if depth_sigma > 0.0:
            depth = add_depth_noise(depth, self.depth_stream.rng.standard_normal(depth.shape, dtype=np.float32),
                                    depth_sigma)
        self.t_frame_ns, self.lit = taken, lit
        frame = {"rgb": rgb, "K": self.intrinsics.K, "T_link_camera": self.T_link_camera, "T_W_camera": T_W_camera,
                 "t": np.float64(taken / NS_PER_S)}
        if self.params["depth"]:
            frame["depth"] = depth
        return frame

    def do_step(self, t_ns, h_ns, inputs):
        frame = self.take(t_ns, inputs)
        if self.writer is not None:
            self.writer.put(self.k, frame)
        self.k += 1
        return self._outputs()

    def terminate(self):
        if self.writer is not None:
            self.writer.close()
        self.model.release()

    def get_state(self):
        return {"pixel_rng": self.pixel_stream.get_state(), "depth_rng": self.depth_stream.get_state(),
                "k": np.int64(self.k), "t_frame_ns": np.int64(self.t_frame_ns), "lit": np.bool_(self.lit)}

    def set_state(self, state):
        self.pixel_stream.set_state(state["pixel_rng"])
        self.depth_stream.set_state(state["depth_rng"])
        self.k, self.t_frame_ns, self.lit = int(state["k"]), int(state["t_frame_ns"]), bool(state["lit"])
