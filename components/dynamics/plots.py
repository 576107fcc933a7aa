"""The dynamics' plots (``orchestrator plot``): per body, its attitude, momentum and joints; and
a grasp's capture on one page."""

from __future__ import annotations

import numpy as np

from components.plotting import Plot, RecordedRun, new_figure


def attitude_in_lvlh(run: RecordedRun, component: str, body: str) -> tuple[np.ndarray, str] | None:
    """The body's attitude as a rotation vector (rad, rows x 3): relative to LVLH (its axes: x
    radial, y along-track, z orbit normal; z is the pitch of a libration) when the component's
    q_eci_lvlh input is recorded, else relative to the body's attitude at t0 in W axes.
    Returns (rotation vectors, frame name), or None without the orientation columns."""
    from scipy.spatial.transform import Rotation

    q_body = run.vector(f"{component}.{body}.orientation", 4)
    if q_body is None:
        return None
    source = run.source(component, "q_eci_lvlh")
    q_lvlh = run.vector(source, 4) if source else None
    body_rotation = Rotation.from_quat(q_body)
    if q_lvlh is not None:
        return (Rotation.from_quat(q_lvlh).inv() * body_rotation).as_rotvec(), "LVLH"
    return (body_rotation[0].inv() * body_rotation).as_rotvec(), "its attitude at t0 (W axes)"


def bodies(run: RecordedRun, c: str) -> dict:
    """Per body: attitude (against LVLH when known), momentum, joint angles."""
    t, params = run.time, run.parameters(c)
    made = {}
    for body in params.get("bodies") or {}:
        attitude = attitude_in_lvlh(run, c, body)
        momentum = run.vector(f"{c}.{body}.momentum", 6)
        q = run.vector(f"{c}.{body}.q")
        found = {"attitude": attitude, "momentum": momentum, "joints": q}
        panels = [panel for panel, data in found.items() if data is not None]
        if not panels:
            continue
        fig = new_figure(9.0, 3.2 * len(panels))
        for row, panel in enumerate(panels, start=1):
            ax = fig.add_subplot(len(panels), 1, row)
            if panel == "attitude":
                assert attitude is not None  # a panel only with its data (as the two below)
                angles, frame = attitude
                for k, axis in enumerate("xyz"):
                    ax.plot(t, np.degrees(angles[:, k]), linewidth=1.0, label=f"about {axis}")
                ax.set(ylabel="deg", title=f"{c}.{body}: attitude against {frame} (rotation vector)")
            elif panel == "momentum":
                assert momentum is not None
                for k, label in enumerate(("p_x", "p_y", "p_z")):
                    ax.plot(t, momentum[:, k] - momentum[0, k], linewidth=1.0, label=label + " (kg m/s)")
                for k, label in enumerate(("L_x", "L_y", "L_z")):
                    ax.plot(
                        t,
                        momentum[:, 3 + k] - momentum[0, 3 + k],
                        linewidth=1.0,
                        linestyle="--",
                        label=label + " (kg m^2/s)",
                    )
                ax.set(ylabel="change from t0", title=f"{c}.{body}: momentum (W axes, angular about the CoM)")
            else:
                assert q is not None
                names = run.joint_names((params["bodies"][body] or {}).get("urdf"), q.shape[1])
                for k in range(q.shape[1]):
                    ax.plot(t, q[:, k], linewidth=1.0, label=f"q[{k}]" if names[k].startswith("tau[") else names[k])
                ax.set(ylabel="rad or m", title=f"{c}.{body}: joint positions")
            ax.set_xlabel("time (s)")
            ax.grid(True, alpha=0.3)
            ax.legend(loc="upper right", fontsize="x-small", ncols=2)
        made[f"{c}_{body}.png"] = fig
    return made


