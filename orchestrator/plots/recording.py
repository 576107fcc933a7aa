"""PNG plots of a recording (``orchestrator plot DIR``), picked by the component types in it.

``plot_recording(record_dir, out_dir)`` reads ``DIR/signals.parquet`` and ``DIR/config.yaml``
(docs/design.md §6) and writes, for each component of a type it knows:

| file | for | content |
|---|---|---|
| ``<c>_track.png`` | orbit.* | altitude, ground track (spherical Earth, UT1 = UTC), r_eci and v_eci over time |
| ``<c>_<body>.png`` | dynamics.dart, dynamics.pinocchio | per body: attitude against LVLH as a rotation vector (about z: the pitch of a libration; against the body's t0 attitude if q_eci_lvlh is not connected), momentum change from t0, joint positions |
| ``<c>_path.png`` | controller.computed_torque | desired (black) and obtained (red) 3D end-effector path relative to its start, in the axes of the base at t0 (inertial; W axes if the base orientation is not recorded) (paper Fig. 5) |
| ``<c>_error.png`` | controller.computed_torque | position error (mm) and orientation error (mrad) per W axis and norm, over time (Fig. 6) |
| ``<c>_torque.png`` | computed_torque, joint_pd | torques of the driven joints, N m (Fig. 7) |
| ``<c>_base.png`` | controller.computed_torque | the body's base displacement (mm, W) and rotation (deg) from t0, and sigma_min of J_g |
| ``<c>_joints.png`` | controller.joint_pd | joint positions and their references |
| ``<c>_shadow.png`` | a component with a ``shadow`` | main - shadow over time for each output both record (orchestrator/plots/shadows.py) |
| ``<c>_capture.png`` | dynamics.* with a ``grasp`` | distance and relative rate to the grasp frame, the assembly's rate, wheel rates (joints named ``*wheel*``), the wrist wrench, and the total momentum's change, the capture instant marked |

``signals=[name, ...]`` plots those columns instead (``signals.png``): a column such as
``dynamics.target.q[0]``, or all elements of a vector, ``orbit.r_eci``. ``<c>`` is the component's
name in the config. Matplotlib's Agg canvas is used directly (no pyplot, no display).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from components.rotations import quat_to_matrix
from orchestrator.plots.figure import PlotError, new_figure
from orchestrator.plots.shadows import shadow_figures

COMPUTED_TORQUE = "controller.computed_torque"
JOINT_PD = "controller.joint_pd"
DYNAMICS = ("dynamics.dart", "dynamics.pinocchio")      # the engines: the same outputs
ORBIT = "orbit."


def _load(record_dir: Path) -> tuple[dict, dict[str, np.ndarray]]:
    import pyarrow.parquet as pq
    import yaml

    signals, config = record_dir / "signals.parquet", record_dir / "config.yaml"
    for path in (signals, config):
        if not path.exists():
            raise PlotError(f"{path} not found (expected a directory written by `orchestrator run --record`)")
    resolved = yaml.safe_load(config.read_text()) or {}
    table = pq.read_table(signals)
    return resolved, {name: table.column(name).to_numpy() for name in table.column_names}


def _vector(columns: dict[str, np.ndarray], name: str, n: int | None = None) -> np.ndarray | None:
    """Columns ``name[0..n-1]`` as an (rows, n) array (all of them when n is None); None if absent."""
    if n is None:
        n = 0
        while f"{name}[{n}]" in columns:
            n += 1
    if n == 0 or any(f"{name}[{i}]" not in columns for i in range(n)):
        return None
    return np.column_stack([columns[f"{name}[{i}]"] for i in range(n)])


def _source(config: dict, component: str, variable: str) -> str | None:
    """The output feeding ``component.variable`` (``dynamics.humanoid.position``), if connected."""
    return (config.get("connections") or {}).get(f"{component}.{variable}")


def _joint_names(record_dir: Path, params: dict, n: int) -> list[str]:
    """Names of the body's n joints (URDF order) if the URDF can be found, else tau[i]. The
    controller's ``urdf`` is resolved as the run resolved it (:func:`read_model`: relative to
    the original config file, found through the recording's start event)."""
    from components.errors import ConfigError
    from components.robots.model import read_model
    from components.viewer.replay import ReplayError, read_recording

    try:
        config_dir = read_recording(record_dir)[1]
        names = read_model(params.get("urdf"), config_dir, "urdf").movable_joints
    except (ConfigError, ReplayError, OSError):
        names = []
    return names if len(names) == n else [f"tau[{i}]" for i in range(n)]


