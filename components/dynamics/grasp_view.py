"""What a dynamics component's view draws of its ``grasp`` (:mod:`components.dynamics.view`): E's
and G's axes on their links, the E-G line while open, the distance and wrench plots, G's marker
and the text log of each capture."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from components.viewer.scene import AXIS_COLORS, LIGHT_AXIS_COLORS, Batch, entity_path

GRASP_AXES = {"E": (0.15, AXIS_COLORS, -2.0), "G": (0.25, LIGHT_AXIS_COLORS, -1.5)}  # m, colours, radius (ui)
GRASP_OPEN = ((250, 170, 40), 0.02, "G")  # G marker while open: colour, radius (m), label
GRASP_CLOSED = ((60, 220, 90), 0.07, "G captured")  # ... once the grasp has closed


@dataclass
class Grasp:
    """A dynamics' ``grasp``: E (``end_effector``, a link of ``chaser``) meets G (``grasp_frame``, a
    link of ``target``). ``ee_link``/``grasp_link``: the link entities, None when that body is not drawn."""

    dynamics: str
    ee_link: str | None
    grasp_link: str | None
    p_ee_grasp: np.ndarray | None
    closed: np.ndarray | None
    wrench: np.ndarray | None
    label: str
    was_closed: bool | None = None  # grasp.closed at the last row logged (None: no row yet)

    @property
    def plots(self) -> str:
        return entity_path("plots", self.dynamics, "grasp")

    @property
    def events(self) -> str:
        return entity_path("events", self.dynamics, "grasp")


def log_grasp_static(scene, g: Grasp) -> None:
    """E and G axes (children of their links), the E-G line's style, the grasp plots' series."""
    import rerun as rr

    for link, frame in ((g.ee_link, "E"), (g.grasp_link, "G")):
        if link is not None:
            length, colors, radius = GRASP_AXES[frame]
            scene.log(
                f"{link}/grasp_{frame}",
                rr.Arrows3D(origins=np.zeros((3, 3)), vectors=length * np.eye(3), colors=colors, radii=[radius]),
                static=True,
            )
    if g.ee_link is not None and g.p_ee_grasp is not None:
        scene.log(
            f"{g.ee_link}/grasp_line",
            rr.LineStrips3D.from_fields(colors=[GRASP_OPEN[0]], radii=[-1.5]),
            static=True,
        )
    if g.p_ee_grasp is not None:
        scene.series(g.plots + "/distance", ["|p_ee_grasp| (m)"], [GRASP_OPEN[0]])
        if g.closed is not None:
            scene.log(
                g.plots + "/distance/capture",
                rr.SeriesPoints(colors=[GRASP_CLOSED[0]], names=["capture"], markers=["circle"], marker_sizes=[6.0]),
                static=True,
            )
    if g.wrench is not None:
        scene.series(g.plots + "/wrench", ["|force| (N)", "|torque| (N m)"], AXIS_COLORS[::2])


def log_grasp_rows(g: Grasp, batch: Batch) -> None:
    """The E-G line while open, the distance and wrench magnitudes, and the changes of ``grasp.closed``."""
    import rerun as rr

    rows, send = batch.rows, batch.send
    n = len(rows)
    closed = rows[:, g.closed[0]] >= 0.5 if g.closed is not None else np.zeros(n, dtype=bool)
    if g.p_ee_grasp is not None:
        p = rows[:, g.p_ee_grasp]
        send(g.plots + "/distance", rr.Scalars.columns(scalars=np.linalg.norm(p, axis=1, keepdims=True)))
        if g.ee_link is not None:  # in E's axes: a child of E's link; no line once closed
            strips = np.stack([np.zeros_like(p), p], axis=1)[~closed]
            send(
                f"{g.ee_link}/grasp_line",
                rr.LineStrips3D.columns(strips=strips).partition((~closed).astype(np.int32)),
            )
    if g.wrench is not None:
        norms = np.linalg.norm(rows[:, g.wrench].reshape(n, 2, 3), axis=2)  # force, torque
        send(g.plots + "/wrench", rr.Scalars.columns(scalars=norms))
    if g.closed is not None:
        _log_grasp_changes(g, batch, closed)


def _log_grasp_changes(g: Grasp, batch: Batch, closed: np.ndarray) -> None:
    """G's marker on the first row and wherever ``grasp.closed`` changes; each capture (0 -> 1)
    once in the text log and as a point on the distance plot."""
    import rerun as rr

    steps, times, rows = batch.steps, batch.times, batch.rows
    first = g.was_closed is None  # the first row of all: the marker's initial look
    changed = closed != np.concatenate([[bool(g.was_closed)], closed[:-1]])
    changed[0] |= first
    g.was_closed = bool(closed[-1])
    at = np.flatnonzero(changed)
    if not len(at):
        return
    if g.grasp_link is not None:
        looks = [GRASP_CLOSED if closed[i] else GRASP_OPEN for i in at]
        batch.send_at(
            f"{g.grasp_link}/grasp_G/marker",
            at,
            rr.Points3D.columns(
                positions=np.zeros((len(at), 3)),
                colors=[look[0] for look in looks],
                radii=[look[1] for look in looks],
                labels=[look[2] for look in looks],
            ),
        )
    texts = {i: _grasp_text(g, steps[i], times[i], rows[i], closed[i], first and i == 0) for i in at}
    shown = {i: text for i, text in texts.items() if text}
    logged = np.array(list(shown), dtype=np.int64)
    if len(logged):
        batch.send_at(
            g.events,
            logged,
            rr.TextLog.columns(text=list(shown.values()), level=["INFO" if closed[i] else "WARN" for i in logged]),
        )
    captures = at[closed[at]]
    if len(captures) and g.p_ee_grasp is not None:
        batch.send_at(
            g.plots + "/distance/capture",
            captures,
            rr.Scalars.columns(scalars=np.linalg.norm(rows[captures][:, g.p_ee_grasp], axis=1, keepdims=True)),
        )


def _grasp_text(g: Grasp, step: int, time: float, row: np.ndarray, closed: bool, first_row: bool) -> str | None:
    """The text log line of a change of ``grasp.closed`` (None: an open grasp at the first row)."""
    if not closed:
        return None if first_row else f"grasp open again at t = {time:.6g} s (step {step}): {g.label}"
    text = f"capture at t = {time:.6g} s (step {step}): {g.label} closed"
    if first_row:
        text += " (already at the first row shown)"
    if g.p_ee_grasp is not None:
        text += f", E-G distance {1e3 * np.linalg.norm(row[g.p_ee_grasp]):.3g} mm"
    return text
