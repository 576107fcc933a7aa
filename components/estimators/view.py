"""What ``estimator.fiducial`` draws in Rerun: the camera it embeds as ``sensor.camera``'s view
draws one (its frustum on its link, the frames it recorded: :mod:`components.camera.view`); its
pose outputs as plain signals."""
from __future__ import annotations

from components.camera.view import CameraView


class FiducialView(CameraView):
    """The embedded camera (the component's ``camera`` parameters, its inputs under ``camera.``)."""

    def __init__(self, name, parameters, scene):
        super().__init__(name, dict(parameters.get("camera") or {}), scene)

    def connect(self, scene):
        import rerun as rr

        body, link = str(self.parameters.get("body", "")), str(self.parameters.get("link", ""))
        dynamics = scene.connections.get(f"{self.name}.camera.{body}.position", "").partition(".")[0]
        for drawn in scene.bodies:
            if drawn.dynamics == dynamics and drawn.name == body and drawn.drawn and link in drawn.geometry.links:
                self.entity = f"{drawn.base}/links/{rr.escape_entity_path_part(link)}/{rr.escape_entity_path_part(self.name)}"
