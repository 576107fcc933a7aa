"""A camera's parameters, inputs and checks, and :class:`Camera`, the frames of those inputs with
the Sun and the noise (no bus, no files); ``sensor.camera`` wraps it. A component that needs the
images reads ``sensor.camera``'s frame outputs over the bus (the Component API, "Images in a step").

Noise: pixel noise and depth noise have a generator each,
``numpy.random.Generator(PCG64(SeedSequence([seed, 0])))`` and ``[seed, 1]``; a frame draws H*W*3
standard normals (float32) from the first when ``pixel_noise`` > 0 and H*W from the second when
``depth_noise`` > 0 (a frame's 1.2 million normals at 640x480 cost more than its render, so none
are drawn for a sigma of 0). The noise of frame k depends only on the seed and k, and another
non-zero sigma scales the same draws. The generators' states are the part's state.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from components.camera.lens import inversion_problem
from components.camera.render import EGL_PACKAGES, egl_problem
from components.constants import MAX_IMAGE_SIZE, NS_PER_S
from components.errors import ConfigError
from components.noise import NormalStream, normalized
from components.robots.model import read_model
from components.schema import Bool, Float, Int, MapOf, Str, Vector
from components.sdk import EPOCH_KEY, Parameter, RunSettings, Variable
from components.signals import body_signals

ECLIPSE_MODELS = ("cylindrical", "conical", "none")

CAMERA_PARAMETERS = (
    Parameter(
        "bodies",
        MapOf(Str(hint="a URDF file path"), "body name", min_items=1),
        default=None,
        description="the bodies in the scene: name (as the dynamics names it) -> its URDF, relative to the config; "
        "null (default): the run's, every body of the dynamics with its urdf",
    ),
    Parameter("body", Str(), description="the body carrying the camera"),
    Parameter("link", Str(), description="the link of that body the camera is fixed to"),
    Parameter("position", Vector(3, "m", plausible=(-100.0, 100.0)), description="camera origin in the link frame"),
    Parameter(
        "orientation", Vector(4), description="q_link_camera [x, y, z, w]; camera axes: z forward, x right, y down"
    ),
    Parameter("width", Int(minimum=1), description=f"image width (pixels, at most {MAX_IMAGE_SIZE})"),
    Parameter("height", Int(minimum=1), description=f"image height (pixels, at most {MAX_IMAGE_SIZE})"),
    Parameter("fx", Float(positive=True), description="focal length along x (pixels)"),
    Parameter("fy", Float(positive=True), description="focal length along y (pixels)"),
    Parameter("cx", Float(), description="principal point x (pixels; pixel centres at integers, OpenCV's convention)"),
    Parameter("cy", Float(), description="principal point y (pixels)"),
    Parameter(
        "distortion",
        Vector(5),
        default=None,
        description="plumb_bob lens distortion [k1, k2, p1, p2, k3] (OpenCV's, ROS's); null: an ideal pinhole",
    ),
    Parameter(
        "near",
        Float("m", positive=True, plausible=(1e-4, 100.0)),
        description="nearest distance drawn, along the optical axis",
    ),
    Parameter(
        "far",
        Float("m", positive=True, plausible=(0.01, 1e6)),
        description="farthest distance drawn, along the optical axis",
    ),
    Parameter("depth", Bool(), default=True, description="record the depth image beside the colour image"),
    Parameter(
        "ambient",
        Float(minimum=0.0, maximum=1.0),
        default=0.0,
        description="light without the Sun, a fraction of a surface's colour (0: unlit faces and eclipse are black)",
    ),
    Parameter(
        "lamp",
        Float("m^2", minimum=0.0),
        default=0.0,
        description="a lamp at the camera's origin: light on a face square to it 1 m away, a fraction of its "
        "colour, falling off as 1/d^2 (Lambert; 0: none)",
    ),
    Parameter(
        "eclipse",
        Str(tuple(ECLIPSE_MODELS)),
        default="cylindrical",
        description="the shadow that unlights the scene (components/space/eclipse.py): cylindrical (the Earth's "
        "cylinder), conical (Earth and Moon, lit while any of the Sun shows), none (always lit)",
    ),
    Parameter("seed", Int(minimum=0), description="seed of the noise (numpy PCG64)"),
    Parameter(
        "pixel_noise",
        Float(minimum=0.0, plausible=(0.0, 64.0)),
        description="white noise on each colour channel, 1-sigma (counts of 0..255)",
    ),
    Parameter(
        "depth_noise",
        Float("m", minimum=0.0, plausible=(0.0, 1.0)),
        description="white noise on the depth, 1-sigma, where something is hit",
    ),
)


def _models(camera: Mapping[str, Any], run: RunSettings):
    if camera["bodies"] is None:  # a run's config fills it in from the dynamics (orchestrator/config/scene.py)
        raise ConfigError(
            "bodies", "expected a mapping body name -> URDF (none given, and no dynamics to take it from)"
        )
    return {
        name: read_model(urdf, run.config_dir, f"bodies.{name}", run.packages)
        for name, urdf in camera["bodies"].items()
    }


def camera_inputs(camera: Mapping[str, Any], run: RunSettings) -> list[Variable]:
    """The inputs a camera reads: ``r_eci`` and, per body, its base ``position``, ``orientation``
    and joints ``q``. ``run``: the run's settings (``config_dir``, ``packages``)."""
    variables = [
        Variable(
            "r_eci",
            "input",
            (3,),
            "m",
            0.0,
            "position of W's origin (the orbit point) in ECI, for the Earth's shadow; all zero: always lit",
        )
    ]
    for name, model in _models(camera, run).items():
        variables += body_signals("input", model, name, ("position", "orientation", "q"))
    return variables


