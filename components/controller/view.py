"""What a controller draws in Rerun (its type's ``view``): its end-effector paths in the robot
space, and the paper's plots (Figs. 5, 6, 7).

| entity | what |
|---|---|
| ``/world/<ctrl>/ee_desired``, ``ee_actual`` | end-effector paths (trails: the blueprint shows all past points) |
| ``/plots/<ctrl>/ee_position/{actual,desired}``, ``ee_error/{position,orientation}``, ``tau`` | paper Figs. 5, 6, 7 |
"""

from __future__ import annotations

from components.viewer.scene import LIGHT_AXIS_COLORS, Batch, Layout, View, entity_path


class ControllerView(View):
    def __init__(self, name, parameters, scene):
        super().__init__(name, parameters, scene)
        self.tau = scene.take(name, "tau")
        self.ee_position = scene.take(name, "ee_position", 3)
        self.ee_desired = scene.take(name, "ee_position_desired", 3)
        self.ee_error = scene.take(name, "ee_error", 6)
        self.joints: list[str] | None = None

    def connect(self, scene):
        """The joint names of the body whose ``tau`` input the controller's ``tau`` feeds."""
        body = self._controlled_body(scene)
        joints = body.geometry.joints if body is not None and body.geometry is not None else None
        if self.tau is not None and joints is not None and len(joints) == len(self.tau):
            self.joints = joints

    def _controlled_body(self, scene):
        for destination, source in scene.connections.items():
            if source == f"{self.name}.tau" and destination.endswith(".tau"):
                for body in scene.bodies:
                    if destination == f"{body.dynamics}.{body.name}.tau":
                        return body
        return None

    def log_static(self, scene):
        import rerun as rr

        if self.ee_desired is not None:
            scene.log(
                entity_path("world", self.name, "ee_desired"),
                rr.Points3D.from_fields(colors=[(250, 170, 40)], radii=[-2.0]),
                static=True,
            )
            scene.series(
                entity_path("plots", self.name, "ee_position", "desired"),
                [f"{a} desired" for a in "xyz"],
                LIGHT_AXIS_COLORS,
            )
        if self.ee_position is not None:
            scene.log(
                entity_path("world", self.name, "ee_actual"),
                rr.Points3D.from_fields(colors=[(225, 30, 120)], radii=[-2.5]),
                static=True,
            )
            scene.series(entity_path("plots", self.name, "ee_position", "actual"), [f"{a} actual" for a in "xyz"])
        if self.ee_error is not None:
            scene.series(entity_path("plots", self.name, "ee_error", "position"), [f"e_{a} (m)" for a in "xyz"])
            scene.series(
                entity_path("plots", self.name, "ee_error", "orientation"),
                [f"e_{a} (rad)" for a in ("roll", "pitch", "yaw")],
                LIGHT_AXIS_COLORS,
            )
        if self.tau is not None:
            scene.series(
                entity_path("plots", self.name, "tau"), self.joints or [f"tau[{i}]" for i in range(len(self.tau))]
            )

    def log_rows(self, scene, batch: Batch):
        import rerun as rr

        if self.ee_desired is not None:
            batch.send(
                entity_path("world", self.name, "ee_desired"),
                rr.Points3D.columns(positions=batch.rows[:, self.ee_desired]),
            )
            batch.scalars(entity_path("plots", self.name, "ee_position", "desired"), self.ee_desired)
        if self.ee_position is not None:
            batch.send(
                entity_path("world", self.name, "ee_actual"),
                rr.Points3D.columns(positions=batch.rows[:, self.ee_position]),
            )
            batch.scalars(entity_path("plots", self.name, "ee_position", "actual"), self.ee_position)
        if self.ee_error is not None:
            batch.scalars(entity_path("plots", self.name, "ee_error", "position"), self.ee_error[:3])
            batch.scalars(entity_path("plots", self.name, "ee_error", "orientation"), self.ee_error[3:])
        if self.tau is not None:
            batch.scalars(entity_path("plots", self.name, "tau"), self.tau)

    def layout(self, scene):
        import rerun.blueprint as rrb

        layout = Layout()
        for column, entity in ((self.ee_desired, "ee_desired"), (self.ee_position, "ee_actual")):
            if column is not None:
                layout.world = True
                layout.trails.append(entity_path("world", self.name, entity))
        if self.ee_position is not None or self.ee_desired is not None:
            layout.figures.append(
                rrb.TimeSeriesView(
                    origin=entity_path("plots", self.name, "ee_position"),
                    name=f"{self.name}: end effector, desired vs actual (m, W)",
                )
            )
        if self.ee_error is not None:
            layout.figures.append(
                rrb.TimeSeriesView(
                    origin=entity_path("plots", self.name, "ee_error"), name=f"{self.name}: end-effector error (m, rad)"
                )
            )
        if self.tau is not None:
            layout.figures.append(
                rrb.TimeSeriesView(
                    origin=entity_path("plots", self.name, "tau"),
                    name=f"{self.name}: joint torques (N m)",
                    plot_legend=rrb.PlotLegend(visible=len(self.tau) <= 6),
                )
            )
        return layout
