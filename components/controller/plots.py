"""The controllers' plots (``orchestrator plot``): the computed-torque controller's path, error,
torques and base (the paper's Figs. 5-7), joint_pd's torques and joints, and the capture
controller's phases."""

from __future__ import annotations

import numpy as np

from components.plotting import Plot, PlotError, RecordedRun, new_figure
from components.rotations import quat_to_matrix


def _driven(tau: np.ndarray) -> np.ndarray:
    """Indices of the torque columns that are not identically zero."""
    return np.flatnonzero(np.any(tau != 0.0, axis=0))


def _required(run: RecordedRun, c: str, *names: str) -> list[np.ndarray]:
    """The variables ``c.name`` for each name; PlotError naming the ones the recording lacks."""
    found = [run.variable(f"{c}.{name}") for name in names]
    missing = [name for name, value in zip(names, found) if value is None]
    if missing:
        raise PlotError(f"{c}: the recording lacks {', '.join(missing)}")
    return [value for value in found if value is not None]  # all of them, now


def _base_attitude(run: RecordedRun, c: str) -> tuple[str | None, np.ndarray | None]:
    """The output feeding the controller's ``orientation`` and its recorded quaternions (or None)."""
    source = run.source(c, "orientation")
    return source, run.vector(source, 4) if source else None


def path(run: RecordedRun, c: str) -> dict:
    p, p_d = _required(run, c, "ee_position", "ee_position_desired")
    # the path in the base's initial frame (inertial: the torso's axes at t0), as the paper draws
    # it; in W axes when the base orientation is not in the recording
    origin, frame = p_d[0], "W"
    _, q_base = _base_attitude(run, c)
    if q_base is not None:
        R0 = quat_to_matrix(q_base[0])
        p, p_d, frame = p @ R0, p_d @ R0, "the base's initial frame"
        origin = p_d[0]
    fig = new_figure(7.0, 6.0)
    ax = fig.add_subplot(projection="3d")
    ax.plot(*(p_d - origin).T, color="black", linestyle="--", linewidth=1.5, label="desired")
    ax.plot(*(p - origin).T, color="red", linewidth=1.0, label="obtained")
    ax.scatter(*(p_d[[0, -1]] - origin).T, color="black", s=12)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.set_title(f"{c}: end-effector path in {frame}, relative to its start")
    ax.legend(loc="upper left")
    span = np.ptp(np.vstack([p - origin, p_d - origin]), axis=0).max() / 2 or 0.1
    centre = (np.vstack([p, p_d]) - origin).min(axis=0) + np.ptp(np.vstack([p, p_d]) - origin, axis=0) / 2
    ax.set_xlim(centre[0] - span, centre[0] + span)
    ax.set_ylim(centre[1] - span, centre[1] + span)
    ax.set_zlim(centre[2] - span, centre[2] + span)
    return {f"{c}_path.png": fig}


def error(run: RecordedRun, c: str) -> dict:
    (error,) = _required(run, c, "ee_error")
    t = run.time
    fig = new_figure(8.0, 6.0)
    axes = fig.subplots(2, 1, sharex=True)
    for ax, part, scale, unit, title in (
        (axes[0], error[:, :3], 1e3, "mm", "a) position error p_d - p"),
        (axes[1], error[:, 3:], 1e3, "mrad", "b) orientation error log(R_d R^T)"),
    ):
        for i, axis in enumerate("xyz"):
            ax.plot(t, part[:, i] * scale, linewidth=1.0, label=axis)
        ax.plot(t, np.linalg.norm(part, axis=1) * scale, color="black", linewidth=1.0, label="norm")
        ax.set_ylabel(unit)
        ax.set_title(title, loc="left")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", ncols=4, fontsize="small")
    axes[1].set_xlabel("time (s)")
    fig.suptitle(f"{c}: tracking error (W axes)")
    return {f"{c}_error.png": fig}


def torques(run: RecordedRun, c: str) -> dict:
    (tau,) = _required(run, c, "tau")
    t = run.time
    names = run.joint_names(run.parameters(c).get("urdf"), tau.shape[1])
    fig = new_figure(8.0, 4.5)
    ax = fig.add_subplot()
    driven = _driven(tau)
    for i in driven:
        ax.plot(t, tau[:, i], linewidth=1.0, label=names[i])
    if driven.size == 0:
        ax.text(0.5, 0.5, "all torques zero", transform=ax.transAxes, ha="center")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("N m")
    ax.set_title(f"{c}: joint torques")
    ax.grid(True, alpha=0.3)
    if driven.size:
        ax.legend(loc="upper right", fontsize="small", ncols=2)
    return {f"{c}_torque.png": fig}


def base(run: RecordedRun, c: str) -> dict:
    t = run.time
    base_source = run.source(c, "position")
    base = run.vector(base_source, 3) if base_source else None
    sigma = run.columns.get(f"{c}.sigma_min")
    if base is None and sigma is None:
        return {}
    q_source, q_base = _base_attitude(run, c)
    fig = new_figure(8.0, 7.5)
    axes = fig.subplots(3, 1, sharex=True)
    if q_base is not None:
        q0 = q_base[0] / np.linalg.norm(q_base[0])
        dots = np.abs(q_base @ q0) / np.linalg.norm(q_base, axis=1)
        axes[1].plot(t, np.degrees(2.0 * np.arccos(np.clip(dots, 0.0, 1.0))), color="black", linewidth=1.0)
        axes[1].set_ylabel("deg")
        axes[1].set_title(f"b) base rotation from its initial attitude ({q_source})", loc="left")
        axes[1].grid(True, alpha=0.3)
    axes = [axes[0], axes[2]]
    if base is not None:
        for i, axis in enumerate("xyz"):
            axes[0].plot(t, (base[:, i] - base[0, i]) * 1e3, linewidth=1.0, label=axis)
        axes[0].set_ylabel("mm")
        axes[0].set_title(f"a) base displacement in W ({base_source})", loc="left")
        axes[0].legend(loc="upper left", ncols=3, fontsize="small")
        axes[0].grid(True, alpha=0.3)
    if sigma is not None:
        axes[1].plot(t, sigma, color="black", linewidth=1.0)
        axes[1].set_title("c) smallest singular value of J_g", loc="left")
        axes[1].grid(True, alpha=0.3)
    axes[1].set_xlabel("time (s)")
    return {f"{c}_base.png": fig}


