"""`orchestrator plot` as a user runs it: figures picked by the component types, checked by what
they show (read back from the plotted lines), --signals, and a recording with nothing to plot."""

from __future__ import annotations

import math

import numpy as np
import pyarrow.parquet as pq
import pytest

from components.constants import MU_EARTH, R_EARTH
from orchestrator.plots.recording import figures
from tests.conftest import ROOT, orchestrator

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def libration(tmp_path_factory):
    """configs/gravity_gradient_libration.yaml, 3 h at 10 s, recorded."""
    record = tmp_path_factory.mktemp("libration") / "rec"
    result = orchestrator("run", ROOT / "configs" / "gravity_gradient_libration.yaml", "--record", record)
    assert result.returncode == 0, result.stderr
    return record


def _line(fig, title_part: str, label: str):
    ax = next(a for a in fig.axes if title_part in a.get_title())
    line = next(ln for ln in ax.get_lines() if ln.get_label() == label)
    return np.asarray(line.get_xdata(), dtype=float), np.asarray(line.get_ydata(), dtype=float)


def test_plot_writes_orbit_and_dynamics_figures_that_show_the_libration(libration):
    result = orchestrator("plot", libration)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == [
        "wrote",
        str(libration / "plots" / "orbit_track.png"),
        "wrote",
        str(libration / "plots" / "dynamics_target.png"),
    ]
    made = dict(figures(libration))
    # the pitch (about LVLH z) as plotted: 1 deg amplitude at w = n sqrt(3 (Iyy - Ixx) / Izz)
    t, pitch = _line(made["dynamics_target.png"], "attitude against LVLH", "about z")
    crossings = [
        t[i] - pitch[i] * (t[i + 1] - t[i]) / (pitch[i + 1] - pitch[i])
        for i in range(len(t) - 1)
        if pitch[i] * pitch[i + 1] < 0
    ]
    n = math.sqrt(MU_EARTH / 6778e3**3)
    expected = n * math.sqrt(3 * (59.33333333 - 33.33333333) / 59.33333333)
    assert math.pi / np.mean(np.diff(crossings)) == pytest.approx(expected, rel=0.01)
    assert np.abs(pitch).max() == pytest.approx(1.0, abs=0.01)
    _, roll = _line(made["dynamics_target.png"], "attitude against LVLH", "about x")
    assert np.abs(roll).max() < 1e-6
    # the orbit as plotted: a circular 6778 km orbit at 51.64 deg
    _, altitude = _line(made["orbit_track.png"], "altitude", "_child0")
    assert altitude == pytest.approx((6778e3 - R_EARTH) / 1e3, abs=1e-6)
    ax = next(a for a in made["orbit_track.png"].axes if "ground track" in a.get_title())
    assert np.nanmax(ax.get_lines()[0].get_ydata()) == pytest.approx(51.64, abs=0.05)


def test_plot_signals_plots_the_named_columns(libration, tmp_path):
    result = orchestrator(
        "plot", libration, "--out", tmp_path / "out", "--signals", "orbit.r_eci, dynamics.target.twist[5]"
    )
    assert result.returncode == 0 and result.stdout.strip() == f"wrote {tmp_path / 'out' / 'signals.png'}"
    made = dict(figures(libration, ["orbit.r_eci", "dynamics.target.twist[5]"]))
    table = pq.read_table(libration / "signals.parquet")
    _, y = _line(made["signals.png"], "orbit.r_eci", "[2]")
    assert np.array_equal(y, table.column("orbit.r_eci[2]").to_numpy())
    typo = orchestrator("plot", libration, "--out", tmp_path / "typo", "--signals", "orbit.r_ecl")
    assert typo.returncode == 2 and "no column 'orbit.r_ecl'" in typo.stderr and "orbit.r_eci" in typo.stderr
    assert not (tmp_path / "typo").exists()


def test_a_recording_with_nothing_to_plot_says_so_and_leaves_no_folder(tmp_path):
    record = tmp_path / "rec"
    run = orchestrator(
        "run", ROOT / "configs" / "user_component.yaml", "--set", "run.duration=0.1 s", "--record", record
    )
    assert run.returncode == 0, run.stderr
    result = orchestrator("plot", record)
    assert result.returncode == 2 and "nothing to plot" in result.stderr and "--signals" in result.stderr
    assert not (record / "plots").exists()
    assert orchestrator("plot", record, "--signals", "spring.x").returncode == 0
