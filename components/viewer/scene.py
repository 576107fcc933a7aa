"""Recorded rows -> Rerun log calls: the content and layout of the Zenorbit view (no bus, no I/O).

``SceneLogger(columns, config, config_dir, recording)`` looks at the resolved config (components by
their ``type``: ``orbit.*``, ``dynamics.*`` with ``bodies``, ``controller.*``) and at the recorded
column names (``<component>.<name>`` or ``<component>.<name>[i]``, docs/design.md §6), and then turns
batches of rows (step, time, one float64 per column) into columnar Rerun logs on two timelines,
``sim_time`` (a duration, s) and ``step`` (a sequence). Whatever is absent is simply not shown.

Entities (SI units; W = the dynamics world frame, ECI = GCRF axes):

| entity | what |
|---|---|
| ``/world/<dyn>/<body>/links/<link>`` | each link's pose in W (Pinocchio forward kinematics of ``position``, ``orientation``, ``q``), URDF visuals as static children |
| ``/world/<dyn>/<body>/com`` | the body's CoM (``com``) |
| ``/world/<dyn>/<body>/gg_torque`` (``tidal_force``, ``drag_force``) | per-link arrows at the link CoMs, scaled (see ``/notes``) |
| ``/world/<ctrl>/ee_desired``, ``ee_actual`` | end-effector paths (trails: the blueprint shows all past points) |
| ``/world/<dyn>/<chaser>/links/<ee>/grasp_E`` | a ``grasp``'s end-effector frame E (axes, children of the link) |
| ``/world/<dyn>/<chaser>/links/<ee>/grasp_line`` | E to G (``grasp.p_ee_grasp``, E axes) while the grasp is open |
| ``/world/<dyn>/<target>/links/<grasp_frame>/grasp_G``, ``grasp_G/marker`` | the grasp frame G (axes); the marker turns green and larger at the capture |
| ``/world/lvlh/axes`` | LVLH axes at the W origin (``q_eci_lvlh``; W axes are ECI axes) |
| ``/orbit/earth`` | the Earth, R = 6378.137 km |
| ``/orbit/<orbit>/trail``, ``/orbit/<orbit>/spacecraft/lvlh`` | ``r_eci`` trail, LVLH axes at the spacecraft |
| ``/plots/<ctrl>/ee_position/{actual,desired}``, ``ee_error/{position,orientation}``, ``tau`` | paper Figs. 5, 6, 7 |
| ``/plots/<dyn>/<body>/momentum/{linear,angular}``, ``gg_torque_norm`` | momentum, per-link gravity-gradient torque magnitude |
| ``/plots/<dyn>/grasp/distance`` (``/capture``), ``grasp/wrench`` | norm of ``grasp.p_ee_grasp`` (a point at the capture); norms of the force and of the torque of ``grasp.wrench`` |
| ``/events/<dyn>/grasp`` | text log: "capture at t = ... s" on the row where ``grasp.closed`` turns 1 |
| ``/signals/<component>/<name>`` | every other recorded variable, one plot series per element |
| ``/notes`` | run summary and arrow scales (text) |
"""
from __future__ import annotations

import dataclasses
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from components.constants import R_EARTH
from components.errors import ConfigError
from components.robots.model import body_items, resolve_urdf
from components.rotations import matrix_to_quat, rpy_to_matrix
from components.viewer.robot import Geometry, Kinematics, mesh_arrays, normalized_quaternions, read_geometry

TIMELINE = "sim_time"
STEP_TIMELINE = "step"
COLUMN = re.compile(r"^(?P<component>[^.\[]+)\.(?P<name>[^\[]+?)(?:\[(?P<index>\d+)\])?$")
AXIS_COLORS = [(230, 60, 60), (60, 200, 80), (70, 110, 240)]
LIGHT_AXIS_COLORS = [(250, 160, 150), (150, 230, 160), (150, 180, 250)]
VECTOR_FIELDS = {            # per-link 3-vectors drawn as arrows: colour, label
    "gg_torque": ((190, 90, 230), "gravity-gradient torque"),
    "tidal_force": ((40, 200, 210), "tidal force"),
    "drag_force": ((240, 150, 40), "drag force"),
}
BULK = ("link_position", "link_orientation")      # drawn through the link poses, never plotted
ARROW_LENGTH = 0.25                                # m, the longest arrow of a field when first seen
ROBOT_EYE = (1.9, -1.6, 1.0)                       # m, initial camera of the robot view
BODY_REACH = 1.5                                   # m, about a body's extent around its base (the camera's margin)
GRASP_AXES = {"E": (0.15, AXIS_COLORS, -2.0), "G": (0.25, LIGHT_AXIS_COLORS, -1.5)}   # m, colours, radius (ui)
GRASP_OPEN = ((250, 170, 40), 0.02, "G")           # G marker while open: colour, radius (m), label
GRASP_CLOSED = ((60, 220, 90), 0.07, "G captured")  # ... once the grasp has closed


def parse_columns(columns: list[str]) -> dict[tuple[str, str], np.ndarray]:
    """``[c.x[0], c.x[1], c.y]`` -> {(c, x): [0, 1], (c, y): [2]}: column indices by variable, in element order."""
    found: dict[tuple[str, str], list[tuple[int, int]]] = {}
    for position, column in enumerate(columns):
        match = COLUMN.match(column)
        if not match:
            continue
        element = int(match["index"]) if match["index"] is not None else 0
        found.setdefault((match["component"], match["name"]), []).append((element, position))
    return {key: np.array([p for _, p in sorted(items)], dtype=np.int64) for key, items in found.items()}


