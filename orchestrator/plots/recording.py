"""PNG plots of a recording (``orchestrator plot DIR``): the plots its component types declare.

``plot_recording(record_dir, out_dir)`` reads ``DIR/signals.parquet`` and ``DIR/config.yaml``
(docs/design.md §6) and writes, for each component, the figures its type declares (``plots``, a
tuple of :class:`components.plotting.Plot`: a user's type adds its own the same way), and
``<c>_shadow.png`` for a component with a ``shadow`` (main - shadow over time for each output
both record, orchestrator/plots/shadows.py). The registered types' plots (:func:`plot_table`):

| file | for | content |
|---|---|---|
| ``<c>_track.png`` | orbit.kepler, orbit.numerical, orbit.sgp4, orbit.custom_path, orbit.fixed | altitude, ground track (spherical Earth, UT1 = UTC), r_eci and v_eci over time |
| ``<c>_accelerations.png`` | orbit.numerical | magnitude of each acceleration term over time (orbit.numerical) |
| ``<c>_<body>.png`` | dynamics.dart, dynamics.pinocchio | per body: attitude against LVLH as a rotation vector (about z: the pitch of a libration; against the body's t0 attitude if q_eci_lvlh is not connected), momentum change from t0, joint positions |
| ``<c>_capture.png`` | dynamics.dart, dynamics.pinocchio | with a ``grasp``: distance and relative rate to the grasp frame, the assembly's rate, wheel rates (joints named ``*wheel*``), the wrist force and torque, and the total linear and angular momentum's change with what changes it, the capture instant marked |
| ``<c>_<body>_magnetic.png`` | dynamics.dart, dynamics.pinocchio | per body with magnetic_field: its angular rate, the field in its axes and the magnetorquers' torque |
| ``<c>_path.png`` | controller.computed_torque | desired (black) and obtained (red) 3D end-effector path relative to its start, in the axes of the base at t0 (inertial; W axes if the base orientation is not recorded) (paper Fig. 5) |
| ``<c>_error.png`` | controller.computed_torque | position error (mm) and orientation error (mrad) per W axis and norm, over time (Fig. 6) |
| ``<c>_torque.png`` | controller.computed_torque, controller.joint_pd, controller.capture | torques of the driven joints, N m (Fig. 7) |
| ``<c>_base.png`` | controller.computed_torque | the body's base displacement (mm, W) and rotation (deg) from t0, and sigma_min of J_g |
| ``<c>_joints.png`` | controller.joint_pd | joint positions and their references |
| ``<c>_phases.png`` | controller.capture | the capture's phase and attempts, the estimated distance to the grasp frame and the estimated errors behind close (position, attitude, velocity, rate: an axis each) |
| ``<c>_bdot.png`` | controller.bdot | the commanded dipole and |dB/dt| over time |
| ``<c>_measured.png`` | sensor.imu | rate, specific_force (solid) against the outputs feeding rate_true, specific_force_true (dashed), per element |
| ``<c>_measured.png`` | sensor.force_torque | wrench (solid) against the outputs feeding wrench_true (dashed), per element |
| ``<c>_measured.png`` | sensor.relative_pose | p, q (solid) against the outputs feeding p_true, q_true (dashed), per element |
| ``<c>_measured.png`` | sensor.magnetometer | b (solid) against the outputs feeding b_true (dashed), per element |
| ``<c>_pose.png`` | estimator.fiducial | each frame's position and attitude error against the dynamics' grasp pose (when recorded), markers found, valid, RMS reprojection error |

``signals=[name, ...]`` plots those columns instead (``signals.png``): a column such as
``dynamics.target.q[0]``, or all elements of a vector, ``orbit.r_eci``. ``<c>`` is the component's
name in the config. Matplotlib's Agg canvas is used directly (no pyplot, no display).
"""

from __future__ import annotations

import re
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from components.plotting import Plot, PlotError, RecordedRun, new_figure
from orchestrator.plots.shadows import shadow_figures


def load_run(record_dir: Path) -> RecordedRun:
    """A recording as :class:`RecordedRun`; PlotError when DIR holds none (or no rows)."""
    import pyarrow.parquet as pq
    import yaml

    signals, config = record_dir / "signals.parquet", record_dir / "config.yaml"
    for path in (signals, config):
        if not path.exists():
            raise PlotError(f"{path} not found (expected a directory written by `orchestrator run --record`)")
    resolved = yaml.safe_load(config.read_text()) or {}
    table = pq.read_table(signals)
    columns = {name: table.column(name).to_numpy() for name in table.column_names}
    if "time" not in columns or not len(columns["time"]):
        raise PlotError(
            f"{signals}: the recording holds no rows (the run wrote none before it ended: its events.jsonl says why)"
        )
    return RecordedRun(
        resolved, columns, np.asarray(columns["time"], dtype=float), _config_dir(record_dir), Path(record_dir)
    )


