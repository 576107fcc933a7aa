"""``estimator.fiducial``: the grasp frame's pose in the end effector from a camera's images, read
from the bus (thin wrapper of :class:`components.estimators.fiducial.FiducialEstimator`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from components.constants import MAX_IMAGE_SIZE, NS_PER_S
from components.errors import ConfigError
from components.estimators import plots as fiducial_plots
from components.estimators import ros as fiducial_ros
from components.estimators.marker_layout import MarkerLayout, layout_path, read_layout
from components.extras import require
from components.robots.model import read_model
from components.robots.urdf import UrdfModel
from components.rotations import continuous, rpy_to_matrix
from components.schema import Float, Int, Str
from components.sdk import Component, Parameter, RunSettings, Variable


def _layout(params: Mapping[str, Any], run: RunSettings) -> MarkerLayout:
    return read_layout(layout_path(params["markers"], run.config_dir), "markers")


def fixed_transform(model: UrdfModel, a: str, b: str) -> np.ndarray:
    """T_a_b (4x4) between two links joined by fixed joints only; ValueError otherwise."""
    parent = {j.child: j for j in model.joints}

    def up(link: str) -> list[str]:
        chain = [link]
        while chain[-1] in parent:
            chain.append(parent[chain[-1]].parent)
        return chain

    up_a, up_b = up(a), up(b)
    common = next(link for link in up_a if link in up_b)

    def to_common(chain: list[str]) -> np.ndarray:
        T = np.eye(4)
        for link in chain[: chain.index(common)]:
            joint = parent[link]
            if joint.type != "fixed":
                raise ValueError(f"joint {joint.name} between them is {joint.type}, not fixed")
            step = np.eye(4)
            step[:3, :3], step[:3, 3] = rpy_to_matrix(joint.rpy), joint.xyz
            T = step @ T
        return T  # T_common_link

    return np.linalg.inv(to_common(up_a)) @ to_common(up_b)


def _link_in_ee(params: Mapping[str, Any], run: RunSettings) -> np.ndarray:
    """T_E_link (4x4): the camera's link in the end effector, from the URDF; ConfigError naming the key."""
    model = read_model(params["urdf"], run.config_dir, "urdf", run.packages)
    for key in ("end_effector", "link"):
        if params[key] not in model.link_names:
            raise ConfigError(
                key, f"expected a link of {params['urdf']} ({', '.join(model.link_names)}), got {params[key]!r}"
            )
    try:
        return fixed_transform(model, params["end_effector"], params["link"])
    except ValueError as e:
        raise ConfigError(
            "end_effector", f"the camera's link {params['link']} must be {params['end_effector']} or fixed to it: {e}"
        ) from None