def joints(run: RecordedRun, c: str) -> dict:
    tau, q_d = _required(run, c, "tau", "q_desired")
    t = run.time
    params = run.parameters(c)
    source = run.source(c, "q")
    q = run.vector(source) if source else None
    names = run.joint_names(params.get("urdf"), tau.shape[1])
    driven = [names.index(j) for j in (params.get("gains") or {}) if j in names] or list(_driven(tau))
    fig = new_figure(8.0, 4.5)
    ax = fig.add_subplot()
    for k, i in enumerate(driven):
        color = f"C{k % 10}"
        ax.plot(t, q_d[:, i], color=color, linestyle="--", linewidth=1.0)
        if q is not None:
            ax.plot(t, q[:, i], color=color, linewidth=1.0, label=names[i])
    ax.set_xlabel("time (s)")
    ax.set_ylabel("rad")
    ax.set_title(f"{c}: joint positions (solid) and references (dashed)")
    ax.grid(True, alpha=0.3)
    if driven and q is not None:
        ax.legend(loc="upper right", fontsize="small", ncols=2)
    return {f"{c}_joints.png": fig}


# close_errors' elements: (title, unit, scale to that unit), each on an axis of its own
CLOSE_ERRORS = (
    ("position error", "mm", 1e3),
    ("attitude error", "deg", np.degrees(1.0)),
    ("velocity error", "mm/s", 1e3),
    ("rate error", "deg/s", np.degrees(1.0)),
)


def phases(run: RecordedRun, c: str) -> dict:
    """The capture controller's course: its phase (named on the axis) and attempts (an axis of
    their own), the estimated distance to the grasp frame, and each estimated error its close
    decision weighs on an axis of its own."""
    from components.controller.capture import PHASES as NAMES

    phase, attempt, distance, errors = _required(run, c, "phase", "attempt", "grasp_distance", "close_errors")
    t = run.time
    fig = new_figure(9.0, 10.0)
    axes = fig.subplot_mosaic([["phase", "phase"], ["distance", "distance"], ["e0", "e1"], ["e2", "e3"]], sharex=True)
    ax = axes["phase"]
    ax.step(t, phase[:, 0], where="post", color="black", linewidth=1.0, label="phase")
    ax.set_yticks(range(len(NAMES)), [f"{k} {name}" for k, name in enumerate(NAMES)], fontsize="small")
    ax.set_ylim(-0.5, len(NAMES) - 0.5)  # every phase inside the frame, none on its border
    ax.set_ylabel("phase")
    ax.set_title(f"{c}: phase, and approaches started", loc="left")
    twin = ax.twinx()
    twin.step(t, attempt[:, 0], where="post", color="tab:blue", linewidth=1.0, label="approaches started")
    twin.set_ylabel("approaches started", color="tab:blue")
    twin.set_ylim(-0.5, max(float(np.max(attempt[:, 0])), 1.0) + 0.5)
    twin.yaxis.get_major_locator().set_params(integer=True)
    lines = ax.get_legend_handles_labels()[0] + twin.get_legend_handles_labels()[0]
    ax.legend(lines, [line.get_label() for line in lines], loc="lower right", fontsize="x-small", ncols=2)
    axes["distance"].plot(t, distance[:, 0], color="black", linewidth=1.0, label="grasp_distance")
    axes["distance"].set(ylabel="m")
    axes["distance"].set_title("estimated distance from the end effector to the grasp frame", loc="left")
    for k, (title, unit, scale) in enumerate(CLOSE_ERRORS):
        ax = axes[f"e{k}"]
        ax.plot(t, scale * errors[:, k], linewidth=1.0, color=f"C{k}", label=f"close_errors[{k}]")
        ax.set_ylabel(unit)
        ax.set_title(f"estimated {title}", loc="left", fontsize="medium")
    for name in ("e2", "e3"):
        axes[name].set_xlabel("time (s)")
    for ax in axes.values():
        ax.grid(True, alpha=0.3)
    return {f"{c}_phases.png": fig}


PATH = Plot(
    "{c}_path.png",
    "desired (black) and obtained (red) 3D end-effector path relative to its start, in the "
    "axes of the base at t0 (inertial; W axes if the base orientation is not recorded) "
    "(paper Fig. 5)",
    path,
)
ERROR = Plot(
    "{c}_error.png", "position error (mm) and orientation error (mrad) per W axis and norm, over time (Fig. 6)", error
)
TORQUES = Plot("{c}_torque.png", "torques of the driven joints, N m (Fig. 7)", torques)
BASE = Plot(
    "{c}_base.png", "the body's base displacement (mm, W) and rotation (deg) from t0, and sigma_min of J_g", base
)
JOINTS = Plot("{c}_joints.png", "joint positions and their references", joints)
PHASES = Plot(
    "{c}_phases.png",
    "the capture's phase and attempts, the estimated distance to the grasp frame and "
    "the estimated errors behind close (position, attitude, velocity, rate: an axis "
    "each)",
    phases,
)
