"""What ``sensor.camera`` exports as ROS 2 messages (its ``rosbag``): its recorded frames
(``DIR/frames/<camera>/<k>.npz``), each stamped with the time it was taken, in the camera's
optical frame ``<camera>`` (z forward, x right, y down: REP 103's optical frame), which
``/tf_static`` mounts on its link ``<dynamics>/<body>/<link>`` (``T_link_camera``).

| topic | message |
|---|---|
| ``/<camera>/image_raw`` | sensor_msgs/Image, ``rgb8`` |
| ``/<camera>/depth/image_raw`` | sensor_msgs/Image, ``32FC1`` (m along the optical axis, 0 where nothing is hit), with ``depth: true`` |
| ``/<camera>/camera_info`` | sensor_msgs/CameraInfo: ``K``, ``plumb_bob`` ``D``, ``R`` identity, ``P`` = [K 0] |

Without frames (no ``--record``, or the live views, which read rows only) it exports nothing. The
export holds every frame in memory while it writes (2 MB a frame at 640x480).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from components.camera.frames import frame_files
from components.rosbag import RosContext, RosExport, RosTopic, link_frame, source_of
from components.rotations import matrix_to_quat


def _mount(context: RosContext, camera: str, T_link_camera: np.ndarray) -> list[RosTopic]:
    parameters = context.run.parameters(camera)
    body, link = str(parameters.get("body", "")), str(parameters.get("link", ""))
    source = source_of(context.run, camera, f"{body}.position")
    if source is None:
        return []
    ns = int(context.stamps[0])
    transform = context.transform(ns, link_frame(source[0], body, link), camera, T_link_camera[:3, 3],
                                  matrix_to_quat(T_link_camera[:3, :3]))
    return [RosTopic("/tf_static", "tf2_msgs/msg/TFMessage", [(ns, context.tf([transform]))], latched=True)]


def _camera_info(context: RosContext, camera: str, ns: int, frame) -> object:
    K, D = np.asarray(frame["K"], dtype=np.float64), np.asarray(frame.get("D", np.zeros(5)), dtype=np.float64)
    height, width = frame["rgb"].shape[:2]
    P = np.hstack([K, np.zeros((3, 1))])
    return context.msg("sensor_msgs/msg/CameraInfo")(
        header=context.header(ns, camera), height=height, width=width, distortion_model="plumb_bob", d=D,
        k=K.ravel(), r=np.eye(3).ravel(), p=P.ravel(), binning_x=0, binning_y=0,
        roi=context.msg("sensor_msgs/msg/RegionOfInterest")(x_offset=0, y_offset=0, height=0, width=0,
                                                            do_rectify=False))


def _camera(context: RosContext, camera: str) -> list[RosTopic]:
    directory = context.run.record_dir
    files = frame_files(Path(directory) / "frames" / camera) if directory is not None else []
    if not files:
        return []
    Image = context.msg("sensor_msgs/msg/Image")
    images = RosTopic(f"/{camera}/image_raw", "sensor_msgs/msg/Image")
    depths = RosTopic(f"/{camera}/depth/image_raw", "sensor_msgs/msg/Image")
    infos = RosTopic(f"/{camera}/camera_info", "sensor_msgs/msg/CameraInfo")
    mount = None
    for path in files:
        with np.load(path) as stored:
            frame = {key: stored[key] for key in stored.files}
        ns = context.stamp_of(float(frame["t"]))
        header = context.header(ns, camera)
        height, width = frame["rgb"].shape[:2]
        images.messages.append((ns, Image(header=header, height=height, width=width, encoding="rgb8", is_bigendian=0,
                                          step=3 * width, data=frame["rgb"].reshape(-1))))
        if "depth" in frame:
            depth = frame["depth"].astype("<f4")
            depths.messages.append((ns, Image(header=header, height=height, width=width, encoding="32FC1",
                                              is_bigendian=0, step=4 * width, data=depth.view(np.uint8).reshape(-1))))
        infos.messages.append((ns, _camera_info(context, camera, ns, frame)))
        mount = frame["T_link_camera"]
    return _mount(context, camera, mount) + [topic for topic in (images, depths, infos) if topic.messages]


CAMERA = RosExport("``/<c>/image_raw`` (rgb8), ``/<c>/depth/image_raw`` (32FC1, m), ``/<c>/camera_info`` "
                   "from the recorded frames; the optical frame ``<c>`` on ``/tf_static``", _camera)
