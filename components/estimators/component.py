"""``estimator.fiducial``: the grasp frame's pose in the end effector from a camera's frames (thin
wrapper of :class:`components.estimators.fiducial.FiducialEstimator`)."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from components.constants import NS_PER_S
from components.errors import ComponentError, ConfigError
from components.estimators.marker_layout import MarkerLayout, read_layout
from components.robots.model import PROJECT_ROOT
from components.rotations import continuous, quat_to_matrix
from components.schema import Float, Int, Str, Vector
from components.sdk import Component, Parameter, Variable
from components.sensors.noise import normalized

# lengths of OpenCV's distortion vectors: k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4 [tx ty]]]]
DISTORTION_SIZES = (4, 5, 8, 12, 14)


def layout_path(value: str, config_dir: str | None) -> Path:
    """The marker layout file: absolute, else relative to the config, else to the project root."""
    path = Path(value)
    candidates = [path] if path.is_absolute() else [Path(config_dir or ".") / path, PROJECT_ROOT / path]
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    raise ConfigError("markers", f"marker layout {value!r} not found (looked in: {', '.join(map(str, candidates))})")


def _layout(params: Mapping[str, Any]) -> MarkerLayout:
    return read_layout(layout_path(params["markers"], params.get("_config_dir")), "markers")


class FiducialComponent(Component):
    """A vision pose estimator (type ``estimator.fiducial``): finds the fiducial markers of a
    layout (``markers``: a YAML file, models/capture/grapple_markers.yaml for the capture target's
    grapple) in a camera's frames and outputs the pose of the layout's link (the grasp frame G)
    in the end-effector frame E: the outputs of ``sensor.relative_pose`` (``p``, ``q``,
    ``t_measured``, ``valid``), so a config swaps one for the other.

    Frames: connect ``t_frame`` and ``frame`` from a ``sensor.camera``'s outputs of the same
    names. When ``frame`` counts a frame it has not looked at, the step takes that frame (its RGB
    image and its intrinsics ``K``) from its frame source and solves it; ``t_measured`` is
    ``t_frame`` (when the image was taken) and ``valid`` says whether this frame gave a pose
    (enough markers, reprojection error within bounds). A frame refused leaves ``p`` and ``q`` at
    the last accepted pose with ``valid`` 0; between frames every output holds. ``q`` is
    sign-continuous from one accepted pose to the next. The camera's pose in E is
    ``camera_position``, ``camera_orientation`` (for a camera on link ``ee``: its own
    ``position``, ``orientation``).

    The frame source is ``frame_source``, a callable frame index (from 0) -> the frame's arrays
    (``rgb`` H x W x 3 uint8, ``K`` 3x3), as the camera records them; the in-process harness sets
    it (``h.component.frame_source = frames.__getitem__``).

    State: the frames looked at and the last outputs (the solve has no memory).
    """
    type_name = "estimator.fiducial"
    parameters = (
        Parameter("markers", Str(hint="a marker layout (YAML) file path"),
                  description="the marker layout: dictionary, link, markers' ids, sizes and poses (relative to the config)"),
        Parameter("camera_position", Vector(3, "m"), description="camera origin in the end-effector frame E"),
        Parameter("camera_orientation", Vector(4),
                  description="q_E_camera [x, y, z, w]; camera axes: z forward, x right, y down (OpenCV)"),
        Parameter("distortion", Vector(None), default=None,
                  description="the lens's OpenCV distortion k1, k2, p1, p2[, k3...] (4, 5, 8, 12 or 14 values); null: none"),
        Parameter("min_markers", Int(minimum=1), description="fewest markers seen for a pose (fewer: valid 0)"),
        Parameter("max_reprojection_error", Float(positive=True),
                  description="largest RMS reprojection error over the markers' corners for a pose (pixels)"),
    )
    variables = (
        Variable("t_frame", "input", (), "s", 0.0, "when the camera's latest frame was taken (sensor.camera's t_frame)"),
        Variable("frame", "input", (), "1", 0.0, "frames the camera has taken so far (sensor.camera's frame)"),
        Variable("p", "output", (3,), "m", [0.0] * 3, "the grasp frame's origin in E (the last accepted pose)"),
        Variable("q", "output", (4,), "1", [0.0, 0.0, 0.0, 1.0],
                 "q_E_G [x, y, z, w] (the last accepted pose), unit, sign-continuous"),
        Variable("t_measured", "output", (), "s", 0.0, "when the latest frame looked at was taken"),
        Variable("valid", "output", (), "1", 0.0, "1 when the latest frame looked at gave a pose, else 0"),
        Variable("markers", "output", (), "1", 0.0, "markers of the layout found in the latest frame"),
        Variable("reprojection_error", "output", (), "px", 0.0,
                 "RMS reprojection error of the latest frame's solve (0 without one)"),
    )

    @classmethod
    def validate(cls, params):
        layout = _layout(params)
        try:
            normalized(params["camera_orientation"], "camera_orientation")
        except ValueError as e:
            raise ConfigError("camera_orientation", str(e)) from None
        if params["min_markers"] > len(layout.markers):
            raise ConfigError("min_markers", f"expected at most the layout's {len(layout.markers)} markers, "
                                             f"got {params['min_markers']}")
        distortion = params["distortion"]
        if distortion is not None and len(distortion) not in DISTORTION_SIZES:
            raise ConfigError("distortion", f"expected {', '.join(map(str, DISTORTION_SIZES))} values "
                                            f"(OpenCV's k1, k2, p1, p2, ...), got {len(distortion)}")

    def __init__(self, params):
        from components.estimators.fiducial import FiducialEstimator
        self.params = params
        self.estimator = FiducialEstimator(_layout(params), params["min_markers"], params["max_reprojection_error"])
        self.p_ee_camera = np.asarray(params["camera_position"], dtype=np.float64)
        self.R_ee_camera = quat_to_matrix(params["camera_orientation"])
        self.distortion = np.zeros(0) if params["distortion"] is None else np.asarray(params["distortion"])
        self.frame_source: Callable[[int], Mapping[str, np.ndarray]] | None = None
        self.frames_seen = 0
        self.p, self.q = np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0])
        self.accepted = False                    # a pose was accepted (q's sign follows it)
        self.t_measured, self.valid, self.markers, self.error = 0.0, False, 0, 0.0

    def _outputs(self) -> dict[str, Any]:
        return {"p": self.p, "q": self.q, "t_measured": self.t_measured, "valid": float(self.valid),
                "markers": float(self.markers), "reprojection_error": self.error}

    def initialize(self, t0_ns, inputs):
        return self._outputs()

    def do_step(self, t_ns, h_ns, inputs):
        frames = int(round(float(inputs["frame"])))
        if frames > self.frames_seen:
            self._solve(frames - 1, float(inputs["t_frame"]))
            self.frames_seen = frames
        return self._outputs()

    def _solve(self, k: int, t_frame: float) -> None:
        if self.frame_source is None:
            raise ComponentError("estimator.fiducial has no frame source: the camera's frames do not reach it")
        frame = self.frame_source(k)
        estimate = self.estimator.estimate(np.asarray(frame["rgb"]), np.asarray(frame["K"]), self.distortion,
                                           self.p_ee_camera, self.R_ee_camera)
        self.t_measured, self.valid, self.markers = t_frame, estimate.valid, estimate.markers
        self.error = estimate.reprojection_error if np.isfinite(estimate.reprojection_error) else 0.0
        if estimate.valid:
            self.p = estimate.p_ee_grasp.copy()
            self.q = continuous(estimate.q_ee_grasp, self.q if self.accepted else None)
            self.accepted = True

    def get_state(self):
        return {"frames_seen": np.int64(self.frames_seen), "p": self.p.copy(), "q": self.q.copy(),
                "accepted": np.bool_(self.accepted), "t_measured": np.float64(self.t_measured),
                "valid": np.bool_(self.valid), "markers": np.int64(self.markers), "error": np.float64(self.error)}

    def set_state(self, state):
        self.frames_seen = int(state["frames_seen"])
        self.p = np.array(state["p"], dtype=np.float64).reshape(3)
        self.q = np.array(state["q"], dtype=np.float64).reshape(4)
        self.accepted, self.valid = bool(state["accepted"]), bool(state["valid"])
        self.t_measured, self.markers, self.error = float(state["t_measured"]), int(state["markers"]), float(state["error"])