def _driven(tau: np.ndarray) -> np.ndarray:
    """Indices of the torque columns that are not identically zero."""
    return np.flatnonzero(np.any(tau != 0.0, axis=0))


def _computed_torque(name: str, params: dict, config: dict, columns: dict, t: np.ndarray,
                     record_dir: Path) -> list[tuple[str, object]]:
    written = []
    p = _vector(columns, f"{name}.ee_position", 3)
    p_d = _vector(columns, f"{name}.ee_position_desired", 3)
    error = _vector(columns, f"{name}.ee_error", 6)
    tau = _vector(columns, f"{name}.tau")
    if p is None or p_d is None or error is None or tau is None:
        raise PlotError(f"{name}: the recording lacks ee_position, ee_position_desired, ee_error or tau")
    # the path in the base's initial frame (inertial: the torso's axes at t0), as the paper draws
    # it; in W axes when the base orientation is not in the recording
    origin, frame = p_d[0], "W"
    q_source = _source(config, name, "orientation")
    q_base = _vector(columns, q_source, 4) if q_source else None
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
    ax.set_title(f"{name}: end-effector path in {frame}, relative to its start")
    ax.legend(loc="upper left")
    span = np.ptp(np.vstack([p - origin, p_d - origin]), axis=0).max() / 2 or 0.1
    centre = (np.vstack([p, p_d]) - origin).min(axis=0) + np.ptp(np.vstack([p, p_d]) - origin, axis=0) / 2
    ax.set_xlim(centre[0] - span, centre[0] + span)
    ax.set_ylim(centre[1] - span, centre[1] + span)
    ax.set_zlim(centre[2] - span, centre[2] + span)
    written.append((f"{name}_path.png", fig))

    fig = new_figure(8.0, 6.0)
    axes = fig.subplots(2, 1, sharex=True)
    for ax, part, scale, unit, title in ((axes[0], error[:, :3], 1e3, "mm", "a) position error p_d - p"),
                                         (axes[1], error[:, 3:], 1e3, "mrad", "b) orientation error log(R_d R^T)")):
        for i, axis in enumerate("xyz"):
            ax.plot(t, part[:, i] * scale, linewidth=1.0, label=axis)
        ax.plot(t, np.linalg.norm(part, axis=1) * scale, color="black", linewidth=1.0, label="norm")
        ax.set_ylabel(unit)
        ax.set_title(title, loc="left")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", ncols=4, fontsize="small")
    axes[1].set_xlabel("time (s)")
    fig.suptitle(f"{name}: tracking error (W axes)")
    written.append((f"{name}_error.png", fig))

    written.append(_torques(name, params, tau, t, record_dir))

    base_source = _source(config, name, "position")
    base = _vector(columns, base_source, 3) if base_source else None
    sigma = columns.get(f"{name}.sigma_min")
    if base is not None or sigma is not None:
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
        written.append((f"{name}_base.png", fig))
    return written


def _torques(name, params, tau, t, record_dir) -> tuple[str, object]:
    names = _joint_names(record_dir, params, tau.shape[1])
    fig = new_figure(8.0, 4.5)
    ax = fig.add_subplot()
    driven = _driven(tau)
    for i in driven:
        ax.plot(t, tau[:, i], linewidth=1.0, label=names[i])
    if driven.size == 0:
        ax.text(0.5, 0.5, "all torques zero", transform=ax.transAxes, ha="center")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("N m")
    ax.set_title(f"{name}: joint torques")
    ax.grid(True, alpha=0.3)
    if driven.size:
        ax.legend(loc="upper right", fontsize="small", ncols=2)
    return (f"{name}_torque.png", fig)