class FiducialComponent(Component):
    """A vision pose estimator (type ``estimator.fiducial``): in each image of a camera (its frame
    input ``rgb``, from ``sensor.camera`` over the bus) it finds the fiducial markers of a layout
    (``markers``: models/capture/grapple_markers.yaml for the capture target's grapple) and solves
    the pose of the layout's link G (the grasp frame) in the end-effector frame E
    (``end_effector``, a link of the URDF ``urdf`` of the camera's body ``body``, which carries
    the camera on ``link``, the same link or one fixed to it). Its outputs are
    ``sensor.relative_pose``'s (``p``, ``q``, ``t_measured``, ``valid``), so a config swaps one for
    the other.

    Connect the camera's outputs: ``<c>.rgb: <camera>.rgb``, ``<c>.K: <camera>.K``, ``<c>.D:
    <camera>.D``, ``<c>.T_link_camera: <camera>.T_link_camera``, ``<c>.t_frame: <camera>.t_frame``,
    ``<c>.frame: <camera>.frame`` (``width`` and ``height`` as the camera's: ``check`` refuses another frame shape). Rate and
    time: one solve per step of the component, of the frame it holds (the camera's latest, made
    from the poses at ``t_frame``); the step's outputs at t + h are that solve: ``t_measured`` the
    frame's time, ``valid`` 1 when it gave a pose (at least ``min_markers`` markers, RMS
    reprojection error at most ``max_reprojection_error``). A frame refused (or none yet:
    ``frame`` 0) leaves ``p`` and ``q`` at the last accepted pose, ``valid`` 0. ``q`` is
    sign-continuous from one accepted pose to the next.

    The markers must show in the camera's image: the capture target's are meshes of black and
    white cells (``orchestrator markers``), which any renderer of URDF colours draws.

    State: the last outputs.
    """

    type_name = "estimator.fiducial"
    plots = (fiducial_plots.POSE,)
    rosbag = fiducial_ros.POSE
    parameters = (
        Parameter("body", Str(), description="the body carrying the camera, as the dynamics names it"),
        Parameter("urdf", Str(hint="a URDF file path"), description="that body's URDF (relative to the config)"),
        Parameter("link", Str(), description="the link of that body the camera is fixed to (the camera's link)"),
        Parameter("end_effector", Str(), description="the link whose frame E the pose is in: link, or one fixed to it"),
        Parameter("width", Int(minimum=1), description=f"the camera's image width (pixels, at most {MAX_IMAGE_SIZE})"),
        Parameter(
            "height", Int(minimum=1), description=f"the camera's image height (pixels, at most {MAX_IMAGE_SIZE})"
        ),
        Parameter(
            "markers",
            Str(hint="a marker layout (YAML) file path"),
            description="the marker layout: dictionary, link, markers' ids, sizes and poses (relative to the config)",
        ),
        Parameter("min_markers", Int(minimum=1), description="fewest markers seen for a pose (fewer: valid 0)"),
        Parameter(
            "max_reprojection_error",
            Float(positive=True),
            description="largest RMS reprojection error over the markers' corners for a pose (pixels)",
        ),
    )
    OUTPUTS = (
        Variable("p", "output", (3,), "m", [0.0] * 3, "the grasp frame's origin in E (the last accepted pose)"),
        Variable(
            "q",
            "output",
            (4,),
            "1",
            [0.0, 0.0, 0.0, 1.0],
            "q_E_G [x, y, z, w] (the last accepted pose), unit, sign-continuous",
        ),
        Variable("t_measured", "output", (), "s", 0.0, "when the latest frame was taken"),
        Variable("valid", "output", (), "1", 0.0, "1 when the latest frame gave a pose, else 0"),
        Variable("markers", "output", (), "1", 0.0, "markers of the layout found in the latest frame"),
        Variable(
            "reprojection_error",
            "output",
            (),
            "px",
            0.0,
            "RMS reprojection error of the latest frame's solve (0 without one)",
        ),
        Variable(
            "frame_solved",
            "output",
            (),
            "1",
            0.0,
            "the camera's count of the latest frame solved (0: none yet; with --record, its file is "
            "frames/<camera>/<frame - 1>.npz)",
        ),
    )

    @classmethod
    def declare(cls, params, run):
        return [
            Variable(
                "rgb",
                "input",
                (params["height"], params["width"], 3),
                "1",
                0,
                "the camera's image",
                frame=True,
                dtype="uint8",
            ),
            Variable("K", "input", (3, 3), "px", np.eye(3), "the camera's intrinsic matrix"),
            Variable("D", "input", (5,), "1", 0.0, "the camera's plumb_bob distortion [k1, k2, p1, p2, k3]"),
            Variable("T_link_camera", "input", (4, 4), "1", np.eye(4), "the camera's pose in its link (m)"),
            Variable("t_frame", "input", (), "s", 0.0, "when the image was taken"),
            Variable("frame", "input", (), "1", 0.0, "the camera's frame count (0: no image yet)"),
        ] + list(cls.OUTPUTS)

    @classmethod
    def validate(cls, params, run):
        for key in ("width", "height"):
            if params[key] > MAX_IMAGE_SIZE:
                raise ConfigError(key, f"expected 1 to {MAX_IMAGE_SIZE} pixels, got {params[key]}")
        _link_in_ee(params, run)
        layout = _layout(params, run)
        if params["min_markers"] > len(layout.markers):
            raise ConfigError(
                "min_markers",
                f"expected at most the layout's {len(layout.markers)} markers, got {params['min_markers']}",
            )
        return params

    @classmethod
    def preflight(cls, params, run, step_s, full=False):
        """ArUco detection needs OpenCV (the extra [vision]): checked at check and run."""
        require("vision", "estimator.fiducial")
        return []

    def __init__(self, params, run):
        from components.estimators.fiducial import FiducialEstimator

        self.params = params
        self.estimator = FiducialEstimator(
            _layout(params, run), params["min_markers"], params["max_reprojection_error"]
        )
        self.T_E_link = _link_in_ee(params, run)
        self.p, self.q = np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0])
        self.accepted = False  # a pose was accepted (q's sign follows it)
        self.t_measured_ns, self.valid, self.markers, self.error = 0, False, 0, 0.0
        self.frame = 0

    def _outputs(self) -> dict[str, Any]:
        return {
            "p": self.p,
            "q": self.q,
            "t_measured": self.t_measured_ns / NS_PER_S,
            "valid": float(self.valid),
            "markers": float(self.markers),
            "reprojection_error": self.error,
            "frame_solved": float(self.frame),
        }

    def initialize(self, t0_ns, inputs):
        return self._outputs()

    def do_step(self, t_ns, h_ns, inputs):
        self.t_measured_ns, self.frame = round(float(inputs["t_frame"]) * NS_PER_S), int(inputs["frame"])
        if not self.frame:  # no frame yet (the camera's start values)
            self.valid, self.markers, self.error = False, 0, 0.0
            return self._outputs()
        T_E_C = self.T_E_link @ inputs["T_link_camera"]
        estimate = self.estimator.estimate(inputs["rgb"], inputs["K"], inputs["D"], T_E_C[:3, 3], T_E_C[:3, :3])
        self.valid, self.markers = estimate.valid, estimate.markers
        self.error = estimate.reprojection_error if np.isfinite(estimate.reprojection_error) else 0.0
        if estimate.valid:
            self.p = estimate.p_ee_grasp.copy()
            self.q = continuous(estimate.q_ee_grasp, self.q if self.accepted else None)
            self.accepted = True
        return self._outputs()

    def get_state(self):
        return {
            "p": self.p.copy(),
            "q": self.q.copy(),
            "accepted": np.bool_(self.accepted),
            "t_measured_ns": np.int64(self.t_measured_ns),
            "valid": np.bool_(self.valid),
            "markers": np.int64(self.markers),
            "error": np.float64(self.error),
            "frame": np.int64(self.frame),
        }

    def set_state(self, state):
        self.p = np.array(state["p"], dtype=np.float64).reshape(3)
        self.q = np.array(state["q"], dtype=np.float64).reshape(4)
        self.accepted, self.valid = bool(state["accepted"]), bool(state["valid"])
        self.t_measured_ns, self.markers = int(state["t_measured_ns"]), int(state["markers"])
        self.error, self.frame = float(state["error"]), int(state["frame"])
