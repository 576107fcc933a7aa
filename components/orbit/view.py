"""What an orbit component draws in Rerun (its type's ``view``): in the ECI space (/orbit) the
Earth, its ``r_eci`` trail and the spacecraft with its LVLH axes; its ``q_eci_lvlh`` can be the
robot view's axes.

| entity | what |
|---|---|
| ``/orbit/earth`` | the Earth, R = 6378.137 km |
| ``/orbit/<orbit>/trail``, ``/orbit/<orbit>/spacecraft/lvlh`` | ``r_eci`` trail, LVLH axes at the spacecraft |
"""

from __future__ import annotations

import numpy as np

from components.constants import R_EARTH
from components.viewer.robot import normalized_quaternions
from components.viewer.scene import AXIS_COLORS, Batch, Layout, View, entity_path, transform_columns


class OrbitView(View):
    def __init__(self, name, parameters, scene):
        super().__init__(name, parameters, scene)
        self.r_eci = scene.find(name, "r_eci", 3)
        self.lvlh = scene.find(name, "q_eci_lvlh", 4)

    def log_static(self, scene):
        import rerun as rr

        scene.log(
            "/orbit/earth",
            rr.Ellipsoids3D(
                half_sizes=[[R_EARTH] * 3],
                colors=[(40, 100, 210)],
                line_radii=[-0.6],
                fill_mode="transparentfillmajorwireframe",
            ),
            static=True,
        )
        if self.r_eci is None:
            return
        scene.log(
            entity_path("orbit", self.name, "trail"),
            rr.Points3D.from_fields(colors=[(250, 220, 90)], radii=[-1.5]),
            static=True,
        )
        scene.log(
            entity_path("orbit", self.name, "spacecraft", "marker"),
            rr.Points3D([[0.0, 0.0, 0.0]], colors=[(255, 255, 255)], radii=[-5.0]),
            static=True,
        )
        if self.lvlh is not None:
            scene.log(
                entity_path("orbit", self.name, "spacecraft", "lvlh"),
                rr.Arrows3D(
                    origins=np.zeros((3, 3)),
                    vectors=1.5e6 * np.eye(3),
                    colors=AXIS_COLORS,
                    labels=["radial", "along-track", "normal"],
                ),
                static=True,
            )

    def log_rows(self, scene, batch: Batch):
        import rerun as rr

        if self.r_eci is None:
            return
        r = batch.rows[:, self.r_eci]
        batch.send(entity_path("orbit", self.name, "trail"), rr.Points3D.columns(positions=r))
        if self.lvlh is not None:
            batch.send(
                entity_path("orbit", self.name, "spacecraft"),
                transform_columns(translation=r, quaternion=normalized_quaternions(batch.rows[:, self.lvlh])),
            )
        else:
            batch.send(entity_path("orbit", self.name, "spacecraft"), transform_columns(translation=r))

    def layout(self, scene):
        return Layout(orbit=True, trails=[entity_path("orbit", self.name, "trail")] if self.r_eci is not None else [])