def _joint_pd(name, params, config, columns, t, record_dir) -> list[tuple[str, object]]:
    tau = _vector(columns, f"{name}.tau")
    q_d = _vector(columns, f"{name}.q_desired")
    if tau is None or q_d is None:
        raise PlotError(f"{name}: the recording lacks tau or q_desired")
    written = [_torques(name, params, tau, t, record_dir)]
    source = _source(config, name, "q")
    q = _vector(columns, source) if source else None
    names = _joint_names(record_dir, params, tau.shape[1])
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
    ax.set_title(f"{name}: joint positions (solid) and references (dashed)")
    ax.grid(True, alpha=0.3)
    if driven and q is not None:
        ax.legend(loc="upper right", fontsize="small", ncols=2)
    written.append((f"{name}_joints.png", fig))
    return written


def _orbit(name: str, config: dict, columns: dict, t: np.ndarray) -> list[tuple[str, object]]:
    """Altitude, ground track, and r, v over time of an orbit component's r_eci, v_eci."""
    import erfa

    from components.constants import R_EARTH
    from components.orbit import timescales

    r, v = _vector(columns, f"{name}.r_eci", 3), _vector(columns, f"{name}.v_eci", 3)
    if r is None:
        return []
    utc = timescales.parse_utc(str((config.get("run") or {}).get("epoch")))
    angle = np.array([erfa.era00(utc[0], utc[1] + s / 86400.0) for s in t])   # Earth rotation, UT1 ~ UTC
    x = np.cos(angle) * r[:, 0] + np.sin(angle) * r[:, 1]                      # Earth-fixed
    y = -np.sin(angle) * r[:, 0] + np.cos(angle) * r[:, 1]
    radius = np.linalg.norm(r, axis=1)
    fig = new_figure(11.0, 7.0)
    ax = fig.add_subplot(2, 2, 1)
    altitude = (radius - R_EARTH) / 1e3
    ax.plot(t, altitude, color="k", linewidth=1.0)
    ax.ticklabel_format(axis="y", useOffset=False)
    if np.ptp(altitude) < 1.0:                      # a circular orbit: no axis of rounding noise
        ax.set_ylim(altitude.mean() - 1.0, altitude.mean() + 1.0)
    ax.set(xlabel="time (s)", ylabel="km", title=f"{name}: altitude above {R_EARTH / 1e3:g} km")
    ax = fig.add_subplot(2, 2, 2)
    lon, lat = np.degrees(np.arctan2(y, x)), np.degrees(np.arcsin(r[:, 2] / radius))
    jumps = np.abs(np.diff(lon, prepend=lon[0])) > 180                           # break the line at +-180
    ax.plot(np.where(jumps, np.nan, lon), lat, color="tab:blue", linewidth=1.0)
    ax.set(xlim=(-180, 180), ylim=(-90, 90), xlabel="longitude (deg)", ylabel="latitude (deg)",
           title=f"{name}: ground track (spherical Earth)")
    for i, (vector, unit, what) in enumerate(((r / 1e3, "km", "r_eci"), (v / 1e3 if v is not None else None, "km/s", "v_eci"))):
        ax = fig.add_subplot(2, 2, 3 + i)
        if vector is not None:
            for k, axis in enumerate("xyz"):
                ax.plot(t, vector[:, k], linewidth=1.0, label=axis)
            ax.legend(loc="upper right", fontsize="small")
        ax.set(xlabel="time (s)", ylabel=unit, title=f"{name}.{what} (ECI)")
    for ax in fig.axes:
        ax.grid(True, alpha=0.3)
    return [(f"{name}_track.png", fig)]


