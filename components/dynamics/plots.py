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
    for body in (params.get("bodies") or {}):
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
                angles, frame = attitude
                for k, axis in enumerate("xyz"):
                    ax.plot(t, np.degrees(angles[:, k]), linewidth=1.0, label=f"about {axis}")
                ax.set(ylabel="deg", title=f"{c}.{body}: attitude against {frame} (rotation vector)")
            elif panel == "momentum":
                for k, label in enumerate(("p_x", "p_y", "p_z")):
                    ax.plot(t, momentum[:, k] - momentum[0, k], linewidth=1.0, label=label + " (kg m/s)")
                for k, label in enumerate(("L_x", "L_y", "L_z")):
                    ax.plot(t, momentum[:, 3 + k] - momentum[0, 3 + k], linewidth=1.0, linestyle="--",
                            label=label + " (kg m^2/s)")
                ax.set(ylabel="change from t0", title=f"{c}.{body}: momentum (W axes, angular about the CoM)")
            else:
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
    total = np.zeros((len(t), 6))
    for body in params.get("bodies") or {}:
        momentum, com = run.vector(f"{c}.{body}.momentum", 6), run.vector(f"{c}.{body}.com", 3)
        if momentum is None or com is None:
            total = None
            break
        total[:, :3] += momentum[:, :3]
        total[:, 3:] += momentum[:, 3:] + np.cross(com, momentum[:, :3])
    fig = new_figure(9.0, 14.0)
    axes = [fig.add_subplot(6, 1, k) for k in range(1, 7)]
    axes[0].plot(t, 1e3 * np.linalg.norm(p, axis=1), label="distance E to G (mm)")
    axes[0].set(yscale="log", title=f"{c}: end effector to grasp frame")
    if relative is not None:
        axes[1].plot(t, 1e3 * np.linalg.norm(relative[:, :3], axis=1), label="relative velocity (mm/s)")
        axes[1].plot(t, np.degrees(np.linalg.norm(relative[:, 3:], axis=1)), label="relative rate (deg/s)")
        axes[1].set(yscale="log", title="grasp frame relative to the end effector")
    for body, twist in rates.items():
        if twist is not None:
            axes[2].plot(t, np.degrees(np.linalg.norm(twist[:, 3:], axis=1)), label=f"{body} (deg/s)")
    axes[2].axhline(0.1, color="grey", linestyle=":", label="0.1 deg/s")
    axes[2].set(title="angular rate (inertial)")
    for i in wheels:
        axes[3].plot(t, qd[:, i], label=joints[i])
    axes[3].set(ylabel="rad/s", title=f"{chaser}: wheel rates" if wheels else "no joints named *wheel*")
    if wrench is not None:
        axes[4].plot(t, np.linalg.norm(wrench[:, :3], axis=1), label="|force| (N)")
        axes[4].plot(t, np.linalg.norm(wrench[:, 3:], axis=1), label="|torque| (N m)")
        axes[4].set(title="wrench at the grasp (what a wrist F/T sensor reads)")
    if total is not None:
        change = total - total[0]
        axes[5].plot(t, np.linalg.norm(change[:, :3], axis=1), label="linear (kg m/s)")
        axes[5].plot(t, np.linalg.norm(change[:, 3:], axis=1), label="angular about W's origin (kg m^2/s)")
        axes[5].set(title="total momentum, change from t0 (all bodies, wheels included)")
    for ax in axes:
        if t_capture is not None:
            ax.axvline(t_capture, color="red", linewidth=0.8, label="capture" if ax is axes[0] else None)
        ax.set_xlabel("time (s)")
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper right", fontsize="x-small", ncols=2)
    fig.tight_layout()
    return {f"{c}_capture.png": fig}


BODIES = Plot("{c}_{body}.png", "per body: attitude against LVLH as a rotation vector (about z: the pitch of a "
                                "libration; against the body's t0 attitude if q_eci_lvlh is not connected), momentum "
                                "change from t0, joint positions", bodies)
CAPTURE = Plot("{c}_capture.png", "with a ``grasp``: distance and relative rate to the grasp frame, the assembly's "
                                  "rate, wheel rates (joints named ``*wheel*``), the wrist wrench, and the total "
                                  "momentum's change, the capture instant marked", capture)
