"""What a dynamics component draws in Rerun (its type's ``view``): its bodies in the robot space
(/world, W) as the simulation poses them, their per-link arrows and plots, and its ``grasp``
(:mod:`components.dynamics.grasp_view`).

| entity | what |
|---|---|
| ``/world/<dyn>/<body>/links/<link>`` | each link's pose in W (Pinocchio forward kinematics of ``position``, ``orientation``, ``q``), URDF visuals as static children |
| ``/world/<dyn>/<body>/com`` | the body's CoM (``com``) |
| ``/world/<dyn>/<body>/gg_torque`` (``tidal_force``, ``drag_force``) | per-link arrows at the link CoMs, scaled (see ``/notes``) |
| ``/world/<dyn>/<chaser>/links/<ee>/grasp_E`` | a ``grasp``'s end-effector frame E (axes, children of the link) |
| ``/world/<dyn>/<chaser>/links/<ee>/grasp_line`` | E to G (``grasp.p_ee_grasp``, E axes) while the grasp is open |
| ``/world/<dyn>/<target>/links/<grasp_frame>/grasp_G``, ``grasp_G/marker`` | the grasp frame G (axes); the marker turns green and larger at the capture |
| ``/plots/<dyn>/<body>/momentum/{linear,angular}``, ``gg_torque_norm`` | momentum, per-link gravity-gradient torque magnitude |
| ``/plots/<dyn>/grasp/distance`` (``/capture``), ``grasp/wrench`` | norm of ``grasp.p_ee_grasp`` (a point at the capture); norms of the force and of the torque of ``grasp.wrench`` |
| ``/events/<dyn>/grasp`` | text log: "capture at t = ... s" on the row where ``grasp.closed`` turns 1 |
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from components.dynamics.grasp_view import Grasp, log_grasp_rows, log_grasp_static
from components.errors import ConfigError
from components.robots.model import body_items, resolve_urdf
from components.rotations import matrix_to_quat, rpy_to_matrix
from components.viewer.robot import Geometry, Kinematics, mesh_arrays, read_geometry
from components.viewer.scene import LIGHT_AXIS_COLORS, Batch, Layout, View, entity_path, transform_columns

VECTOR_FIELDS = {  # per-link 3-vectors drawn as arrows: colour, label, unit
    "gg_torque": ((190, 90, 230), "gravity-gradient torque", "N m"),
    "tidal_force": ((40, 200, 210), "tidal force", "N"),
    "drag_force": ((240, 150, 40), "drag force", "N"),
}


def _start(spec: Mapping) -> tuple[str, np.ndarray] | None:
    """A body's initial base position as configured (``frame``, ``position`` in m; defaults world,
    origin); None when not plain numbers (a raw config with units)."""
    try:
        return str(spec.get("frame", "world")), np.asarray(spec.get("position", (0.0, 0.0, 0.0)), dtype=float).reshape(
            3
        )
    except (TypeError, ValueError):
        return None


@dataclass
class Body:
    """A robot of a dynamics component, drawn from its URDF: column indices of its outputs (None: absent)."""

    dynamics: str
    name: str
    geometry: Geometry | None
    kinematics: Kinematics | None
    position: np.ndarray | None
    orientation: np.ndarray | None
    q: np.ndarray | None
    com: np.ndarray | None
    momentum: np.ndarray | None
    fields: dict[str, np.ndarray] = field(default_factory=dict)
    start: tuple[str, np.ndarray] | None = None  # its initial base position: (frame, m), None if unreadable

    @property
    def base(self) -> str:
        return entity_path("world", self.dynamics, self.name)

    @property
    def drawn(self) -> bool:
        """Its link poses are logged per row (kinematics, base position and orientation known)."""
        return self.kinematics is not None and self.position is not None and self.orientation is not None


class DynamicsView(View):
    """The bodies (``bodies``, read as the dynamics reads them) and the ``grasp`` of a dynamics component."""

    def __init__(self, name, parameters, scene):
        super().__init__(name, parameters, scene)
        self.bodies = self._bodies(scene, name, parameters)
        self.grasps = self._grasps(scene, name, parameters)

    # ------------------------------------------------------------------ discovery

    def _bodies(self, scene, dynamics: str, parameters: dict) -> list[Body]:
        """The bodies of a dynamics component, read as ``dynamics.dart`` reads them (same ``bodies``
        forms, same URDF path resolution from the config's directory): the URDF drawn is the one simulated."""
        bodies: list[Body] = []
        try:
            items = body_items(parameters.get("bodies"))
        except ConfigError as e:
            scene.warn(f"{dynamics}: {e}; no robot drawn")
            return bodies
        for name, spec in items:
            geometry = kinematics = None
            try:
                urdf = resolve_urdf(spec["urdf"], scene.config_dir, f"bodies.{name}.urdf", scene.packages)
            except ConfigError as e:
                urdf = None
                scene.warn(f"{dynamics}.{name}: {e.message}; the robot is not drawn")
            if urdf is not None:
                try:
                    geometry = read_geometry(urdf, scene.packages)
                    kinematics = Kinematics(geometry)
                except Exception as e:  # a URDF Pinocchio cannot load: the plots still work
                    scene.warn(
                        f"{dynamics}.{name}: cannot build the kinematics of {urdf} ({e}); the robot is not drawn"
                    )
                    kinematics = None
            n_joints = len(geometry.joints) if geometry else None
            n_links = len(geometry.links) if geometry else None
            body = Body(
                dynamics,
                name,
                geometry,
                kinematics,
                position=scene.find(dynamics, f"{name}.position", 3),
                orientation=scene.find(dynamics, f"{name}.orientation", 4),
                q=scene.find(dynamics, f"{name}.q"),
                com=scene.take(dynamics, f"{name}.com", 3),
                momentum=scene.take(dynamics, f"{name}.momentum", 6),
                start=_start(spec),
            )
            if body.q is not None and n_joints is not None and len(body.q) != n_joints:
                scene.warn(
                    f"{dynamics}.{name}.q has {len(body.q)} values, the URDF {n_joints} joints; the robot is not drawn"
                )
                body.kinematics = None
            if n_links:
                for key in VECTOR_FIELDS:
                    index = scene.take(dynamics, f"{name}.{key}", 3 * n_links)
                    if index is not None:
                        body.fields[key] = index
            bodies.append(body)
        return bodies

    def _grasps(self, scene, dynamics: str, parameters: dict) -> list[Grasp]:
        """The dynamics' ``grasp`` (none or one), as ``dynamics.dart`` declares it: E and G are links of
        the chaser and the target; its ``grasp.*`` outputs stay under /signals as well."""
        spec = parameters.get("grasp")
        if not isinstance(spec, dict):
            return []
        chaser, ee, target, frame = (str(spec.get(k, "")) for k in ("chaser", "end_effector", "target", "grasp_frame"))
        return [
            Grasp(
                dynamics,
                self._link_entity(scene, dynamics, chaser, ee),
                self._link_entity(scene, dynamics, target, frame),
                p_ee_grasp=scene.find(dynamics, "grasp.p_ee_grasp", 3),
                closed=scene.find(dynamics, "grasp.closed", 1),
                wrench=scene.find(dynamics, "grasp.wrench", 6),
                label=f"{chaser}.{ee} -> {target}.{frame}",
            )
        ]

    def _link_entity(self, scene, dynamics: str, body_name: str, link: str) -> str | None:
        """The entity of ``link`` of a drawn body (its pose logged per row), else None."""
        import rerun as rr

        for body in self.bodies:
            if body.dynamics != dynamics or body.name != body_name or not body.drawn:
                continue
            if link in body.geometry.links:
                return f"{body.base}/links/{rr.escape_entity_path_part(link)}"
            scene.warn(f"{dynamics}.grasp: {link!r} is not a link of {body_name}; that grasp frame is not drawn")
        return None

    # ------------------------------------------------------------------ static content

    def log_static(self, scene):
        for body in self.bodies:
            self._log_body_static(scene, body)
        for grasp in self.grasps:
            log_grasp_static(scene, grasp)
        for body in self.bodies:
            plots = body.base.replace("/world", "/plots", 1)
            if body.momentum is not None:
                scene.series(plots + "/momentum/linear", [f"p_{a} (kg m/s)" for a in "xyz"])
                scene.series(plots + "/momentum/angular", [f"h_{a} (kg m²/s)" for a in "xyz"], LIGHT_AXIS_COLORS)
            if "gg_torque" in body.fields:
                scene.series(plots + "/gg_torque_norm", body.geometry.links)

    def _log_body_static(self, scene, body: Body) -> None:
        import rerun as rr

        if body.geometry is None:
            return
        for k, visual in enumerate(body.geometry.visuals):
            path = f"{body.base}/links/{rr.escape_entity_path_part(visual.link)}/visual_{k}"
            quaternion = matrix_to_quat(rpy_to_matrix(visual.rpy))
            common: dict[str, Any] = dict(
                centers=[visual.xyz], quaternions=[quaternion], colors=[visual.color], fill_mode="solid"
            )
            if visual.kind == "box":
                scene.log(path, rr.Boxes3D(half_sizes=[np.array(visual.size) / 2], **common), static=True)
            elif visual.kind == "cylinder":
                scene.log(path, rr.Cylinders3D(radii=[visual.size[0]], lengths=[visual.size[1]], **common), static=True)
            elif visual.kind == "sphere":
                scene.log(path, rr.Ellipsoids3D(half_sizes=[[visual.size[0]] * 3], **common), static=True)
            elif visual.kind == "mesh":
                problem = self._log_mesh(scene, path, visual, quaternion)
                if problem is None:
                    continue
                fallback = [c for c in body.geometry.collisions if c.link == visual.link]
                drawn = 0
                for i, shape in enumerate(fallback):
                    q = matrix_to_quat(rpy_to_matrix(shape.rpy))
                    where = f"{path}_collision_{i}"
                    style: dict[str, Any] = dict(
                        centers=[shape.xyz], quaternions=[q], colors=[visual.color], fill_mode="solid"
                    )
                    if shape.kind == "box":
                        scene.log(where, rr.Boxes3D(half_sizes=[np.array(shape.size) / 2], **style), static=True)
                    elif shape.kind == "cylinder":
                        scene.log(
                            where, rr.Cylinders3D(radii=[shape.size[0]], lengths=[shape.size[1]], **style), static=True
                        )
                    elif shape.kind == "sphere":
                        scene.log(where, rr.Ellipsoids3D(half_sizes=[[shape.size[0]] * 3], **style), static=True)
                    elif (
                        shape.kind == "mesh"
                        and self._log_mesh(scene, where, dataclasses.replace(shape, color=visual.color), q) is not None
                    ):
                        continue
                    drawn += 1
                if drawn:
                    scene.warn(
                        f"{body.name}: visual mesh of link {visual.link} cannot be drawn ({problem}); "
                        f"drawn from its collision geometry instead"
                    )
                else:
                    scene.warn(
                        f"{body.name}: visual mesh of link {visual.link} cannot be drawn ({problem}) and the link "
                        f"has no collision geometry that can; not drawn"
                    )
        if body.com is not None:
            scene.log(f"{body.base}/com", rr.Points3D.from_fields(colors=[(255, 230, 0)], radii=[-4.0]), static=True)
        for key, _index in body.fields.items():
            color, _, _ = VECTOR_FIELDS[key]
            scene.log(f"{body.base}/{key}", rr.Arrows3D.from_fields(colors=[color], radii=[-1.5]), static=True)

    def _log_mesh(self, scene, path: str, visual, quaternion) -> str | None:
        """A mesh visual at ``path``: .stl/.obj/.glb/.gltf as Rerun reads them, anything else (.dae
        ...) converted with trimesh into a Mesh3D; None when drawn, else why not."""
        import rerun as rr

        if visual.mesh is None:
            return "file not found"
        transform = rr.Transform3D(translation=visual.xyz, quaternion=quaternion, scale=visual.size)
        if visual.mesh.suffix.lower() in (".stl", ".obj", ".glb", ".gltf"):
            scene.log(path, transform, rr.Asset3D(path=visual.mesh), static=True)
            return None
        try:
            vertices, triangles, normals, colors = mesh_arrays(visual.mesh)
        except Exception as e:  # trimesh's and pycollada's own exceptions for a file they cannot read
            return f"{visual.mesh.name}: {type(e).__name__}: {e}"
        if colors is None:
            colors = np.tile(np.array(visual.color, dtype=np.uint8), (len(vertices), 1))
        scene.log(
            path,
            transform,
            rr.Mesh3D(
                vertex_positions=vertices, triangle_indices=triangles, vertex_normals=normals, vertex_colors=colors
            ),
            static=True,
        )
        return None

    # ------------------------------------------------------------------ rows

    def log_rows(self, scene, batch: Batch):
        for body in self.bodies:
            self._log_body(scene, body, batch)
        for grasp in self.grasps:
            log_grasp_rows(grasp, batch)

    def _log_body(self, scene, body: Body, batch: Batch) -> None:
        """Link poses, CoM, per-link arrows and plots of one body."""
        import rerun as rr

        rows, send = batch.rows, batch.send
        plots = body.base.replace("/world", "/plots", 1)
        n = len(rows)
        rotations = None
        if body.kinematics is not None and body.position is not None and body.orientation is not None:
            q = rows[:, body.q] if body.q is not None else np.zeros((n, body.kinematics.n_joints))
            translations, rotations = body.kinematics.link_poses(rows[:, body.position], rows[:, body.orientation], q)
            quaternions = matrix_to_quat(rotations)
            assert body.geometry is not None  # the kinematics is built from it
            for j, link in enumerate(body.geometry.links):
                send(
                    f"{body.base}/links/{rr.escape_entity_path_part(link)}",
                    transform_columns(translations[:, j], quaternions[:, j]),
                )
        if body.com is not None:
            send(f"{body.base}/com", rr.Points3D.columns(positions=rows[:, body.com]))
        if body.momentum is not None:
            send(plots + "/momentum/linear", rr.Scalars.columns(scalars=rows[:, body.momentum[:3]]))
            send(plots + "/momentum/angular", rr.Scalars.columns(scalars=rows[:, body.momentum[3:]]))
        if body.fields:
            assert body.geometry is not None  # the fields are per link of it
            L = len(body.geometry.links)
            if rotations is not None:  # arrows start at the link CoMs, in W
                origins = translations + np.einsum("nlij,lj->nli", rotations, body.geometry.coms)
            for key, index in body.fields.items():
                vectors = rows[:, index].reshape(n, L, 3)
                if key == "gg_torque":
                    send(plots + "/gg_torque_norm", rr.Scalars.columns(scalars=np.linalg.norm(vectors, axis=2)))
                if rotations is None:
                    continue
                scale = scene.arrow_scale((body.dynamics, body.name, key), VECTOR_FIELDS[key][2], vectors)
                if scale is None:
                    continue
                send(
                    f"{body.base}/{key}",
                    rr.Arrows3D.columns(
                        origins=origins.reshape(-1, 3), vectors=scale * vectors.reshape(-1, 3)
                    ).partition([L] * n),
                )

    def layout(self, scene):
        import rerun.blueprint as rrb

        layout = Layout(world=bool(self.bodies), events=any(g.closed is not None for g in self.grasps))
        for g in self.grasps:
            if g.p_ee_grasp is not None:
                layout.figures.append(
                    rrb.TimeSeriesView(origin=g.plots + "/distance", name=f"{g.dynamics}: grasp, E to G distance (m)")
                )
            if g.wrench is not None:
                layout.figures.append(
                    rrb.TimeSeriesView(
                        origin=g.plots + "/wrench", name=f"{g.dynamics}: grasp wrench on the target (N, N m)"
                    )
                )
        for b in self.bodies:
            if b.momentum is not None:
                layout.tabs.append(
                    rrb.TimeSeriesView(
                        origin=b.base.replace("/world", "/plots", 1) + "/momentum", name=f"{b.name}: momentum (W)"
                    )
                )
            if "gg_torque" in b.fields:
                layout.tabs.append(
                    rrb.TimeSeriesView(
                        origin=b.base.replace("/world", "/plots", 1) + "/gg_torque_norm",
                        name=f"{b.name}: gravity-gradient torque per link (N m)",
                    )
                )
        return layout