def attitude_in_lvlh(config: dict, columns: dict, component: str, body: str) -> tuple[np.ndarray, str] | None:
    """The body's attitude as a rotation vector (rad, rows x 3): relative to LVLH (its axes: x
    radial, y along-track, z orbit normal; z is the pitch of a libration) when the component's
    q_eci_lvlh input is recorded, else relative to the body's attitude at t0 in W axes.
    Returns (rotation vectors, frame name), or None without the orientation columns."""
    from scipy.spatial.transform import Rotation

    q_body = _vector(columns, f"{component}.{body}.orientation", 4)
    if q_body is None:
        return None
    source = _source(config, component, "q_eci_lvlh")
    q_lvlh = _vector(columns, source, 4) if source else None
    body_rotation = Rotation.from_quat(q_body)
    if q_lvlh is not None:
        return (Rotation.from_quat(q_lvlh).inv() * body_rotation).as_rotvec(), "LVLH"
    return (body_rotation[0].inv() * body_rotation).as_rotvec(), "its attitude at t0 (W axes)"


def _dynamics(name: str, params: dict, config: dict, columns: dict, t: np.ndarray,
              record_dir: Path) -> list[tuple[str, object]]:
    """Per body: attitude (against LVLH when known), momentum, joint angles."""
    written = []
    for body in (params.get("bodies") or {}):
        attitude = attitude_in_lvlh(config, columns, name, body)
        momentum = _vector(columns, f"{name}.{body}.momentum", 6)
        q = _vector(columns, f"{name}.{body}.q")
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
                ax.set(ylabel="deg", title=f"{name}.{body}: attitude against {frame} (rotation vector)")
            elif panel == "momentum":
                for k, label in enumerate(("p_x", "p_y", "p_z")):
                    ax.plot(t, momentum[:, k] - momentum[0, k], linewidth=1.0, label=label + " (kg m/s)")
                for k, label in enumerate(("L_x", "L_y", "L_z")):
                    ax.plot(t, momentum[:, 3 + k] - momentum[0, 3 + k], linewidth=1.0, linestyle="--",
                            label=label + " (kg m^2/s)")
                ax.set(ylabel="change from t0", title=f"{name}.{body}: momentum (W axes, angular about the CoM)")
            else:
                names = _joint_names(record_dir, {"urdf": (params["bodies"][body] or {}).get("urdf")}, q.shape[1])
                for k in range(q.shape[1]):
                    ax.plot(t, q[:, k], linewidth=1.0, label=f"q[{k}]" if names[k].startswith("tau[") else names[k])
                ax.set(ylabel="rad or m", title=f"{name}.{body}: joint positions")
            ax.set_xlabel("time (s)")
            ax.grid(True, alpha=0.3)
            ax.legend(loc="upper right", fontsize="x-small", ncols=2)
        written.append((f"{name}_{body}.png", fig))
    return written


def _capture(name: str, params: dict, columns: dict, t: np.ndarray, record_dir: Path) -> list[tuple[str, object]]:
    """The capture: approach, impact and detumbling on one page."""
    grasp = params.get("grasp")
    p = _vector(columns, f"{name}.grasp.p_ee_grasp", 3)
    if not grasp or p is None:
        return []
    chaser, target = grasp["chaser"], grasp["target"]
    relative = _vector(columns, f"{name}.grasp.twist_ee_grasp", 6)
    wrench = _vector(columns, f"{name}.grasp.wrench", 6)
    closed = columns.get(f"{name}.grasp.closed")
    t_capture = t[np.argmax(closed >= 0.5)] if closed is not None and np.any(closed >= 0.5) else None
    rates = {body: _vector(columns, f"{name}.{body}.twist", 6) for body in (chaser, target)}
    qd = _vector(columns, f"{name}.{chaser}.qd")
    joints = _joint_names(record_dir, {"urdf": (params["bodies"][chaser] or {}).get("urdf")}, qd.shape[1]) \
        if qd is not None else []
    wheels = [i for i, j in enumerate(joints) if "wheel" in j] if qd is not None else []
    total = np.zeros((len(t), 6))
    for body in params.get("bodies") or {}:
        momentum, com = _vector(columns, f"{name}.{body}.momentum", 6), _vector(columns, f"{name}.{body}.com", 3)
        if momentum is None or com is None:
            total = None
            break
        total[:, :3] += momentum[:, :3]
        total[:, 3:] += momentum[:, 3:] + np.cross(com, momentum[:, :3])
    fig = new_figure(9.0, 14.0)
    axes = [fig.add_subplot(6, 1, k) for k in range(1, 7)]
    axes[0].plot(t, 1e3 * np.linalg.norm(p, axis=1), label="distance E to G (mm)")
    axes[0].set(yscale="log", title=f"{name}: end effector to grasp frame")
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
    return [(f"{name}_capture.png", fig)]