def check_camera(camera: Mapping[str, Any], run: RunSettings) -> None:
    """Checks across a camera's parameters: ConfigError naming the key (relative to the camera's)."""
    models = _models(camera, run)
    if camera["body"] not in models:
        raise ConfigError("body", f"expected one of bodies ({', '.join(models)}), got {camera['body']!r}")
    links = models[camera["body"]].link_names
    if camera["link"] not in links:
        raise ConfigError("link", f"expected a link of {camera['body']} ({', '.join(links)}), got {camera['link']!r}")
    try:
        normalized(camera["orientation"], "orientation")
    except ValueError as e:
        raise ConfigError("orientation", str(e)) from None
    for key in ("width", "height"):
        if camera[key] > MAX_IMAGE_SIZE:
            raise ConfigError(key, f"expected 1 to {MAX_IMAGE_SIZE} pixels, got {camera[key]}")
    for key, size in (("cx", camera["width"]), ("cy", camera["height"])):
        if not -0.5 <= camera[key] <= size - 0.5:
            raise ConfigError(
                key,
                f"expected a principal point within the image (-0.5 to {size - 0.5:g} pixels "
                f"for {size} pixels), got {camera[key]:g}",
            )
    if camera["distortion"] is not None:
        problem = inversion_problem(camera["width"], camera["height"], intrinsic_matrix(camera), camera["distortion"])
        if problem is not None:
            raise ConfigError("distortion", f"{problem}, got {[float(c) for c in camera['distortion']]}")
    if not camera["far"] > camera["near"]:
        raise ConfigError("far", f"expected more than near ({camera['near']:g} m), got {camera['far']:g} m")


def intrinsic_matrix(camera: Mapping[str, Any]) -> np.ndarray:
    """K (3x3, pixels) of a camera's parameters."""
    return np.array([[camera["fx"], 0.0, camera["cx"]], [0.0, camera["fy"], camera["cy"]], [0.0, 0.0, 1.0]])


def check_egl(who: str = "sensor.camera") -> None:
    """ConfigError (no key) when no OpenGL context on EGL can be made here, naming the Debian packages."""
    problem = egl_problem()
    if problem is not None:
        raise ConfigError(
            "",
            f"{who} renders with OpenGL on EGL, which this machine lacks: {problem} (Debian packages: {EGL_PACKAGES})",
        )