def _config_dir(record_dir: Path) -> Path | None:
    """The directory of the run's original config file (a ``file.py:Class`` type is relative to it)."""
    from components.viewer.replay import ReplayError, read_recording

    try:
        return read_recording(record_dir)[1]
    except ReplayError:
        return None


def _declared(run: RecordedRun, warn: Callable[[str], None]) -> list[tuple[str, object]]:
    """The figures the component types of the run declare, component by component in config order."""
    from components import registry
    from components.errors import ConfigError

    made: list[tuple[str, object]] = []
    for name, spec in (run.config.get("components") or {}).items():
        type_name = (spec or {}).get("type")
        try:
            cls = registry.load(type_name, run.config_dir)
        except ConfigError as e:
            warn(f"{name}: no plots ({e.message})")
            continue
        for plot in cls.plots:
            for file, fig in plot.draw(run, name).items():
                if not plot.matches(name, file):
                    raise PlotError(
                        f"{name} ({type_name}): its plot {plot.file!r} made {file!r}, which that "
                        "file name does not describe"
                    )
                made.append((file, fig))
    return made


def _signals(names: list[str], run: RecordedRun) -> list[tuple[str, object]]:
    """One panel per name: a column (``x[0]``) or every element of a vector (``dynamics.b.q``)."""
    columns, t = run.columns, run.time
    series = {}
    for name in names:
        if name in columns:
            series[name] = columns[name][:, None]
        elif (vector := run.vector(name)) is not None:
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


def figures(
    record_dir, signals: list[str] | None = None, warn: Callable[[str], None] | None = None
) -> list[tuple[str, object]]:
    """(file name, matplotlib Figure) for a recording: the figures its component types declare,
    or one figure of the named ``signals``. ``warn`` (default: print to stderr) hears of a type
    that cannot be loaded (its components are not plotted).

    PlotError when the recording is missing, lacks the columns a figure needs, or has nothing
    to plot.
    """
    record_dir = Path(record_dir)
    if (record_dir / "cases.parquet").exists() and not signals:  # a campaign (orchestrator sweep --out DIR)
        from orchestrator.plots.campaigns import campaign_figures

        return campaign_figures(record_dir)
    run = load_run(record_dir)
    if signals:
        return _signals(signals, run)
    warn = warn or (lambda message: print(f"plot: {message}", file=sys.stderr, flush=True))
    written = _declared(run, warn) + shadow_figures(run.config, run.columns, run.time)
    if outcome := recorded_outcome(record_dir):  # every figure says how the run ended (a figure is shown alone)
        for _, fig in written:
            _titled(fig, outcome)
    if not written:
        types = ", ".join(sorted({(s or {}).get("type", "?") for s in (run.config.get("components") or {}).values()}))
        raise PlotError(
            f"nothing to plot in {record_dir}: no figures for its component types ({types}); "
            f"name columns to plot with --signals NAME,NAME"
        )
    return written


def recorded_outcome(record_dir: Path) -> str | None:
    """The run's outcome in words (events.jsonl's end event, orchestrator/run/outcome.py), if any."""
    import json

    try:
        lines = (Path(record_dir) / "events.jsonl").read_text().splitlines()
    except OSError:
        return None
    for line in reversed(lines):
        try:
            event = json.loads(line)
        except ValueError:  # a run killed mid-line
            continue
        if event.get("event") == "end":
            return event.get("outcome_text")
    return None


def _titled(fig, outcome: str) -> None:
    """The outcome above the figure's own title, in lines that fit its width."""
    import textwrap

    own = fig._suptitle.get_text() if fig._suptitle is not None else ""
    text = textwrap.fill(f"run outcome: {outcome}", width=max(40, int(fig.get_figwidth() * 11)))
    fig.suptitle(f"{text}\n{own}" if own else text, fontsize="medium")


def plot_recording(record_dir, out_dir, signals: list[str] | None = None) -> list[Path]:
    """Write :func:`figures` as PNGs into ``out_dir`` (created only then); return their paths."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    made = figures(record_dir, signals)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for filename, fig in made:
        assert isinstance(fig, Figure), f"{filename}: a plot draws Matplotlib figures"
        FigureCanvasAgg(fig)
        fig.savefig(out_dir / filename, dpi=110)
        paths.append(out_dir / filename)
    return paths


def plot_table() -> str:
    """The markdown rows (file | for | content) of the registered types' plots, a plot shared by
    several types on one row: the module docstring's table."""
    from components import registry

    types_of: dict[int, list[str]] = {}
    plots: dict[int, Plot] = {}
    for type_name in registry.TYPES:
        for plot in registry.load(type_name).plots:
            plots.setdefault(id(plot), plot)
            types_of.setdefault(id(plot), []).append(type_name)
    rows = []
    for key, plot in plots.items():
        file = re.sub(r"{(\w+)}", r"<\1>", plot.file)
        rows.append(f"| ``{file}`` | {', '.join(types_of[key])} | {plot.description} |")
    return "\n".join(rows)
