"""What ``sensor.camera`` exports as ROS 2 messages (its ``rosbag``): its recorded frames
(``DIR/frames/<camera>/<k>.npz``), each stamped with the time it was taken, in the camera's
optical frame ``<camera>`` (z forward, x right, y down: REP 103's optical frame), which
``/tf_static`` mounts on its link ``<dynamics>/<body>/<link>`` (``T_link_camera``).

| topic | message |
|---|---|
| ``/<camera>/image_raw`` | sensor_msgs/Image, ``rgb8`` |
| ``/<camera>/depth/image_raw`` | sensor_msgs/Image, ``32FC1`` (m along the optical axis, 0 where nothing is hit), with ``depth: true`` |
| ``/<camera>/camera_info`` | sensor_msgs/CameraInfo: ``K``, ``plumb_bob`` ``D``, ``R`` identity, ``P`` = [K 0] |

Without frames (no ``--record``) it exports nothing. The export reads the frames one at a time
as it writes them (:class:`~components.rosbag.LazyMessages`): its memory does not grow with the
number of frames. The live views (``--ros2``, ``--view foxglove``) publish
the same topics and messages from the bus, frame by frame as the camera sends them
(:func:`frame_topics`, :mod:`components.ros_frames`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from components.camera.frames import frame_files, read_frame
from components.rosbag import FrameTopics, LazyMessages, RosContext, RosExport, RosTopic, link_frame, source_of
from components.rotations import matrix_to_quat


def _mount(context: RosContext, camera: str, T_link_camera: np.ndarray) -> list[RosTopic]:
    parameters = context.run.parameters(camera)
    body, link = str(parameters.get("body", "")), str(parameters.get("link", ""))
    source = source_of(context.run, camera, f"{body}.position")
    if source is None:
        return []
    ns = int(context.stamps[0])
    transform = context.transform(
        ns, link_frame(source[0], body, link), camera, T_link_camera[:3, 3], matrix_to_quat(T_link_camera[:3, :3])
    )
    return [RosTopic("/tf_static", "tf2_msgs/msg/TFMessage", [(ns, context.tf([transform]))], latched=True)]


def _camera_info(context: RosContext, camera: str, ns: int, K, D, height: int, width: int) -> object:
    K, D = np.asarray(K, dtype=np.float64), np.asarray(D, dtype=np.float64)
    P = np.hstack([K, np.zeros((3, 1))])
    return context.msg("sensor_msgs/msg/CameraInfo")(
        header=context.header(ns, camera),
        height=height,
        width=width,
        distortion_model="plumb_bob",
        d=D,
        k=K.ravel(),
        r=np.eye(3).ravel(),
        p=P.ravel(),
        binning_x=0,
        binning_y=0,
        roi=context.msg("sensor_msgs/msg/RegionOfInterest")(
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        ),
    )


def _image(context: RosContext, camera: str, ns: int, rgb: np.ndarray) -> object:
    height, width = rgb.shape[:2]
    return context.msg("sensor_msgs/msg/Image")(
        header=context.header(ns, camera),
        height=height,
        width=width,
        encoding="rgb8",
        is_bigendian=0,
        step=3 * width,
        data=rgb.reshape(-1),
    )


def _depth(context: RosContext, camera: str, ns: int, depth: np.ndarray) -> object:
    height, width = depth.shape[:2]
    depth = depth.astype("<f4", copy=False)
    return context.msg("sensor_msgs/msg/Image")(
        header=context.header(ns, camera),
        height=height,
        width=width,
        encoding="32FC1",
        is_bigendian=0,
        step=4 * width,
        data=depth.view(np.uint8).reshape(-1),
    )


def _topics(camera: str) -> tuple[RosTopic, RosTopic, RosTopic]:
    """The camera's image, depth and camera_info topics (no messages)."""
    return (
        RosTopic(f"/{camera}/image_raw", "sensor_msgs/msg/Image"),
        RosTopic(f"/{camera}/depth/image_raw", "sensor_msgs/msg/Image"),
        RosTopic(f"/{camera}/camera_info", "sensor_msgs/msg/CameraInfo"),
    )


def _camera(context: RosContext, camera: str) -> list[RosTopic]:
    """The recorded frames' topics, built frame by frame as the export writes them (each reads
    only its arrays of the file: a frame is decompressed once across the three)."""
    directory = context.run.record_dir
    files = frame_files(Path(directory) / "frames" / camera) if directory is not None else []
    if not files:
        return []
    images, depths, infos = _topics(camera)
    last = read_frame(files[-1])  # the mount as last recorded; all frames of a camera share a size
    height, width = last["rgb"].shape[:2]
    stamps = [context.stamp_of(float(read_frame(path, ("t",))["t"])) for path in files]

    def image(k: int):
        return stamps[k], _image(context, camera, stamps[k], read_frame(files[k], ("rgb",))["rgb"])

    def depth(k: int):
        return stamps[k], _depth(context, camera, stamps[k], read_frame(files[k], ("depth",))["depth"])

    def info(k: int):
        frame = read_frame(files[k], ("K", "D"))
        return stamps[k], _camera_info(
            context, camera, stamps[k], frame["K"], frame.get("D", np.zeros(5)), height, width
        )

    images.messages, infos.messages = LazyMessages(len(files), image), LazyMessages(len(files), info)
    topics = [images]
    if "depth" in last:
        depths.messages = LazyMessages(len(files), depth)
        topics.append(depths)
    return _mount(context, camera, last["T_link_camera"]) + topics + [infos]


def frame_topics(context: RosContext, camera: str) -> FrameTopics | None:
    """The camera's frame outputs live (from the bus): ``rgb`` on ``/<c>/image_raw`` with its
    ``/<c>/camera_info`` (K and D from the parameters, as the camera computes them), ``depth`` on
    ``/<c>/depth/image_raw``; the same messages as the export's for a frame taken at that stamp.
    None when the parameters do not resolve (``orchestrator check`` names the problem)."""
    from components import registry  # the type by its name: camera/component.py imports this module
    from components.sdk import RunSettings, resolve_parameters

    spec = (context.run.config.get("components") or {}).get(camera) or {}
    component_type = registry.load(spec.get("type", "sensor.camera"), context.run.config_dir)
    params, _, errors = resolve_parameters(
        component_type, context.run.parameters(camera), RunSettings(config_dir=context.run.config_dir)
    )
    if errors:
        context.warn(f"{camera}: its frames are not published live ({errors[0]})")
        return None
    K = np.array([[params["fx"], 0.0, params["cx"]], [0.0, params["fy"], params["cy"]], [0.0, 0.0, 1.0]])
    D = np.array(tuple(float(c) for c in params["distortion"] or ()) or (0.0,) * 5)
    images, depths, infos = _topics(camera)

    def messages(output: str, ns: int, frame: np.ndarray) -> list[tuple[RosTopic, object]]:
        if output == "depth":
            return [(depths, _depth(context, camera, ns, frame))]
        height, width = frame.shape[:2]
        return [
            (images, _image(context, camera, ns, frame)),
            (infos, _camera_info(context, camera, ns, K, D, height, width)),
        ]

    outputs = {"rgb": [images, infos], **({"depth": [depths]} if params["depth"] else {})}
    return FrameTopics(outputs, messages)


CAMERA = RosExport(
    "``/<c>/image_raw`` (rgb8), ``/<c>/depth/image_raw`` (32FC1, m), ``/<c>/camera_info`` "
    "from the recorded frames, and live from the bus; the optical frame ``<c>`` on ``/tf_static``",
    _camera,
    frames=frame_topics,
)
