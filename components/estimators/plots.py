"""``estimator.fiducial``'s plot (``orchestrator plot``): each frame's solve over the run, against
the dynamics' own grasp pose when the recording holds it (a ``grasp`` of the same chaser, end
effector and grasp frame as the estimator's: ``<dynamics>.grasp.p_ee_grasp``, ``.q_ee_grasp``, taken
at the frame's time)."""

from __future__ import annotations

import numpy as np

from components.errors import ConfigError
from components.estimators.marker_layout import layout_path, read_layout
from components.plotting import Plot, RecordedRun, new_figure
from components.rotations import log_so3, quat_to_matrix


def chaser_dynamics(run: RecordedRun, c: str) -> str | None:
    """The dynamics moving the camera's body: the one feeding ``<camera>.<body>.position`` of the
    camera whose images the estimator reads (``c.rgb``), or None."""
    camera = (run.source(c, "rgb") or "").partition(".")[0]
    source = run.source(camera, f"{run.parameters(c).get('body')}.position") if camera else None
    return source.partition(".")[0] if source else None


def new_frames(frame: np.ndarray) -> np.ndarray:
    """The rows where the estimator's solve is of a new frame (its ``frame_solved`` output changes)."""
    return np.flatnonzero(np.diff(frame, prepend=0.0) > 0)


def _truth(run: RecordedRun, c: str) -> str | None:
    """The dynamics recording the grasp frame's pose in the estimator's end effector, or None."""
    params = run.parameters(c)
    dynamics = chaser_dynamics(run, c)
    if dynamics is None:
        return None
    grasp = run.parameters(dynamics).get("grasp") or {}
    if grasp.get("chaser") != params.get("body") or grasp.get("end_effector") != params.get("end_effector"):
        return None
    try:
        link = read_layout(layout_path(params["markers"], run.config_dir)).link
    except ConfigError:  # the layout file is not where the run found it: no truth to compare with
        return None
    if grasp.get("grasp_frame") != link or run.variable(f"{dynamics}.grasp.p_ee_grasp") is None:
        return None
    return dynamics


def _recorded(run: RecordedRun, name: str) -> np.ndarray:
    """A variable recorded with the one the plot starts from (the estimator's outputs with its
    ``frame_solved``, the dynamics' grasp pose with its ``p_ee_grasp``)."""
    found = run.variable(name)
    assert found is not None, f"{name} is not recorded"
    return found


def frame_errors(run: RecordedRun, c: str, dynamics: str):
    """(t_measured s, position error m, attitude error rad) of every accepted frame: the first row
    that shows each frame's solve, against the truth at the frame's time."""
    valid, t_measured = _recorded(run, f"{c}.valid")[:, 0], _recorded(run, f"{c}.t_measured")[:, 0]
    p, q = _recorded(run, f"{c}.p"), _recorded(run, f"{c}.q")
    p_true, q_true = _recorded(run, f"{dynamics}.grasp.p_ee_grasp"), _recorded(run, f"{dynamics}.grasp.q_ee_grasp")
    rows = [k for k in new_frames(_recorded(run, f"{c}.frame_solved")[:, 0]) if valid[k] > 0.5]
    out = []
    for k in rows:
        j = int(np.argmin(np.abs(run.time - t_measured[k])))
        if abs(run.time[j] - t_measured[k]) > 1e-9:
            continue  # the frame's time is not a recorded row
        R_error = quat_to_matrix(q_true[j]).T @ quat_to_matrix(q[k])
        out.append((t_measured[k], float(np.linalg.norm(p[k] - p_true[j])), float(np.linalg.norm(log_so3(R_error)))))
    return np.array(out).reshape(-1, 3)


def draw(run: RecordedRun, c: str) -> dict:
    frame = run.variable(f"{c}.frame_solved")
    if frame is None:
        return {}
    dynamics = _truth(run, c)
    fig = new_figure(9.0, 10.0)
    axes = [fig.add_subplot(4, 1, row) for row in range(1, 5)]
    new = new_frames(frame[:, 0])
    t_frame = _recorded(run, f"{c}.t_measured")[new, 0]
    if dynamics is not None:
        errors = frame_errors(run, c, dynamics)
        axes[0].plot(errors[:, 0], 1e3 * errors[:, 1], ".-", label="position")
        axes[0].set(ylabel="mm", title=f"{c}: error against {dynamics}.grasp (each accepted frame, at its time)")
        axes[1].plot(errors[:, 0], np.degrees(errors[:, 2]), ".-", label="attitude")
        axes[1].set(ylabel="deg", title=f"{c}: attitude error")
    else:
        p = _recorded(run, f"{c}.p")
        for k in range(3):
            axes[0].plot(run.time, p[:, k], label=f"p[{k}]")
        axes[0].set(ylabel="m", title=f"{c}.p (no grasp pose of the same frames recorded to compare with)")
        axes[1].set_axis_off()
    axes[2].plot(t_frame, _recorded(run, f"{c}.markers")[new, 0], ".", label="markers")
    axes[2].plot(t_frame, _recorded(run, f"{c}.valid")[new, 0], "x", label="valid")
    axes[2].set(title=f"{c}: markers found and valid, per frame")
    axes[3].plot(t_frame, _recorded(run, f"{c}.reprojection_error")[new, 0], ".", label="reprojection error")
    axes[3].set(xlabel="frame time (s)", ylabel="px", title=f"{c}: RMS reprojection error")
    for ax in axes:
        if ax.axison:
            ax.grid(True, alpha=0.3)
            ax.legend(loc="upper right", fontsize="x-small")
    return {f"{c}_pose.png": fig}


POSE = Plot(
    "{c}_pose.png",
    "each frame's position and attitude error against the dynamics' grasp pose (when "
    "recorded), markers found, valid, RMS reprojection error",
    draw,
)
