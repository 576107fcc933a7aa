"""Recorded rows -> Rerun log calls: the frame of the Zenorbit view (no bus, no I/O).

``SceneLogger(columns, config, config_dir, recording, frames_dir)`` looks at the resolved config and the
recorded column names (``<component>.<name>`` or ``<component>.<name>[i]``, docs/design.md §6).
Each component whose type has a ``view`` (a :class:`View` class, found through the registry) draws
its part; this module turns batches of rows (step, time, one float64 per column) into their
columnar Rerun logs on two timelines, ``sim_time`` (a duration, s) and ``step`` (a sequence), and
lays the parts out. Whatever is absent is simply not shown.

What it draws itself (SI units; W = the dynamics world frame, ECI = GCRF axes):

| entity | what |
|---|---|
| ``/world/lvlh/axes`` | LVLH axes at the W origin (an LVLH attitude a view offers; W axes are ECI axes) |
| ``/signals/<component>/<name>`` | every recorded variable no view shows, one plot series per element |
| ``/notes`` | run summary and arrow scales (text) |

The views: components/orbit/view.py, components/dynamics/view.py, components/controller/view.py.
"""

from __future__ import annotations

import re
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from components.viewer.robot import normalized_quaternions

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb
    from rerun.blueprint.api import VisualizerLike
    from rerun.encodings import EntityPathLike

TIMELINE = "sim_time"
STEP_TIMELINE = "step"
COLUMN = re.compile(r"^(?P<component>[^.\[]+)\.(?P<name>[^\[]+?)(?:\[(?P<index>\d+)\])?$")
AXIS_COLORS = [(230, 60, 60), (60, 200, 80), (70, 110, 240)]
LIGHT_AXIS_COLORS = [(250, 160, 150), (150, 230, 160), (150, 180, 250)]
BULK = ("link_position", "link_orientation")  # drawn through the link poses, never plotted
ARROW_LENGTH = 0.25  # m, the longest arrow of a field when first seen
ROBOT_EYE = (1.9, -1.6, 1.0)  # m, initial camera of the robot view
BODY_REACH = 1.5  # m, about a body's extent around its base (the camera's margin)


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
    for values, batch, descriptor in (
        (translation, Translation3DBatch, rr.Transform3D.descriptor_translation),
        (quaternion, RotationQuatBatch, rr.Transform3D.descriptor_quaternion),
    ):
        if values is not None:
            values = np.asarray(values, dtype=np.float32)
            columns.append(batch(values).described(descriptor()).partition(np.ones(len(values), dtype=np.int32)))
    return columns


def indexes(steps: np.ndarray, times: np.ndarray) -> list:
    """The two timelines of rows: ``sim_time`` (a duration, from ``times`` in s) and ``step``."""
    import rerun as rr

    return [rr.TimeColumn(TIMELINE, duration=times), rr.TimeColumn(STEP_TIMELINE, sequence=steps)]


def entity_path(*parts: str) -> str:
    """An entity path of escaped parts: ``entity_path("world", name)`` is ``/world/<name>``."""
    import rerun as rr

    return "/" + "/".join(rr.escape_entity_path_part(p) for p in parts)


def trail() -> rrb.VisibleTimeRanges:
    """A blueprint override: an entity's past points stay shown (a path drawn as it goes)."""
    import rerun.blueprint as rrb

    return rrb.VisibleTimeRanges(
        timeline=TIMELINE, start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.cursor_relative()
    )


@dataclass
class Layout:
    """Where a view's entities go in the blueprint. ``world``/``orbit``: it draws in the robot
    space (/world, W) or in the ECI space (/orbit); ``trails``: its entities there whose past
    points stay shown; ``figures``: time-series views beside the 3D ones; ``tabs``: views among
    the tabs; ``events``: it logs text under /events."""

    world: bool = False
    orbit: bool = False
    trails: list[str] = field(default_factory=list)
    figures: list = field(default_factory=list)
    tabs: list = field(default_factory=list)
    events: bool = False


