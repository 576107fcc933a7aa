"""Component types bring their plots and views: a user's type plots itself with no edit of
orchestrator/, and the capture controller and the sensors plot (and view) what they recorded.
Checked by what the figures show (their lines' data against the recorded columns)."""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from orchestrator.plots.recording import figures
from tests.conftest import ROOT, needs, orchestrator

pytestmark = pytest.mark.integration

PHASE_PORTRAIT = '''
"""The README's oscillator, plotting its own phase portrait."""
from components.examples.oscillator import Oscillator
from components.plotting import Plot, new_figure


def phase_portrait(run, c):
    x, v = run.variable(f"{c}.x"), run.variable(f"{c}.v")
    if x is None or v is None:
        return {}
    fig = new_figure(5.0, 5.0)
    ax = fig.add_subplot()
    ax.plot(x[:, 0], v[:, 0], label="state")
    ax.set(xlabel="x (m)", ylabel="v (m/s)", title=f"{c}: phase portrait")
    return {f"{c}_phase.png": fig}


class PlottedOscillator(Oscillator):
    plots = (Plot("{c}_phase.png", "velocity against position", phase_portrait),)
'''


def _columns(record):
    table = pq.read_table(record / "signals.parquet")
    return {name: table.column(name).to_numpy() for name in table.column_names}


def _line(fig, title_part: str, label: str):
    ax = next(a for a in fig.axes if title_part in a.get_title() + a.get_title("left"))
    line = next(ln for ln in ax.get_lines() if ln.get_label() == label)
    return np.asarray(line.get_xdata(), dtype=float), np.asarray(line.get_ydata(), dtype=float)


def test_a_users_own_type_plots_itself(tmp_path):
    (tmp_path / "phase.py").write_text(PHASE_PORTRAIT)
    config = yaml.safe_load((ROOT / "configs" / "user_component.yaml").read_text())
    config["components"]["spring"]["type"] = "phase.py:PlottedOscillator"
    config["run"]["duration"] = "0.5 s"
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
    record = tmp_path / "rec"
    run = orchestrator("run", tmp_path / "config.yaml", "--record", record)
    assert run.returncode == 0, run.stderr
    result = orchestrator("plot", record)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["wrote", str(record / "plots" / "spring_phase.png")]
    x, v = _line(dict(figures(record))["spring_phase.png"], "phase portrait", "state")
    columns = _columns(record)
    assert np.array_equal(x, columns["spring.x"]) and np.array_equal(v, columns["spring.v"])


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """configs/capture_tumbling_target.yaml, its first 6 s (approach, closing, capture), recorded."""
    record = tmp_path_factory.mktemp("capture") / "rec"
    result = orchestrator(
        "run",
        ROOT / "configs" / "capture_tumbling_target.yaml",
        "--set",
        "run.duration=6 s",
        "--record",
        record,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    return record


def test_the_capture_controller_and_the_sensors_plot_what_they_recorded(capture):
    result = orchestrator("plot", capture)
    assert result.returncode == 0, result.stderr
    for name in ("controller_phases", "controller_torque", "imu_measured", "wrist_ft_measured", "pose_sensor_measured"):
        assert str(capture / "plots" / f"{name}.png") in result.stdout.split()
    made, columns = dict(figures(capture)), _columns(capture)
    phases = made["controller_phases.png"]
    t, phase = _line(phases, "phase", "phase")
    assert np.array_equal(t, columns["time"]) and np.array_equal(phase, columns["controller.phase"])
    assert {0.0, 1.0, 2.0, 5.0} <= set(phase)  # waited, approached, closed, captured
    assert np.array_equal(_line(phases, "distance", "grasp_distance")[1], columns["controller.grasp_distance"])
    assert np.allclose(
        _line(phases, "velocity error", "close_errors[2]")[1],
        1e3 * columns["controller.close_errors[2]"],
        rtol=1e-15,
        atol=0,
    )  # m/s drawn in mm/s
    # each measurement against the true value feeding the sensor (the connection's source)
    imu = made["imu_measured.png"]
    for k in range(3):
        assert np.array_equal(_line(imu, "imu.rate", f"rate[{k}]")[1], columns[f"imu.rate[{k}]"])
        assert np.array_equal(_line(imu, "imu.rate", f"rate_true[{k}]")[1], columns[f"dynamics.servicer.imu_rate[{k}]"])
    wrench = made["wrist_ft_measured.png"]
    assert np.array_equal(_line(wrench, "wrench", "wrench_true[5]")[1], columns["dynamics.grasp.wrench[5]"])
    assert np.array_equal(_line(wrench, "wrench", "wrench[5]")[1], columns["wrist_ft.wrench[5]"])


@needs("view", "orchestrator view")
def test_the_sensors_view_shows_measured_beside_true(capture, tmp_path):
    from tests.integration.test_viewer import read_rrd

    rrd = tmp_path / "capture.rrd"
    result = orchestrator("view", capture, "--view", f"save:{rrd}")
    assert result.returncode == 0, result.stderr
    entities, columns = read_rrd(rrd), _columns(capture)
    for path, column in (
        ("/plots/imu/rate/measured", "imu.rate"),
        ("/plots/imu/rate/true", "dynamics.servicer.imu_rate"),
        ("/plots/wrist_ft/wrench/true", "dynamics.grasp.wrench"),
    ):
        logged = entities[path]["data"]
        at = np.searchsorted(columns["step"], logged["step"])
        n = len(logged["Scalars:scalars"][0])
        recorded = np.column_stack([columns[f"{column}[{k}]"] for k in range(n)])[at]
        assert np.array_equal(np.array(logged["Scalars:scalars"]), recorded), path
    assert "/signals/imu/rate" not in entities  # shown once, beside its true value


def test_the_plot_table_is_the_declarations():
    import orchestrator.plots.recording as recording

    assert recording.plot_table() in recording.__doc__