class Camera:
    """The frames of one camera (``camera``: its validated parameters; ``run``: the run's settings,
    for the epoch, config_dir and packages)."""

    def __init__(self, camera: Mapping[str, Any], run: RunSettings):
        from components.camera.model import CameraModel, Intrinsics, mount_transform
        from components.camera.sun import SunClock
        from components.viewer.robot import read_geometry

        if not run.epoch:
            raise ConfigError(EPOCH_KEY, "a camera needs the run's epoch (run.epoch) for the Sun")
        self.camera = camera
        models = _models(camera, run)
        geometries = {name: read_geometry(model.path, run.packages) for name, model in models.items()}
        distortion = None if camera["distortion"] is None else tuple(float(c) for c in camera["distortion"])
        self.intrinsics = Intrinsics(
            camera["width"],
            camera["height"],
            camera["fx"],
            camera["fy"],
            camera["cx"],
            camera["cy"],
            camera["near"],
            camera["far"],
            distortion,
        )
        self.T_link_camera = mount_transform(camera["position"], camera["orientation"])
        self.model = CameraModel(
            geometries,
            camera["body"],
            camera["link"],
            self.T_link_camera,
            self.intrinsics,
            camera["ambient"],
            camera["lamp"],
        )
        self.D = np.array(distortion or (0.0,) * 5)  # plumb_bob [k1, k2, p1, p2, k3]
        self.sun = SunClock(run.epoch)
        self.pixel_stream = NormalStream(np.random.SeedSequence([camera["seed"], 0]))
        self.depth_stream = NormalStream(np.random.SeedSequence([camera["seed"], 1]))
        self.bodies = list(models)

    def frame(self, t_ns: int, inputs: Mapping[str, np.ndarray]) -> dict[str, Any]:
        """The frame of what ``inputs`` show, taken at ``t_ns`` (the time the inputs were sampled),
        noise added: ``rgb`` (H, W, 3) uint8, ``depth`` (H, W) float32 (m along the optical axis, 0:
        nothing hit), ``K``, ``D`` (plumb_bob, zeros for a pinhole), ``T_link_camera``,
        ``T_W_camera``, ``t`` (s) and ``lit`` (bool)."""
        from components.camera.model import add_depth_noise, add_pixel_noise
        from components.space.eclipse import illumination

        sun_eci = self.sun.sun(t_ns)
        sun_W = sun_eci / np.linalg.norm(sun_eci)
        model = self.camera["eclipse"]
        lit = illumination(inputs["r_eci"], sun_eci, self.sun.moon(t_ns) if model == "conical" else None, model) > 0.0
        states = {
            name: (inputs[f"{name}.position"], inputs[f"{name}.orientation"], inputs[f"{name}.q"])
            for name in self.bodies
        }
        rgb, depth, T_W_camera = self.model.render(states, sun_W if lit else None)
        pixel_sigma, depth_sigma = self.camera["pixel_noise"], self.camera["depth_noise"]
        if pixel_sigma > 0.0:
            rgb = add_pixel_noise(rgb, self.pixel_stream.rng.standard_normal(rgb.shape, dtype=np.float32), pixel_sigma)
        if depth_sigma > 0.0:
            depth = add_depth_noise(
                depth, self.depth_stream.rng.standard_normal(depth.shape, dtype=np.float32), depth_sigma
            )
        return {
            "rgb": rgb,
            "depth": depth,
            "K": self.intrinsics.K,
            "D": self.D,
            "T_link_camera": self.T_link_camera,
            "T_W_camera": T_W_camera,
            "t": np.float64(t_ns / NS_PER_S),
            "lit": lit,
        }

    def get_state(self) -> dict[str, np.ndarray]:
        return {"pixel_rng": self.pixel_stream.get_state(), "depth_rng": self.depth_stream.get_state()}

    def set_state(self, state: Mapping[str, Any]) -> None:
        self.pixel_stream.set_state(state["pixel_rng"])
        self.depth_stream.set_state(state["depth_rng"])

    def release(self) -> None:
        self.model.release()