def transform_columns(translation=None, quaternion=None) -> list:
    """``rr.Transform3D.columns`` for one row per transform, built from described component batches
    directly (the archetype helper costs ~40 % more per call; the link poses call it once per link)."""
    import rerun as rr
    from rerun.components import RotationQuatBatch, Translation3DBatch

    columns = []
    for values, batch, descriptor in ((translation, Translation3DBatch, rr.Transform3D.descriptor_translation),
                                      (quaternion, RotationQuatBatch, rr.Transform3D.descriptor_quaternion)):
        if values is not None:
            values = np.asarray(values, dtype=np.float32)
            columns.append(batch(values).described(descriptor()).partition(np.ones(len(values), dtype=np.int32)))
    return columns


def _indexes(steps: np.ndarray, times: np.ndarray) -> list:
    """The two timelines of rows: ``sim_time`` (a duration, from ``times`` in s) and ``step``."""
    import rerun as rr
    return [rr.TimeColumn(TIMELINE, duration=times), rr.TimeColumn(STEP_TIMELINE, sequence=steps)]


def _start(spec: dict) -> tuple[str, np.ndarray] | None:
    """A body's initial base position as configured (``frame``, ``position`` in m; defaults world,
    origin); None when not plain numbers (a raw config with units)."""
    try:
        return str(spec.get("frame", "world")), np.asarray(spec.get("position", (0.0, 0.0, 0.0)), dtype=float).reshape(3)
    except (TypeError, ValueError):
        return None


def _path(*parts: str) -> str:
    import rerun as rr
    return "/" + "/".join(rr.escape_entity_path_part(p) for p in parts)


@dataclass
class _Body:
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
    start: tuple[str, np.ndarray] | None = None     # its initial base position: (frame, m), None if unreadable

    @property
    def base(self) -> str:
        return _path("world", self.dynamics, self.name)

    @property
    def drawn(self) -> bool:
        """Its link poses are logged per row (kinematics, base position and orientation known)."""
        return self.kinematics is not None and self.position is not None and self.orientation is not None


@dataclass
class _Controller:
    name: str
    ee_position: np.ndarray | None
    ee_desired: np.ndarray | None
    ee_error: np.ndarray | None
    tau: np.ndarray | None
    joints: list[str] | None


@dataclass
class _Grasp:
    """A dynamics' ``grasp``: E (``end_effector``, a link of ``chaser``) meets G (``grasp_frame``, a
    link of ``target``). ``ee_link``/``grasp_link``: the link entities, None when that body is not drawn."""
    dynamics: str
    ee_link: str | None
    grasp_link: str | None
    p_ee_grasp: np.ndarray | None
    closed: np.ndarray | None
    wrench: np.ndarray | None
    label: str
    was_closed: bool | None = None      # grasp.closed at the last row logged (None: no row yet)

    @property
    def plots(self) -> str:
        return _path("plots", self.dynamics, "grasp")

    @property
    def events(self) -> str:
        return _path("events", self.dynamics, "grasp")


@dataclass
class _Orbit:
    name: str
    r_eci: np.ndarray | None
    q_eci_lvlh: np.ndarray | None