@dataclass
class Batch:
    """Rows to log: ``steps`` (n,) int, ``times`` (n,) s, ``rows`` (n, n_columns) float64, sent
    to ``recording`` on both timelines."""

    steps: np.ndarray
    times: np.ndarray
    rows: np.ndarray
    recording: rr.RecordingStream | None

    def send(self, path: str, columns) -> None:
        import rerun as rr

        rr.send_columns(path, indexes=indexes(self.steps, self.times), columns=columns, recording=self.recording)

    def scalars(self, path: str, index: np.ndarray) -> None:
        """The columns ``index`` of every row as one plot series each."""
        import rerun as rr

        self.send(path, rr.Scalars.columns(scalars=self.rows[:, index]))

    def send_at(self, path: str, at: np.ndarray, columns) -> None:
        """``send`` for the rows ``at`` only (their steps and times)."""
        import rerun as rr

        rr.send_columns(
            path, indexes=indexes(self.steps[at], self.times[at]), columns=columns, recording=self.recording
        )


class View:
    """What one component draws in Rerun. A component type's ``view`` is a subclass, built as
    ``view(name, parameters, scene)`` (``parameters`` as the config gives them) for each of its
    components; it finds its columns with ``scene.find``/``scene.take``. The scene then calls
    ``connect`` once every view exists (a view that needs another's looks now), ``log_static``
    once, ``log_rows`` for each batch of rows, and ``layout`` for the blueprint.

    ``bodies``: the robots it draws under /world (objects with ``dynamics``, ``name``, ``geometry``
    and ``start``: the camera frames them, a controller finds the one it drives). ``lvlh``: the
    column indices of an LVLH attitude it outputs (``q_eci_lvlh``), the robot view's axes.
    """

    bodies: Sequence = ()
    lvlh: np.ndarray | None = None

    def __init__(self, name: str, parameters: dict, scene: SceneLogger):
        self.name = name

    def connect(self, scene: SceneLogger) -> None:
        """Look at the other views (``scene.views``, ``scene.bodies``)."""

    def log_static(self, scene: SceneLogger) -> None:
        """What does not change: shapes, styles, plot series names and colours."""

    def log_rows(self, scene: SceneLogger, batch: Batch) -> None:
        """One batch of rows, in time order."""

    def layout(self, scene: SceneLogger) -> Layout:
        return Layout()