def _signals(names: list[str], columns: dict, t: np.ndarray) -> list[tuple[str, object]]:
    """One panel per name: a column (``x[0]``) or every element of a vector (``dynamics.b.q``)."""
    series = {}
    for name in names:
        if name in columns:
            series[name] = columns[name][:, None]
        elif (vector := _vector(columns, name)) is not None:
            series[name] = vector
        else:
            near = sorted({c.split("[")[0] for c in columns if c not in ("step", "time")})
            raise PlotError(f"--signals: no column {name!r} in the recording (signals: {', '.join(near)})")
    fig = new_figure(9.0, 2.6 * len(series))
    for row, (name, values) in enumerate(series.items(), start=1):
        ax = fig.add_subplot(len(series), 1, row)
        for k in range(values.shape[1]):
            ax.plot(t, values[:, k], linewidth=1.0, label=f"[{k}]" if values.shape[1] > 1 else None)
        ax.set(xlabel="time (s)", title=name)
        ax.grid(True, alpha=0.3)
        if values.shape[1] > 1:
            ax.legend(loc="upper right", fontsize="x-small", ncols=2)
    return [("signals.png", fig)]


def figures(record_dir, signals: list[str] | None = None) -> list[tuple[str, object]]:
    """(file name, matplotlib Figure) for a recording: the module table's figures, picked by the
    component types in its config.yaml, or one figure of the named ``signals``.

    PlotError when the recording is missing, lacks the columns a figure needs, or has nothing
    to plot.
    """
    record_dir = Path(record_dir)
    if (record_dir / "cases.parquet").exists() and not signals:   # a campaign (orchestrator sweep --out DIR)
        from orchestrator.plots.campaigns import campaign_figures
        return campaign_figures(record_dir)
    config, columns = _load(record_dir)
    if "time" not in columns or not len(columns["time"]):
        raise PlotError(f"{record_dir / 'signals.parquet'}: the recording holds no rows (the run wrote none before it ended: its events.jsonl says why)")
    t = np.asarray(columns["time"], dtype=float)
    if signals:
        return _signals(signals, columns, t)
    written: list[tuple[str, object]] = []
    for name, spec in (config.get("components") or {}).items():
        kind = (spec or {}).get("type") or ""
        params = (spec or {}).get("parameters") or {}
        if kind == COMPUTED_TORQUE:
            written += _computed_torque(name, params, config, columns, t, record_dir)
        elif kind == JOINT_PD:
            written += _joint_pd(name, params, config, columns, t, record_dir)
        elif kind in DYNAMICS:
            written += _dynamics(name, params, config, columns, t, record_dir)
            written += _capture(name, params, columns, t, record_dir)
        elif kind.startswith(ORBIT):
            written += _orbit(name, config, columns, t)
    written += shadow_figures(config, columns, t)
    if not written:
        types = ", ".join(sorted({(s or {}).get("type", "?") for s in (config.get("components") or {}).values()}))
        raise PlotError(f"nothing to plot in {record_dir}: no figures for its component types ({types}); "
                        f"name columns to plot with --signals NAME,NAME")
    return written


def plot_recording(record_dir, out_dir, signals: list[str] | None = None) -> list[Path]:
    """Write :func:`figures` as PNGs into ``out_dir`` (created only then); return their paths."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    made = figures(record_dir, signals)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for filename, fig in made:
        FigureCanvasAgg(fig)
        fig.savefig(out_dir / filename, dpi=110)
        paths.append(out_dir / filename)
    return paths