class SceneLogger:
    """Turns rows of a Zenorbit run into Rerun log calls on ``recording`` (a ``rr.RecordingStream``).

    Call ``log_static()`` once, then ``log_rows(steps, times, rows)`` with batches of rows in time
    order (``rows``: shape (n, len(columns)), float64). ``blueprint()`` lays the views out.
    """

    def __init__(self, columns: list[str], config: dict, config_dir: str | Path | None = None, *,
                 recording=None, warn: Callable[[str], None] | None = None):
        self.columns = list(columns)
        self.config = config or {}
        self.config_dir = Path(config_dir) if config_dir else None
        # run.packages as the run resolved them: relative to the config's directory
        packages = (self.config.get("run") or {}).get("packages") or {}
        self.packages = {str(k): str((self.config_dir or Path(".")) / str(v)) for k, v in packages.items()} \
            if isinstance(packages, dict) else {}
        self.rec = recording
        self.warn = warn or (lambda message: print(f"viewer: {message}", file=sys.stderr, flush=True))
        self.variables = parse_columns(self.columns)
        self.shown: set[tuple[str, str]] = set()
        components = self.config.get("components") or {}
        types = {name: self._type_name(str((entry or {}).get("type", ""))) for name, entry in components.items()}
        self.connections = {str(k): str(v) for k, v in (self.config.get("connections") or {}).items()}
        self.bodies = [body for name, t in types.items() if t.startswith("dynamics.")
                       for body in self._bodies(name, components[name])]
        self.controllers = [self._controller(name) for name, t in types.items() if t.startswith("controller.")]
        self.orbits = [self._orbit(name) for name, t in types.items() if t.startswith("orbit.")]
        self.grasps = [grasp for name, t in types.items() if t.startswith("dynamics.")
                       for grasp in self._grasps(name, components[name])]
        self.world_lvlh = self._world_lvlh()
        for key in self.variables:
            if key[1].split(".")[-1] in BULK:
                self.shown.add(key)
        self.signals = [key for key in self.variables if key not in self.shown]
        self.arrow_scales: dict[tuple[str, str, str], float] = {}
        self.rows_logged = 0

    # ------------------------------------------------------------------ discovery

    def _type_name(self, type_: str) -> str:
        """A registered type name as is; for ``module:Class`` / ``file.py:Class``, the class's ``type_name``."""
        if ":" not in type_:
            return type_
        try:
            from components import registry
            return registry.load(type_, self.config_dir).type_name or type_
        except Exception:
            return type_

    def _find(self, component: str, name: str, size: int | None = None) -> np.ndarray | None:
        """Column indices of ``component.name``, or None if absent or not of ``size`` elements."""
        index = self.variables.get((component, name))
        if index is None or (size is not None and len(index) != size):
            return None
        return index

    def _take(self, component: str, name: str, size: int | None = None) -> np.ndarray | None:
        """As ``_find``, and the variable is shown elsewhere than under /signals."""
        index = self._find(component, name, size)
        if index is not None:
            self.shown.add((component, name))
        return index

    def _bodies(self, dynamics: str, entry: dict) -> list[_Body]:
        """The bodies of a dynamics component, read as ``dynamics.dart`` reads them (same ``bodies``
        forms, same URDF path resolution from the config's directory): the URDF drawn is the one simulated."""
        bodies = []
        parameters = (entry or {}).get("parameters") or {}
        try:
            items = body_items(parameters.get("bodies"))
        except ConfigError as e:
            self.warn(f"{dynamics}: {e}; no robot drawn")
            return bodies
        for name, spec in items:
            geometry = kinematics = None
            try:
                urdf = resolve_urdf(spec["urdf"], self.config_dir, f"bodies.{name}.urdf", self.packages)
            except ConfigError as e:
                urdf = None
                self.warn(f"{dynamics}.{name}: {e.message}; the robot is not drawn")
            if urdf is not None:
                try:
                    geometry = read_geometry(urdf, self.packages)
                    kinematics = Kinematics(geometry)
                except Exception as e:  # a URDF Pinocchio cannot load: the plots still work
                    self.warn(f"{dynamics}.{name}: cannot build the kinematics of {urdf} ({e}); the robot is not drawn")
                    kinematics = None
            n_joints = len(geometry.joints) if geometry else None
            n_links = len(geometry.links) if geometry else None
            body = _Body(dynamics, name, geometry, kinematics,
                         position=self._find(dynamics, f"{name}.position", 3),
                         orientation=self._find(dynamics, f"{name}.orientation", 4),
                         q=self.variables.get((dynamics, f"{name}.q")),
                         com=self._take(dynamics, f"{name}.com", 3),
                         momentum=self._take(dynamics, f"{name}.momentum", 6), start=_start(spec))
            if body.q is not None and n_joints is not None and len(body.q) != n_joints:
                self.warn(f"{dynamics}.{name}.q has {len(body.q)} values, the URDF {n_joints} joints; "
                          "the robot is not drawn")
                body.kinematics = None
            if n_links:
                for key in VECTOR_FIELDS:
                    index = self._take(dynamics, f"{name}.{key}", 3 * n_links)
                    if index is not None:
                        body.fields[key] = index
            bodies.append(body)
        return bodies

    def _grasps(self, dynamics: str, entry: dict) -> list[_Grasp]:
        """The dynamics' ``grasp`` (none or one), as ``dynamics.dart`` declares it: E and G are links of
        the chaser and the target; its ``grasp.*`` outputs stay under /signals as well."""
        spec = ((entry or {}).get("parameters") or {}).get("grasp")
        if not isinstance(spec, dict):
            return []
        chaser, ee, target, frame = (str(spec.get(k, "")) for k in ("chaser", "end_effector", "target", "grasp_frame"))
        return [_Grasp(dynamics, self._link_entity(dynamics, chaser, ee), self._link_entity(dynamics, target, frame),
                       p_ee_grasp=self._find(dynamics, "grasp.p_ee_grasp", 3),
                       closed=self._find(dynamics, "grasp.closed", 1),
                       wrench=self._find(dynamics, "grasp.wrench", 6), label=f"{chaser}.{ee} -> {target}.{frame}")]

    def _link_entity(self, dynamics: str, body_name: str, link: str) -> str | None:
        """The entity of ``link`` of a drawn body (its pose logged per row), else None."""
        import rerun as rr

        for body in self.bodies:
            if body.dynamics != dynamics or body.name != body_name or not body.drawn:
                continue
            if link in body.geometry.links:
                return f"{body.base}/links/{rr.escape_entity_path_part(link)}"
            self.warn(f"{dynamics}.grasp: {link!r} is not a link of {body_name}; that grasp frame is not drawn")
        return None

    def _controlled_body(self, controller: str) -> _Body | None:
        """The body whose ``tau`` input the controller's ``tau`` feeds (from the connections)."""
        for destination, source in self.connections.items():
            if source == f"{controller}.tau" and destination.endswith(".tau"):
                for body in self.bodies:
                    if destination == f"{body.dynamics}.{body.name}.tau":
                        return body
        return None

    def _controller(self, name: str) -> _Controller:
        tau = self._take(name, "tau")
        body = self._controlled_body(name)
        joints = body.geometry.joints if body is not None and body.geometry is not None else None
        if tau is not None and joints is not None and len(joints) != len(tau):
            joints = None
        return _Controller(name, ee_position=self._take(name, "ee_position", 3),
                           ee_desired=self._take(name, "ee_position_desired", 3),
                           ee_error=self._take(name, "ee_error", 6), tau=tau, joints=joints)

    def _orbit(self, name: str) -> _Orbit:
        return _Orbit(name, r_eci=self._find(name, "r_eci", 3), q_eci_lvlh=self._find(name, "q_eci_lvlh", 4))

    def _world_lvlh(self) -> np.ndarray | None:
        """LVLH attitude for the robot view: the orbit output feeding the dynamics, else the first orbit."""
        feeding = [source for destination, source in self.connections.items()
                   if destination.endswith(".q_eci_lvlh") and any(destination.startswith(f"{b.dynamics}.")
                                                                   for b in self.bodies)]
        for orbit in self.orbits:
            if f"{orbit.name}.q_eci_lvlh" in feeding and orbit.q_eci_lvlh is not None:
                return orbit.q_eci_lvlh
        if self.bodies:
            return next((o.q_eci_lvlh for o in self.orbits if o.q_eci_lvlh is not None), None)
        return None

    # ------------------------------------------------------------------ layout

    def _trail(self):
        import rerun.blueprint as rrb
        return rrb.VisibleTimeRanges(timeline=TIMELINE, start=rrb.TimeRangeBoundary.infinite(),
                                     end=rrb.TimeRangeBoundary.cursor_relative())

    def _camera(self) -> tuple[np.ndarray, np.ndarray]:
        """Eye and look target of the robot view: ROBOT_EYE on the origin, unless the bodies start apart
        (initial positions in the view's axes: LVLH-framed ones in the LVLH view, all in the W view);
        then looking at their centre from the side of the line through them, far enough to see them all."""
        frames = ("lvlh",) if self.world_lvlh is not None else ("lvlh", "world")
        starts = [b.start for b in self.bodies]
        eye, target = np.array(ROBOT_EYE), np.zeros(3)
        if len(starts) < 2 or any(s is None or s[0] not in frames for s in starts):
            return eye, target
        points = np.array([position for _, position in starts])
        center = (points.min(axis=0) + points.max(axis=0)) / 2
        offsets = points - center
        spread = float(np.linalg.norm(offsets, axis=1).max())
        if spread < 0.5:
            return eye, target
        axis = offsets[np.argmax(np.linalg.norm(offsets, axis=1))] / spread
        side = eye / np.linalg.norm(eye)
        side = side - (side @ axis) * axis                    # at right angles to the line of the bodies
        side = side / np.linalg.norm(side) if np.linalg.norm(side) > 1e-6 else eye / np.linalg.norm(eye)
        return center + max(np.linalg.norm(eye), 2.0 * (spread + BODY_REACH)) * side, center

    def blueprint(self):
        """The layout: robots and orbit in 3D on the left, the paper's plots in the middle, the rest in tabs."""
        import rerun.blueprint as rrb

        spatial = []
        eye, target = self._camera()
        if self.bodies or any(c.ee_position is not None or c.ee_desired is not None for c in self.controllers):
            trails = {}
            for c in self.controllers:
                if c.ee_desired is not None:
                    trails[_path("world", c.name, "ee_desired")] = self._trail()
                if c.ee_position is not None:
                    trails[_path("world", c.name, "ee_actual")] = self._trail()
            if self.world_lvlh is not None:   # seen from LVLH (z orbit normal up): a steady camera
                spatial.append(rrb.Spatial3DView(
                    origin="/world/lvlh", contents="/world/**", name="Robots (W, seen in LVLH axes)",
                    overrides=trails, eye_controls=rrb.EyeControls3D(position=eye, look_target=target)))
            else:
                spatial.append(rrb.Spatial3DView(origin="/world", name="Robots (W frame)", overrides=trails,
                                                 eye_controls=rrb.EyeControls3D(position=eye, look_target=target)))
        if self.orbits:
            trails = {_path("orbit", o.name, "trail"): self._trail() for o in self.orbits if o.r_eci is not None}
            spatial.append(rrb.Spatial3DView(origin="/orbit", name="Orbit (ECI)", overrides=trails,
                                             line_grid=rrb.LineGrid3D(visible=False)))
        figures = []
        for c in self.controllers:
            if c.ee_position is not None or c.ee_desired is not None:
                figures.append(rrb.TimeSeriesView(origin=_path("plots", c.name, "ee_position"),
                                                  name=f"{c.name}: end effector, desired vs actual (m, W)"))
            if c.ee_error is not None:
                figures.append(rrb.TimeSeriesView(origin=_path("plots", c.name, "ee_error"),
                                                  name=f"{c.name}: end-effector error (m, rad)"))
            if c.tau is not None:
                figures.append(rrb.TimeSeriesView(origin=_path("plots", c.name, "tau"),
                                                  name=f"{c.name}: joint torques (N m)",
                                                  plot_legend=rrb.PlotLegend(visible=len(c.tau) <= 6)))
        for g in self.grasps:
            if g.p_ee_grasp is not None:
                figures.append(rrb.TimeSeriesView(origin=g.plots + "/distance",
                                                  name=f"{g.dynamics}: grasp, E to G distance (m)"))
            if g.wrench is not None:
                figures.append(rrb.TimeSeriesView(origin=g.plots + "/wrench",
                                                  name=f"{g.dynamics}: grasp wrench on the target (N, N m)"))
        tabs = []
        for b in self.bodies:
            if b.momentum is not None:
                tabs.append(rrb.TimeSeriesView(origin=b.base.replace("/world", "/plots", 1) + "/momentum",
                                               name=f"{b.name}: momentum (W)"))
            if "gg_torque" in b.fields:
                tabs.append(rrb.TimeSeriesView(origin=b.base.replace("/world", "/plots", 1) + "/gg_torque_norm",
                                               name=f"{b.name}: gravity-gradient torque per link (N m)"))
        for component in dict.fromkeys(c for c, _ in self.signals):
            tabs.append(rrb.TimeSeriesView(origin=_path("signals", component), name=f"{component} signals"))
        if any(g.closed is not None for g in self.grasps):
            tabs.append(rrb.TextLogView(origin="/events", name="Events"))
        tabs.append(rrb.TextDocumentView(origin="/notes", name="Run"))
        columns = []
        if spatial:
            columns.append(rrb.Vertical(*spatial))
        if figures:
            columns.append(rrb.Vertical(*figures))
        columns.append(rrb.Tabs(*tabs))
        layout = rrb.Horizontal(*columns, column_shares=[3, 2, 2][:len(columns)] if len(columns) > 1 else None)
        return rrb.Blueprint(layout, rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"),
                             rrb.TimePanel(state="collapsed", timeline=TIMELINE, play_state="following"))

    # ------------------------------------------------------------------ static content

    def _log(self, path: str, *archetypes, static: bool = False) -> None:
        import rerun as rr
        rr.log(path, *archetypes, static=static, recording=self.rec)

    def log_static(self) -> None:
        """Everything that does not change: visuals, the Earth, axes, plot series names and colours."""
        import rerun as rr

        for root in ("/world", "/world/lvlh", "/orbit"):
            self._log(root, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        for body in self.bodies:
            self._log_body_static(body)
        for grasp in self.grasps:
            self._log_grasp_static(grasp)
        for c in self.controllers:
            if c.ee_desired is not None:
                self._log(_path("world", c.name, "ee_desired"),
                          rr.Points3D.from_fields(colors=[(250, 170, 40)], radii=[-2.0]), static=True)
                self._series(_path("plots", c.name, "ee_position", "desired"),
                             [f"{a} desired" for a in "xyz"], LIGHT_AXIS_COLORS)
            if c.ee_position is not None:
                self._log(_path("world", c.name, "ee_actual"),
                          rr.Points3D.from_fields(colors=[(225, 30, 120)], radii=[-2.5]), static=True)
                self._series(_path("plots", c.name, "ee_position", "actual"), [f"{a} actual" for a in "xyz"])
            if c.ee_error is not None:
                self._series(_path("plots", c.name, "ee_error", "position"), [f"e_{a} (m)" for a in "xyz"])
                self._series(_path("plots", c.name, "ee_error", "orientation"), [f"e_{a} (rad)" for a in
                                                                                   ("roll", "pitch", "yaw")],
                             LIGHT_AXIS_COLORS)
            if c.tau is not None:
                self._series(_path("plots", c.name, "tau"), c.joints or [f"tau[{i}]" for i in range(len(c.tau))])
        if self.world_lvlh is not None:
            self._log("/world/lvlh/axes", rr.Arrows3D(origins=np.zeros((3, 3)), vectors=0.3 * np.eye(3),
                                                      colors=AXIS_COLORS, radii=[-1.5]), static=True)
        if self.orbits:
            self._log("/orbit/earth", rr.Ellipsoids3D(half_sizes=[[R_EARTH] * 3], colors=[(40, 100, 210)],
                                                      line_radii=[-0.6], fill_mode="transparentfillmajorwireframe"),
                      static=True)
        for o in self.orbits:
            if o.r_eci is None:
                continue
            self._log(_path("orbit", o.name, "trail"), rr.Points3D.from_fields(colors=[(250, 220, 90)], radii=[-1.5]),
                      static=True)
            self._log(_path("orbit", o.name, "spacecraft", "marker"),
                      rr.Points3D([[0.0, 0.0, 0.0]], colors=[(255, 255, 255)], radii=[-5.0]),
                      static=True)
            if o.q_eci_lvlh is not None:
                self._log(_path("orbit", o.name, "spacecraft", "lvlh"),
                          rr.Arrows3D(origins=np.zeros((3, 3)), vectors=1.5e6 * np.eye(3), colors=AXIS_COLORS,
                                      labels=["radial", "along-track", "normal"]), static=True)
        for body in self.bodies:
            plots = body.base.replace("/world", "/plots", 1)
            if body.momentum is not None:
                self._series(plots + "/momentum/linear", [f"p_{a} (kg m/s)" for a in "xyz"])
                self._series(plots + "/momentum/angular", [f"h_{a} (kg m²/s)" for a in "xyz"], LIGHT_AXIS_COLORS)
            if "gg_torque" in body.fields:
                self._series(plots + "/gg_torque_norm", body.geometry.links)
        for component, name in self.signals:
            n = len(self.variables[component, name])
            self._series(_path("signals", component, name), [name] if n == 1 else [f"{name}[{i}]" for i in range(n)])
        self._notes()

    def _series(self, path: str, names: list[str], colors=None) -> None:
        import rerun as rr
        if colors is None and len(names) <= 3:
            colors = AXIS_COLORS
        self._log(path, rr.SeriesLines(names=names, colors=colors[:len(names)] if colors else None), static=True)

    def _log_body_static(self, body: _Body) -> None:
        import rerun as rr

        if body.geometry is None:
            return
        for k, visual in enumerate(body.geometry.visuals):
            path = f"{body.base}/links/{rr.escape_entity_path_part(visual.link)}/visual_{k}"
            quaternion = matrix_to_quat(rpy_to_matrix(visual.rpy))
            common = dict(centers=[visual.xyz], quaternions=[quaternion], colors=[visual.color], fill_mode="solid")
            if visual.kind == "box":
                self._log(path, rr.Boxes3D(half_sizes=[np.array(visual.size) / 2], **common), static=True)
            elif visual.kind == "cylinder":
                self._log(path, rr.Cylinders3D(radii=[visual.size[0]], lengths=[visual.size[1]], **common), static=True)
            elif visual.kind == "sphere":
                self._log(path, rr.Ellipsoids3D(half_sizes=[[visual.size[0]] * 3], **common), static=True)
            elif visual.kind == "mesh":
                problem = self._log_mesh(path, visual, quaternion)
                if problem is None:
                    continue
                fallback = [c for c in body.geometry.collisions if c.link == visual.link]
                drawn = 0
                for i, shape in enumerate(fallback):
                    q = matrix_to_quat(rpy_to_matrix(shape.rpy))
                    where = f"{path}_collision_{i}"
                    style = dict(centers=[shape.xyz], quaternions=[q], colors=[visual.color], fill_mode="solid")
                    if shape.kind == "box":
                        self._log(where, rr.Boxes3D(half_sizes=[np.array(shape.size) / 2], **style), static=True)
                    elif shape.kind == "cylinder":
                        self._log(where, rr.Cylinders3D(radii=[shape.size[0]], lengths=[shape.size[1]], **style), static=True)
                    elif shape.kind == "sphere":
                        self._log(where, rr.Ellipsoids3D(half_sizes=[[shape.size[0]] * 3], **style), static=True)
                    elif shape.kind == "mesh" and self._log_mesh(where, dataclasses.replace(shape, color=visual.color),
                                                                 q) is not None:
                        continue
                    drawn += 1
                if drawn:
                    self.warn(f"{body.name}: visual mesh of link {visual.link} cannot be drawn ({problem}); "
                              f"drawn from its collision geometry instead")
                else:
                    self.warn(f"{body.name}: visual mesh of link {visual.link} cannot be drawn ({problem}) and the link "
                              f"has no collision geometry that can; not drawn")
        if body.com is not None:
            self._log(f"{body.base}/com", rr.Points3D.from_fields(colors=[(255, 230, 0)], radii=[-4.0]), static=True)
        for key, index in body.fields.items():
            color, _ = VECTOR_FIELDS[key]
            self._log(f"{body.base}/{key}", rr.Arrows3D.from_fields(colors=[color], radii=[-1.5]), static=True)

    def _log_mesh(self, path: str, visual, quaternion) -> str | None:
        """A mesh visual at ``path``: .stl/.obj/.glb/.gltf as Rerun reads them, anything else (.dae
        ...) converted with trimesh into a Mesh3D; None when drawn, else why not."""
        import rerun as rr

        if visual.mesh is None:
            return "file not found"
        transform = rr.Transform3D(translation=visual.xyz, quaternion=quaternion, scale=visual.size)
        if visual.mesh.suffix.lower() in (".stl", ".obj", ".glb", ".gltf"):
            self._log(path, transform, rr.Asset3D(path=visual.mesh), static=True)
            return None
        try:
            vertices, triangles, normals, colors = mesh_arrays(visual.mesh)
        except Exception as e:   # trimesh's and pycollada's own exceptions for a file they cannot read
            return f"{visual.mesh.name}: {type(e).__name__}: {e}"
        if colors is None:
            colors = np.tile(np.array(visual.color, dtype=np.uint8), (len(vertices), 1))
        self._log(path, transform, rr.Mesh3D(vertex_positions=vertices, triangle_indices=triangles,
                                             vertex_normals=normals, vertex_colors=colors), static=True)
        return None

    def _log_grasp_static(self, g: _Grasp) -> None:
        """E and G axes (children of their links), the E-G line's style, the grasp plots' series."""
        import rerun as rr

        for link, frame in ((g.ee_link, "E"), (g.grasp_link, "G")):
            if link is not None:
                length, colors, radius = GRASP_AXES[frame]
                self._log(f"{link}/grasp_{frame}", rr.Arrows3D(origins=np.zeros((3, 3)), vectors=length * np.eye(3),
                                                              colors=colors, radii=[radius]), static=True)
        if g.ee_link is not None and g.p_ee_grasp is not None:
            self._log(f"{g.ee_link}/grasp_line", rr.LineStrips3D.from_fields(colors=[GRASP_OPEN[0]], radii=[-1.5]),
                      static=True)
        if g.p_ee_grasp is not None:
            self._series(g.plots + "/distance", ["|p_ee_grasp| (m)"], [GRASP_OPEN[0]])
            if g.closed is not None:
                self._log(g.plots + "/distance/capture", rr.SeriesPoints(colors=[GRASP_CLOSED[0]], names=["capture"],
                                                                          markers=["circle"], marker_sizes=[6.0]),
                          static=True)
        if g.wrench is not None:
            self._series(g.plots + "/wrench", ["|force| (N)", "|torque| (N m)"], AXIS_COLORS[::2])

    def _notes(self) -> None:
        import rerun as rr

        run = self.config.get("run") or {}
        lines = [f"# {run.get('name', 'Zenorbit run')}", "",
                 f"epoch {run.get('epoch', '?')}, step {run.get('step', '?')}, duration {run.get('duration', '?')}", "",
                 "| component | type |", "|---|---|"]
        for name, entry in (self.config.get("components") or {}).items():
            lines.append(f"| {name} | {(entry or {}).get('type', '?')} |")
        if self.arrow_scales:
            lines += ["", "Arrow scales (length in m per unit of the signal):", ""]
            for (dynamics, body, key), scale in sorted(self.arrow_scales.items()):
                unit = "N m" if key == "gg_torque" else "N"
                lines.append(f"- {dynamics}.{body}.{key}: {scale:.4g} m per {unit}")
        self._log("/notes", rr.TextDocument("\n".join(lines), media_type=rr.MediaType.MARKDOWN), static=True)

    # ------------------------------------------------------------------ rows

    def log_rows(self, steps, times, rows) -> None:
        """Log a batch of rows: ``steps`` (n,) int, ``times`` (n,) s, ``rows`` (n, n_columns) float64."""
        import rerun as rr

        rows = np.asarray(rows, dtype=np.float64).reshape(-1, len(self.columns))
        if not len(rows):
            return
        steps = np.asarray(steps, dtype=np.int64)
        times = np.asarray(times, dtype=np.float64)
        indexes = _indexes(steps, times)

        def send(path, columns):
            rr.send_columns(path, indexes=indexes, columns=columns, recording=self.rec)

        def scalars(path, index):
            send(path, rr.Scalars.columns(scalars=rows[:, index]))

        notes_changed = False
        for body in self.bodies:
            notes_changed |= self._log_body(body, rows, send)
        for grasp in self.grasps:
            self._log_grasp(grasp, steps, times, rows, send)
        for c in self.controllers:
            if c.ee_desired is not None:
                send(_path("world", c.name, "ee_desired"), rr.Points3D.columns(positions=rows[:, c.ee_desired]))
                scalars(_path("plots", c.name, "ee_position", "desired"), c.ee_desired)
            if c.ee_position is not None:
                send(_path("world", c.name, "ee_actual"), rr.Points3D.columns(positions=rows[:, c.ee_position]))
                scalars(_path("plots", c.name, "ee_position", "actual"), c.ee_position)
            if c.ee_error is not None:
                scalars(_path("plots", c.name, "ee_error", "position"), c.ee_error[:3])
                scalars(_path("plots", c.name, "ee_error", "orientation"), c.ee_error[3:])
            if c.tau is not None:
                scalars(_path("plots", c.name, "tau"), c.tau)
        if self.world_lvlh is not None:
            send("/world/lvlh", transform_columns(quaternion=normalized_quaternions(rows[:, self.world_lvlh])))
        for o in self.orbits:
            if o.r_eci is None:
                continue
            r = rows[:, o.r_eci]
            send(_path("orbit", o.name, "trail"), rr.Points3D.columns(positions=r))
            if o.q_eci_lvlh is not None:
                send(_path("orbit", o.name, "spacecraft"), transform_columns(
                    translation=r, quaternion=normalized_quaternions(rows[:, o.q_eci_lvlh])))
            else:
                send(_path("orbit", o.name, "spacecraft"), transform_columns(translation=r))
        for component, name in self.signals:
            scalars(_path("signals", component, name), self.variables[component, name])
        if notes_changed:
            self._notes()
        self.rows_logged += len(rows)

    def _log_body(self, body: _Body, rows: np.ndarray, send) -> bool:
        """Link poses, CoM, per-link arrows and plots of one body; True when an arrow scale was set."""
        import rerun as rr

        changed = False
        plots = body.base.replace("/world", "/plots", 1)
        n = len(rows)
        rotations = None
        if body.kinematics is not None and body.position is not None and body.orientation is not None:
            q = rows[:, body.q] if body.q is not None else np.zeros((n, body.kinematics.n_joints))
            translations, rotations = body.kinematics.link_poses(rows[:, body.position], rows[:, body.orientation], q)
            quaternions = matrix_to_quat(rotations)
            for j, link in enumerate(body.geometry.links):
                send(f"{body.base}/links/{rr.escape_entity_path_part(link)}",
                     transform_columns(translations[:, j], quaternions[:, j]))
        if body.com is not None:
            send(f"{body.base}/com", rr.Points3D.columns(positions=rows[:, body.com]))
        if body.momentum is not None:
            send(plots + "/momentum/linear", rr.Scalars.columns(scalars=rows[:, body.momentum[:3]]))
            send(plots + "/momentum/angular", rr.Scalars.columns(scalars=rows[:, body.momentum[3:]]))
        if body.fields:
            L = len(body.geometry.links)
            if rotations is not None:     # arrows start at the link CoMs, in W
                origins = translations + np.einsum("nlij,lj->nli", rotations, body.geometry.coms)
            for key, index in body.fields.items():
                vectors = rows[:, index].reshape(n, L, 3)
                if key == "gg_torque":
                    send(plots + "/gg_torque_norm", rr.Scalars.columns(scalars=np.linalg.norm(vectors, axis=2)))
                if rotations is None:
                    continue
                scale_key = (body.dynamics, body.name, key)
                if scale_key not in self.arrow_scales:
                    largest = float(np.linalg.norm(vectors, axis=2).max())
                    if largest <= 0.0 or not np.isfinite(largest):
                        continue
                    self.arrow_scales[scale_key] = ARROW_LENGTH / largest
                    changed = True
                scale = self.arrow_scales[scale_key]
                send(f"{body.base}/{key}", rr.Arrows3D.columns(
                    origins=origins.reshape(-1, 3), vectors=scale * vectors.reshape(-1, 3)).partition([L] * n))
        return changed

    def _log_grasp(self, g: _Grasp, steps: np.ndarray, times: np.ndarray, rows: np.ndarray, send) -> None:
        """The E-G line while open, the distance and wrench magnitudes, and the changes of ``grasp.closed``."""
        import rerun as rr

        n = len(rows)
        closed = rows[:, g.closed[0]] >= 0.5 if g.closed is not None else np.zeros(n, dtype=bool)
        if g.p_ee_grasp is not None:
            p = rows[:, g.p_ee_grasp]
            send(g.plots + "/distance", rr.Scalars.columns(scalars=np.linalg.norm(p, axis=1, keepdims=True)))
            if g.ee_link is not None:      # in E's axes: a child of E's link; no line once closed
                strips = np.stack([np.zeros_like(p), p], axis=1)[~closed]
                send(f"{g.ee_link}/grasp_line", rr.LineStrips3D.columns(strips=strips).partition(
                    (~closed).astype(np.int32)))
        if g.wrench is not None:
            norms = np.linalg.norm(rows[:, g.wrench].reshape(n, 2, 3), axis=2)     # force, torque
            send(g.plots + "/wrench", rr.Scalars.columns(scalars=norms))
        if g.closed is not None:
            self._log_grasp_changes(g, steps, times, rows, closed)

    def _log_grasp_changes(self, g: _Grasp, steps: np.ndarray, times: np.ndarray, rows: np.ndarray,
                           closed: np.ndarray) -> None:
        """G's marker on the first row and wherever ``grasp.closed`` changes; each capture (0 -> 1)
        once in the text log and as a point on the distance plot."""
        import rerun as rr

        first = g.was_closed is None               # the first row of all: the marker's initial look
        changed = closed != np.concatenate([[bool(g.was_closed)], closed[:-1]])
        changed[0] |= first
        g.was_closed = bool(closed[-1])
        at = np.flatnonzero(changed)
        if not len(at):
            return
        if g.grasp_link is not None:
            looks = [GRASP_CLOSED if closed[i] else GRASP_OPEN for i in at]
            self._send_at(f"{g.grasp_link}/grasp_G/marker", steps[at], times[at], rr.Points3D.columns(
                positions=np.zeros((len(at), 3)), colors=[look[0] for look in looks],
                radii=[look[1] for look in looks], labels=[look[2] for look in looks]))
        texts = {i: self._grasp_text(g, steps[i], times[i], rows[i], closed[i], first and i == 0) for i in at}
        logged = np.array([i for i, text in texts.items() if text], dtype=np.int64)
        if len(logged):
            self._send_at(g.events, steps[logged], times[logged], rr.TextLog.columns(
                text=[texts[i] for i in logged], level=["INFO" if closed[i] else "WARN" for i in logged]))
        captures = at[closed[at]]
        if len(captures) and g.p_ee_grasp is not None:
            self._send_at(g.plots + "/distance/capture", steps[captures], times[captures], rr.Scalars.columns(
                scalars=np.linalg.norm(rows[captures][:, g.p_ee_grasp], axis=1, keepdims=True)))

    @staticmethod
    def _grasp_text(g: _Grasp, step: int, time: float, row: np.ndarray, closed: bool, first_row: bool) -> str | None:
        """The text log line of a change of ``grasp.closed`` (None: an open grasp at the first row)."""
        if not closed:
            return None if first_row else f"grasp open again at t = {time:.6g} s (step {step}): {g.label}"
        text = f"capture at t = {time:.6g} s (step {step}): {g.label} closed"
        if first_row:
            text += " (already at the first row shown)"
        if g.p_ee_grasp is not None:
            text += f", E-G distance {1e3 * np.linalg.norm(row[g.p_ee_grasp]):.3g} mm"
        return text

    def _send_at(self, path: str, steps: np.ndarray, times: np.ndarray, columns) -> None:
        """``send_columns`` for some of the rows (their steps and times)."""
        import rerun as rr
        rr.send_columns(path, indexes=_indexes(steps, times), columns=columns, recording=self.rec)