def capture(run: RecordedRun, c: str) -> dict:
    """The capture: approach, impact and detumbling on one page."""
    t, params = run.time, run.parameters(c)
    grasp = params.get("grasp")
    p = run.vector(f"{c}.grasp.p_ee_grasp", 3)
    if not grasp or p is None:
        return {}
    chaser, target = grasp["chaser"], grasp["target"]
    relative = run.vector(f"{c}.grasp.twist_ee_grasp", 6)
    wrench = run.vector(f"{c}.grasp.wrench", 6)
    closed = run.columns.get(f"{c}.grasp.closed")
    t_capture = t[np.argmax(closed >= 0.5)] if closed is not None and np.any(closed >= 0.5) else None
    rates = {body: run.vector(f"{c}.{body}.twist", 6) for body in (chaser, target)}
    qd = run.vector(f"{c}.{chaser}.qd")
    joints = run.joint_names((params["bodies"][chaser] or {}).get("urdf"), qd.shape[1]) if qd is not None else []
    wheels = [i for i, j in enumerate(joints) if "wheel" in j] if qd is not None else []
    total = _total_momentum(run, c, params, len(t))
    fig = new_figure(12.0, 15.0)
    axes = fig.subplot_mosaic(
        [["distance", "rate"], ["rel_v", "rel_w"], ["force", "torque"], ["wheels", "wheels"], ["p", "L"]]
    )
    # one quantity per axis, its unit the axis' label
    axes["distance"].plot(t, 1e3 * np.linalg.norm(p, axis=1))
    axes["distance"].set(yscale="log", ylabel="mm", title=f"{c}: end effector to grasp frame, distance")
    if relative is not None:
        axes["rel_v"].plot(t, 1e3 * np.linalg.norm(relative[:, :3], axis=1))
        axes["rel_v"].set(yscale="log", ylabel="mm/s", title="grasp frame's velocity relative to the EE")
        axes["rel_w"].plot(t, np.degrees(np.linalg.norm(relative[:, 3:], axis=1)), color="tab:orange")
        axes["rel_w"].set(yscale="log", ylabel="deg/s", title="grasp frame's rate relative to the EE")
    for body, twist in rates.items():
        if twist is not None:
            axes["rate"].plot(t, np.degrees(np.linalg.norm(twist[:, 3:], axis=1)), label=body)
    axes["rate"].axhline(0.1, color="grey", linestyle=":", label="0.1 deg/s")
    axes["rate"].set(ylabel="deg/s", title="angular rate (inertial)")
    if qd is not None:  # (no wheels without it)
        for i in wheels:
            axes["wheels"].plot(t, qd[:, i], label=joints[i])
    axes["wheels"].set(ylabel="rad/s", title=f"{chaser}: wheel rates" if wheels else "no joints named *wheel*")
    if wrench is not None:
        axes["force"].plot(t, np.linalg.norm(wrench[:, :3], axis=1))
        axes["force"].set(ylabel="N", title="|force| at the grasp (a wrist F/T sensor's)")
        axes["torque"].plot(t, np.linalg.norm(wrench[:, 3:], axis=1), color="tab:orange")
        axes["torque"].set(ylabel="N m", title="|torque| at the grasp (a wrist F/T sensor's)")
    if total is not None:
        change = total - total[0]
        why = _momentum_changed_by(params)
        axes["p"].plot(t, np.linalg.norm(change[:, :3], axis=1))
        axes["p"].set(ylabel="kg m/s", title=f"total linear momentum, change from t0\n{why}")
        axes["L"].plot(t, np.linalg.norm(change[:, 3:], axis=1), color="tab:orange")
        axes["L"].set(ylabel="kg m^2/s", title=f"total angular momentum (about W's origin), change\n{why}")
    for name, ax in axes.items():
        if t_capture is not None:
            ax.axvline(t_capture, color="red", linewidth=0.8, label="capture")
        ax.set_xlim(t[0], t[-1])
        if name in ("p", "L"):
            ax.set_xlabel("time (s)")
        ax.grid(True, alpha=0.3)
        if len(ax.get_legend_handles_labels()[0]) > 1:
            ax.legend(loc="upper right", fontsize="x-small", ncols=2)
    return {f"{c}_capture.png": fig}