class SceneLogger:
    """Turns rows of a Zenorbit run into Rerun log calls on ``recording`` (a ``rr.RecordingStream``).

    Call ``log_static()`` once, then ``log_rows(steps, times, rows)`` with batches of rows in time
    order (``rows``: shape (n, len(columns)), float64). ``blueprint()`` lays the views out.
    """

    def __init__(
        self,
        columns: list[str],
        config: dict,
        config_dir: str | Path | None = None,
        *,
        recording=None,
        warn: Callable[[str], None] | None = None,
        frames_dir: str | Path | None = None,
    ):
        self.columns = list(columns)
        self.frames_dir = Path(frames_dir) if frames_dir else None  # the recording's frames/ (camera images)
        self.config = config or {}
        self.config_dir = Path(config_dir) if config_dir else None
        # run.packages as the run resolved them: relative to the config's directory
        packages = (self.config.get("run") or {}).get("packages") or {}
        self.packages = (
            {str(k): str((self.config_dir or Path(".")) / str(v)) for k, v in packages.items()}
            if isinstance(packages, dict)
            else {}
        )
        self.rec = recording
        self.warn = warn or (lambda message: print(f"viewer: {message}", file=sys.stderr, flush=True))
        self.variables = parse_columns(self.columns)
        self.shown: set[tuple[str, str]] = set()
        self.connections = {str(k): str(v) for k, v in (self.config.get("connections") or {}).items()}
        self.arrow_scales: dict[tuple[str, ...], float] = {}
        self.arrow_units: dict[tuple[str, ...], str] = {}
        self.types: dict[str, type] = {}  # the components' types that could be loaded
        self.views: dict[str, View] = {}
        for name, entry in (self.config.get("components") or {}).items():
            view = self._view_of(name, entry or {})
            if view is not None:
                self.views[name] = view
        for view in self.views.values():
            view.connect(self)
        self.world_lvlh = self._world_lvlh()
        for key in self.variables:
            if key[1].split(".")[-1] in BULK:
                self.shown.add(key)
        self.signals = [key for key in self.variables if key not in self.shown]
        self.rows_logged = 0

    # ------------------------------------------------------------------ discovery

    def _view_of(self, name: str, entry: dict) -> View | None:
        """The view of a component, by its type's ``view`` (None: its outputs are plain signals)."""
        from components import registry
        from components.errors import ConfigError

        try:
            cls = registry.load(str(entry.get("type", "")), self.config_dir)
        except ConfigError as e:
            self.warn(f"{name}: {e.message}; its outputs are shown as plain signals")
            return None
        self.types[name] = cls
        return cls.view(name, entry.get("parameters") or {}, self) if cls.view is not None else None

    @property
    def bodies(self) -> list:
        """The robots the views draw under /world, in config order."""
        return [body for view in self.views.values() for body in view.bodies]

    def find(self, component: str, name: str, size: int | None = None) -> np.ndarray | None:
        """Column indices of ``component.name``, or None if absent or not of ``size`` elements."""
        index = self.variables.get((component, name))
        if index is None or (size is not None and len(index) != size):
            return None
        return index

    def take(self, component: str, name: str, size: int | None = None) -> np.ndarray | None:
        """As ``find``, and the variable is shown elsewhere than under /signals."""
        index = self.find(component, name, size)
        if index is not None:
            self.shown.add((component, name))
        return index

    def arrow_scale(self, key: tuple[str, ...], unit: str, vectors: np.ndarray) -> float | None:
        """The length scale (m per ``unit``) of an arrow field: ARROW_LENGTH for its longest
        vector when first nonzero, then kept (the notes list it); None while all are zero."""
        if key not in self.arrow_scales:
            largest = float(np.linalg.norm(vectors, axis=-1).max())
            if largest <= 0.0 or not np.isfinite(largest):
                return None
            self.arrow_scales[key], self.arrow_units[key] = ARROW_LENGTH / largest, unit
        return self.arrow_scales[key]

    def _world_lvlh(self) -> np.ndarray | None:
        """LVLH attitude for the robot view: the output feeding the bodies' component, else the first offered."""
        drawing = {body.dynamics for body in self.bodies}
        feeding = [
            source
            for destination, source in self.connections.items()
            if destination.endswith(".q_eci_lvlh") and destination.split(".")[0] in drawing
        ]
        offered = [(name, view.lvlh) for name, view in self.views.items() if view.lvlh is not None]
        for name, lvlh in offered:
            if f"{name}.q_eci_lvlh" in feeding:
                return lvlh
        if self.bodies and offered:
            return offered[0][1]
        return None

    # ------------------------------------------------------------------ layout

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
        side = side - (side @ axis) * axis  # at right angles to the line of the bodies
        side = side / np.linalg.norm(side) if np.linalg.norm(side) > 1e-6 else eye / np.linalg.norm(eye)
        return center + max(np.linalg.norm(eye), 2.0 * (spread + BODY_REACH)) * side, center

    def blueprint(self):
        """The layout: robots and orbit in 3D on the left, the views' plots in the middle, the rest in tabs."""
        import rerun.blueprint as rrb

        layouts = [view.layout(self) for view in self.views.values()]
        spatial = []
        eye, target = self._camera()
        if any(layout.world for layout in layouts):
            trails: dict[EntityPathLike, VisualizerLike] = {
                path: trail() for layout in layouts for path in layout.trails if path.startswith("/world/")
            }
            if self.world_lvlh is not None:  # seen from LVLH (z orbit normal up): a steady camera
                spatial.append(
                    rrb.Spatial3DView(
                        origin="/world/lvlh",
                        contents="/world/**",
                        name="Robots (W, seen in LVLH axes)",
                        overrides=trails,
                        eye_controls=rrb.EyeControls3D(position=eye, look_target=target),
                    )
                )
            else:
                spatial.append(
                    rrb.Spatial3DView(
                        origin="/world",
                        name="Robots (W frame)",
                        overrides=trails,
                        eye_controls=rrb.EyeControls3D(position=eye, look_target=target),
                    )
                )
        if any(layout.orbit for layout in layouts):
            trails = {path: trail() for layout in layouts for path in layout.trails if path.startswith("/orbit/")}
            spatial.append(
                rrb.Spatial3DView(
                    origin="/orbit", name="Orbit (ECI)", overrides=trails, line_grid=rrb.LineGrid3D(visible=False)
                )
            )
        figures = [figure for layout in layouts for figure in layout.figures]
        tabs = [tab for layout in layouts for tab in layout.tabs]
        for component in dict.fromkeys(c for c, _ in self.signals):
            tabs.append(rrb.TimeSeriesView(origin=entity_path("signals", component), name=f"{component} signals"))
        if any(layout.events for layout in layouts):
            tabs.append(rrb.TextLogView(origin="/events", name="Events"))
        tabs.append(rrb.TextDocumentView(origin="/notes", name="Run"))
        columns: list[rrb.Container] = []
        if spatial:
            columns.append(rrb.Vertical(*spatial))
        if figures:
            columns.append(rrb.Vertical(*figures))
        columns.append(rrb.Tabs(*tabs))
        layout = rrb.Horizontal(*columns, column_shares=[3, 2, 2][: len(columns)] if len(columns) > 1 else None)
        return rrb.Blueprint(
            layout,
            rrb.BlueprintPanel(state="collapsed"),
            rrb.SelectionPanel(state="collapsed"),
            rrb.TimePanel(state="collapsed", timeline=TIMELINE, play_state="following"),
        )

    # ------------------------------------------------------------------ static content

    def log(self, path: str, *archetypes, static: bool = False) -> None:
        import rerun as rr

        rr.log(path, *archetypes, static=static, recording=self.rec)

    def log_static(self) -> None:
        """Everything that does not change: the views' shapes and styles, axes, plot series names and colours."""
        import rerun as rr

        for root in ("/world", "/world/lvlh", "/orbit"):
            self.log(root, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        for view in self.views.values():
            view.log_static(self)
        if self.world_lvlh is not None:
            self.log(
                "/world/lvlh/axes",
                rr.Arrows3D(origins=np.zeros((3, 3)), vectors=0.3 * np.eye(3), colors=AXIS_COLORS, radii=[-1.5]),
                static=True,
            )
        for component, name in self.signals:
            n = len(self.variables[component, name])
            self.series(
                entity_path("signals", component, name), [name] if n == 1 else [f"{name}[{i}]" for i in range(n)]
            )
        self._notes()

    def series(self, path: str, names: list[str], colors=None) -> None:
        """A plot's series: their names and colours (the axis colours for up to three)."""
        import rerun as rr

        if colors is None and len(names) <= 3:
            colors = AXIS_COLORS
        self.log(path, rr.SeriesLines(names=names, colors=colors[: len(names)] if colors else None), static=True)

    def _notes(self) -> None:
        import rerun as rr

        run = self.config.get("run") or {}
        lines = [
            f"# {run.get('name', 'Zenorbit run')}",
            "",
            f"epoch {run.get('epoch', '?')}, step {run.get('step', '?')}, duration {run.get('duration', '?')}",
            "",
            "| component | type |",
            "|---|---|",
        ]
        for name, entry in (self.config.get("components") or {}).items():
            lines.append(f"| {name} | {(entry or {}).get('type', '?')} |")
        if self.arrow_scales:
            lines += ["", "Arrow scales (length in m per unit of the signal):", ""]
            for key, scale in sorted(self.arrow_scales.items()):
                lines.append(f"- {'.'.join(key)}: {scale:.4g} m per {self.arrow_units[key]}")
        self.log("/notes", rr.TextDocument("\n".join(lines), media_type=rr.MediaType.MARKDOWN), static=True)

    # ------------------------------------------------------------------ rows

    def log_rows(self, steps, times, rows) -> None:
        """Log a batch of rows: ``steps`` (n,) int, ``times`` (n,) s, ``rows`` (n, n_columns) float64."""
        rows = np.asarray(rows, dtype=np.float64).reshape(-1, len(self.columns))
        if not len(rows):
            return
        batch = Batch(np.asarray(steps, dtype=np.int64), np.asarray(times, dtype=np.float64), rows, self.rec)
        scales = len(self.arrow_scales)
        for view in self.views.values():
            view.log_rows(self, batch)
        if self.world_lvlh is not None:
            batch.send("/world/lvlh", transform_columns(quaternion=normalized_quaternions(rows[:, self.world_lvlh])))
        for component, name in self.signals:
            batch.scalars(entity_path("signals", component, name), self.variables[component, name])
        if len(self.arrow_scales) != scales:
            self._notes()
        self.rows_logged += len(rows)
