"""``estimator.fiducial``: the grasp frame's pose in the end effector from a camera's images (thin
wrapper of :class:`components.estimators.fiducial.FiducialEstimator` around an embedded
:class:`components.camera.camera.Camera`)."""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from components.camera.camera import CAMERA_PARAMETERS, Camera, camera_inputs, check_camera, check_egl
from components.camera.model import mount_transform
from components.constants import NS_PER_S
from components.errors import ConfigError
from components.estimators.marker_layout import MarkerLayout, layout_path, read_layout
from components.estimators import plots as fiducial_plots
from components.estimators import ros as fiducial_ros
from components.estimators.view import FiducialView
from components.robots.model import read_model
from components.robots.urdf import UrdfModel
from components.rotations import continuous, rpy_to_matrix
from components.schema import Float, Int, Record, Str
from components.sdk import Component, Parameter, Variable

PREFIX = "camera."          # before the names of the camera's inputs


def _layout(params: Mapping[str, Any]) -> MarkerLayout:
    return read_layout(layout_path(params["markers"], params.get("_config_dir")), "markers")


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
        for link in chain[:chain.index(common)]:
            joint = parent[link]
            if joint.type != "fixed":
                raise ValueError(f"joint {joint.name} between them is {joint.type}, not fixed")
            step = np.eye(4)
            step[:3, :3], step[:3, 3] = rpy_to_matrix(joint.rpy), joint.xyz
            T = step @ T
        return T                                  # T_common_link

    return np.linalg.inv(to_common(up_a)) @ to_common(up_b)


def _camera_in_ee(params: Mapping[str, Any]) -> np.ndarray:
    """T_E_camera (4x4) from the URDF and the camera's mount; ConfigError naming the key."""
    camera = params["camera"]
    model = read_model(camera["bodies"][camera["body"]], params.get("_config_dir"), f"camera.bodies.{camera['body']}",
                       params.get("_packages"))
    if params["end_effector"] not in model.link_names:
        raise ConfigError("end_effector", f"expected a link of {camera['body']} ({', '.join(model.link_names)}), "
                                          f"got {params['end_effector']!r}")
    try:
        T_E_link = fixed_transform(model, params["end_effector"], camera["link"])
    except ValueError as e:
        raise ConfigError("end_effector", f"the camera's link {camera['link']} must be {params['end_effector']} or "
                                          f"fixed to it: {e}") from None
    return T_E_link @ mount_transform(camera["position"], camera["orientation"])