def _total_momentum(run: RecordedRun, c: str, params: dict, rows: int) -> np.ndarray | None:
    """All bodies' momentum (linear; angular about W's origin), or None when a body's momentum or
    CoM is not recorded."""
    total = np.zeros((rows, 6))
    for body in params.get("bodies") or {}:
        momentum, com = run.vector(f"{c}.{body}.momentum", 6), run.vector(f"{c}.{body}.com", 3)
        if momentum is None or com is None:
            return None
        total[:, :3] += momentum[:, :3]
        total[:, 3:] += momentum[:, 3:] + np.cross(com, momentum[:, :3])
    return total


def _momentum_changed_by(params: dict) -> str:
    """What changes the bodies' total momentum in this run (all bodies, wheels included: the
    capture and the wheels exchange it, the environment's external forces change it)."""
    external = [
        name
        for key, name in (("tidal_force", "the tidal force"), ("gravity_gradient", "gravity gradient"))
        if params.get(key, True)
    ]
    if not external:
        return "(no external force: the capture and wheels only exchange it)"
    return f"(changed by {' and '.join(external)})"


BODIES = Plot(
    "{c}_{body}.png",
    "per body: attitude against LVLH as a rotation vector (about z: the pitch of a "
    "libration; against the body's t0 attitude if q_eci_lvlh is not connected), momentum "
    "change from t0, joint positions",
    bodies,
)
CAPTURE = Plot(
    "{c}_capture.png",
    "with a ``grasp``: distance and relative rate to the grasp frame, the assembly's "
    "rate, wheel rates (joints named ``*wheel*``), the wrist force and torque, and the "
    "total linear and angular momentum's change with what changes it, the capture "
    "instant marked",
    capture,
)


def magnetic(run: RecordedRun, c: str) -> dict:
    """Per body with the magnetic field: its angular rate, the field in its axes and the
    magnetorquers' torque (a detumbling on one page)."""
    t, params = run.time, run.parameters(c)
    made = {}
    for body in params.get("bodies") or {}:
        b = run.vector(f"{c}.{body}.b_body", 3)
        twist = run.vector(f"{c}.{body}.twist", 6)
        if b is None or twist is None:
            continue
        torque = run.vector(f"{c}.{body}.mtb_torque", 3)
        rows = 3 if torque is not None else 2
        fig = new_figure(9.0, 3.0 * rows)
        ax = fig.add_subplot(rows, 1, 1)
        w = np.degrees(twist[:, 3:6])
        for k, axis in enumerate("xyz"):
            ax.plot(t, w[:, k], linewidth=0.8, label=f"w_{axis} (W axes)")
        ax.plot(t, np.linalg.norm(w, axis=1), color="k", linewidth=1.5, label="|w|")
        ax.set(ylabel="deg/s", title=f"{c}.{body}: angular rate (inertial)")
        panels = [("b_body", b * 1e6, "uT", "magnetic field, base axes")]
        if torque is not None:
            panels.append(("mtb_torque", torque * 1e3, "mN m", "magnetorquers' torque, base axes"))
        for row, (name, values, unit, what) in enumerate(panels, start=2):
            ax.legend(loc="upper right", fontsize="x-small", ncols=2)
            ax.grid(True, alpha=0.3)
            ax = fig.add_subplot(rows, 1, row)
            for k in range(3):
                ax.plot(t, values[:, k], linewidth=0.8, label=f"{name}[{k}]")
            ax.set(ylabel=unit, title=f"{c}.{body}: {what}")
        ax.legend(loc="upper right", fontsize="x-small", ncols=2)
        ax.grid(True, alpha=0.3)
        ax.set_xlabel("time (s)")
        made[f"{c}_{body}_magnetic.png"] = fig
    return made


MAGNETIC = Plot(
    "{c}_{body}_magnetic.png",
    "per body with magnetic_field: its angular rate, the field in its axes and the magnetorquers' torque",
    magnetic,
)
