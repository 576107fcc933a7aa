"""What a camera draws in Rerun (``sensor.camera``'s ``view``): its frustum on its link in the 3D
scene, and its images, read from the recorded frames (``DIR/frames/<camera>/<k>.npz``).

| entity | what |
|---|---|
| ``<link entity>/<camera>`` | the camera's mount (a transform in its link) and its pinhole: the frustum |
| ``<link entity>/<camera>/rgb``, ``.../depth`` | the latest frame's colour image and depth (m) |

The link entity is the dynamics view's (``/world/<dynamics>/<body>/links/<link>``), found through the
camera's ``<body>.position`` connection; without it (the body not drawn) the camera hangs at
``/world/<camera>`` with its images only. A frame is shown from the row whose ``frame`` count
first includes it; live, a frame whose file is not written yet is shown at a later row. Without
frames (no ``--record``, or ``orchestrator view`` of a recording without them) nothing but the
frustum is drawn.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from components.camera.frames import frame_path, read_frame
from components.viewer.scene import STEP_TIMELINE, TIMELINE, Batch, Layout, View, entity_path


class CameraView(View):
    """One camera: its mount and pinhole (static), its frames as they come."""

    def __init__(self, name, parameters, scene):
        super().__init__(name, parameters, scene)
        self.parameters = parameters
        self.frame = scene.take(name, "frame", 1)
        self.frames_dir = Path(scene.frames_dir) / name if getattr(scene, "frames_dir", None) else None
        self.entity = entity_path("world", name)
        self.shown = 0  # frames shown so far (the next to show is file shown, ...)

    def connect(self, scene):
        import rerun as rr

        body, link = str(self.parameters.get("body", "")), str(self.parameters.get("link", ""))
        source = scene.connections.get(f"{self.name}.{body}.position", "")
        dynamics = source.partition(".")[0]
        for drawn in scene.bodies:
            if drawn.dynamics == dynamics and drawn.name == body and drawn.drawn and link in drawn.geometry.links:
                self.entity = (
                    f"{drawn.base}/links/{rr.escape_entity_path_part(link)}/{rr.escape_entity_path_part(self.name)}"
                )

    def log_static(self, scene):
        import rerun as rr

        p = self.parameters
        try:
            K = [[float(p["fx"]), 0.0, float(p["cx"])], [0.0, float(p["fy"]), float(p["cy"])], [0.0, 0.0, 1.0]]
            resolution = [int(p["width"]), int(p["height"])]
            mount = rr.Transform3D(
                translation=[float(v) for v in p["position"]],
                quaternion=rr.Quaternion(xyzw=[float(v) for v in p["orientation"]]),
            )
        except (KeyError, TypeError, ValueError) as e:  # a raw config with units: no frustum, images only
            scene.warn(f"{self.name}: cannot read its intrinsics or mount from the config ({e}); no frustum drawn")
            return
        far = float(p["far"]) if isinstance(p.get("far"), (int, float)) else 1.0
        scene.log(
            self.entity,
            mount,
            rr.Pinhole(
                image_from_camera=K,
                resolution=resolution,
                camera_xyz=rr.ViewCoordinates.RDF,
                image_plane_distance=min(far, 0.5),
            ),
            static=True,
        )

    def log_rows(self, scene, batch: Batch):
        import rerun as rr

        if self.frame is None or self.frames_dir is None:
            return
        counts = batch.rows[:, self.frame[0]].astype(np.int64)
        for step, time, count in zip(batch.steps, batch.times, counts):
            if count <= self.shown:
                continue
            path = frame_path(self.frames_dir, int(count) - 1)
            if not path.is_file():  # live: not written yet; tried again at the next row
                continue
            frame = read_frame(path, ("rgb", "depth"))
            rgb, depth = frame["rgb"], frame.get("depth")
            rr.set_time(TIMELINE, duration=float(time), recording=scene.rec)
            rr.set_time(STEP_TIMELINE, sequence=int(step), recording=scene.rec)
            scene.log(f"{self.entity}/rgb", rr.Image(rgb))
            if depth is not None:
                scene.log(f"{self.entity}/depth", rr.DepthImage(depth, meter=1.0))
            self.shown = int(count)

    def layout(self, scene):
        import rerun.blueprint as rrb

        return Layout(
            world=True,
            figures=[
                rrb.Spatial2DView(origin=self.entity, contents=f"{self.entity}/rgb", name=f"{self.name}: image"),
                rrb.Spatial2DView(origin=self.entity, contents=f"{self.entity}/depth", name=f"{self.name}: depth (m)"),
            ],
        )