class FiducialComponent(Component):
    """A vision pose estimator (type ``estimator.fiducial``): a camera it embeds (``camera``:
    ``sensor.camera``'s parameters) takes a frame each step, in which it finds the fiducial
    markers of a layout (``markers``: models/capture/grapple_markers.yaml for the capture target's
    grapple) and solves the pose of the layout's link G (the grasp frame) in the end-effector
    frame E (``end_effector``, a link of the camera's body). Its outputs are ``sensor.relative_pose``'s
    (``p``, ``q``, ``t_measured``, ``valid``), so a config swaps one for the other.

    Connect the camera's inputs as ``sensor.camera``'s, under ``camera.``: each body's
    ``camera.<body>.position``, ``.orientation``, ``.q`` from the dynamics, ``camera.r_eci`` from
    the orbit. Rate and time: one frame per step of the component (its own ``step:``), rendered
    from the inputs it holds (sampled at t, or when ``input_times_ns`` says); the step's outputs at
    t + h are that frame's solve: ``t_measured`` the frame's time, ``valid`` 1 when it gave a pose
    (at least ``min_markers`` markers, RMS reprojection error at most ``max_reprojection_error``).
    A frame refused leaves ``p`` and ``q`` at the last accepted pose, ``valid`` 0. ``q`` is
    sign-continuous from one accepted pose to the next. With ``--record DIR`` the frames it saw go
    to ``DIR/frames/<component>/<k>.npz`` as ``sensor.camera``'s do (``frame`` counts them), and the
    Rerun view shows them on the camera's frustum.

    The markers must show in the camera's image: the capture target's are meshes of black and
    white cells (``python -m tools.fiducial_markers``), which any renderer of URDF colours draws.

    State: the camera's noise generators, the frames taken and the last outputs.
    """
    type_name = "estimator.fiducial"
    view = FiducialView
    plots = (fiducial_plots.POSE,)
    rosbag = fiducial_ros.POSE
    parameters = (
        Parameter("camera", Record("Camera", CAMERA_PARAMETERS),
                  description="the camera it sees through: sensor.camera's parameters"),
        Parameter("end_effector", Str(), description="the link of camera.body whose frame E the pose is in: "
                                                     "the camera's link, or one fixed to it"),
        Parameter("markers", Str(hint="a marker layout (YAML) file path"),
                  description="the marker layout: dictionary, link, markers' ids, sizes and poses "
                              "(relative to the config)"),
        Parameter("min_markers", Int(minimum=1), description="fewest markers seen for a pose (fewer: valid 0)"),
        Parameter("max_reprojection_error", Float(positive=True),
                  description="largest RMS reprojection error over the markers' corners for a pose (pixels)"),
    )
    OUTPUTS = (
        Variable("p", "output", (3,), "m", [0.0] * 3, "the grasp frame's origin in E (the last accepted pose)"),
        Variable("q", "output", (4,), "1", [0.0, 0.0, 0.0, 1.0],
                 "q_E_G [x, y, z, w] (the last accepted pose), unit, sign-continuous"),
        Variable("t_measured", "output", (), "s", 0.0, "when the latest frame was taken"),
        Variable("valid", "output", (), "1", 0.0, "1 when the latest frame gave a pose, else 0"),
        Variable("markers", "output", (), "1", 0.0, "markers of the layout found in the latest frame"),
        Variable("reprojection_error", "output", (), "px", 0.0,
                 "RMS reprojection error of the latest frame's solve (0 without one)"),
        Variable("frame", "output", (), "1", 0.0,
                 "frames taken so far (with --record, the latest is frames/<component>/<frame - 1>.npz)"),
    )

    @classmethod
    def declare(cls, params):
        return camera_inputs(params["camera"], params, PREFIX) + list(cls.OUTPUTS)

    @classmethod
    def validate(cls, params):
        try:
            check_camera(params["camera"], params)
        except ConfigError as e:
            raise ConfigError(f"camera.{e.key}", e.message) from None
        _camera_in_ee(params)
        layout = _layout(params)
        if params["min_markers"] > len(layout.markers):
            raise ConfigError("min_markers", f"expected at most the layout's {len(layout.markers)} markers, "
                                             f"got {params['min_markers']}")

    @classmethod
    def preflight(cls, params, step_s, full=False):
        """The camera needs an OpenGL context on EGL: checked by making one, at check and run."""
        check_egl(cls.type_name)
        return []

    def __init__(self, params):
        from components.camera.frames import FrameWriter
        from components.estimators.fiducial import FiducialEstimator
        self.params = params
        self.camera = Camera(params["camera"], params, PREFIX)
        self.estimator = FiducialEstimator(_layout(params), params["min_markers"], params["max_reprojection_error"])
        T_E_C = _camera_in_ee(params)
        self.R_ee_camera, self.p_ee_camera = T_E_C[:3, :3].copy(), T_E_C[:3, 3].copy()
        self.writer = FrameWriter(params["_frames"]) if params.get("_frames") else None
        self.k = 0                                  # frames taken
        self.p, self.q = np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0])
        self.accepted = False                       # a pose was accepted (q's sign follows it)
        self.t_measured_ns, self.valid, self.markers, self.error = 0, False, 0, 0.0

    def frame(self, t_ns: int, inputs: Mapping[str, np.ndarray]) -> dict[str, Any]:
        """The camera's frame of what the inputs show at ``t_ns``: ``rgb``, ``K``, ``D`` (its lens's
        plumb_bob distortion), ..."""
        return self.camera.frame(t_ns, inputs)

    def _outputs(self) -> dict[str, Any]:
        return {"p": self.p, "q": self.q, "t_measured": self.t_measured_ns / NS_PER_S, "valid": float(self.valid),
                "markers": float(self.markers), "reprojection_error": self.error, "frame": float(self.k)}

    def initialize(self, t0_ns, inputs):
        return self._outputs()

    def do_step(self, t_ns, h_ns, inputs):
        taken = self.input_times_ns.get(f"{PREFIX}{self.params['camera']['body']}.position", t_ns)
        frame = self.frame(taken, inputs)
        estimate = self.estimator.estimate(frame["rgb"], frame["K"], frame["D"], self.p_ee_camera, self.R_ee_camera)
        self.t_measured_ns, self.valid, self.markers = taken, estimate.valid, estimate.markers
        self.error = estimate.reprojection_error if np.isfinite(estimate.reprojection_error) else 0.0
        if estimate.valid:
            self.p = estimate.p_ee_grasp.copy()
            self.q = continuous(estimate.q_ee_grasp, self.q if self.accepted else None)
            self.accepted = True
        if self.writer is not None:
            self.writer.put(self.k, {key: value for key, value in frame.items()
                                     if key != "lit" and (key != "depth" or self.params["camera"]["depth"])})
        self.k += 1
        return self._outputs()

    def terminate(self):
        if self.writer is not None:
            self.writer.close()
        self.camera.release()

    def get_state(self):
        return {**self.camera.get_state(), "k": np.int64(self.k), "p": self.p.copy(), "q": self.q.copy(),
                "accepted": np.bool_(self.accepted), "t_measured_ns": np.int64(self.t_measured_ns),
                "valid": np.bool_(self.valid), "markers": np.int64(self.markers), "error": np.float64(self.error)}

    def set_state(self, state):
        self.camera.set_state(state)
        self.k = int(state["k"])
        self.p = np.array(state["p"], dtype=np.float64).reshape(3)
        self.q = np.array(state["q"], dtype=np.float64).reshape(4)
        self.accepted, self.valid = bool(state["accepted"]), bool(state["valid"])
        self.t_measured_ns, self.markers = int(state["t_measured_ns"]), int(state["markers"])
        self.error = float(state["error"])
