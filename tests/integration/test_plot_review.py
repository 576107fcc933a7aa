"""Plots a reviewer accepts (issue 44): one quantity per axis with its unit, no title or label
outside the figure, the momentum panels naming what changes momentum, the run's outcome above
every figure; campaign plots leave out seeds and constants. The recording is a real short run of
the shipped capture (captured at ~3.7 s)."""

from __future__ import annotations

import json
import re

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from orchestrator.plots.recording import figures
from tests.conftest import ROOT, component_processes, orchestrator

pytestmark = pytest.mark.integration

UNIT = re.compile(r"\(([^()]*)\)\s*$")  # a label's trailing "(unit)"


@pytest.fixture(scope="module")
def capture_figures(tmp_path_factory):
    record = tmp_path_factory.mktemp("plots") / "capture"
    run = orchestrator(
        "run", ROOT / "configs" / "capture_tumbling_target.yaml", "--set", "run.duration=4.5 s", "--record", record
    )
    assert run.returncode == 0, run.stderr
    assert component_processes() == []
    return dict(figures(record))


def texts_outside(fig) -> list[str]:
    """Titles, suptitle and axis labels whose drawn box leaves the figure (clipped in the PNG)."""
    FigureCanvasAgg(fig)
    renderer = fig.canvas.get_renderer()
    fig.draw_without_rendering()
    box = fig.bbox
    found = []
    texts = [fig._suptitle] if fig._suptitle is not None else []
    for ax in fig.axes:
        texts += [ax.title, ax._left_title, ax._right_title, ax.xaxis.label, ax.yaxis.label]
    for text in texts:
        if not text.get_text() or not text.get_visible():
            continue
        extent = text.get_window_extent(renderer)
        if extent.x0 < box.x0 - 1 or extent.x1 > box.x1 + 1 or extent.y0 < box.y0 - 1 or extent.y1 > box.y1 + 1:
            found.append(text.get_text())
    return found


def units_of(ax) -> set[str]:
    """The units an axes' data are in: its y label's and every labelled line's trailing (unit)."""
    labels = [ax.get_ylabel()] + [line.get_label() for line in ax.get_lines() if not line.get_label().startswith("_")]
    found = set()
    for label in labels:
        m = UNIT.search(label)
        if m:
            found.add(m.group(1))
        elif label == ax.get_ylabel() and label:
            found.add(label)  # a y label that is the unit itself ("mm/s")
    return found


@pytest.mark.parametrize("name", ["controller_phases.png", "dynamics_capture.png"])
def test_the_capture_figures_put_one_quantity_with_its_unit_on_each_axis(capture_figures, name):
    fig = capture_figures[name]
    for ax in fig.axes:
        curves = [line for line in ax.get_lines() if len(line.get_xdata()) > 2]  # data, not a marker line
        if not curves:
            continue
        assert ax.get_ylabel(), f"{name}: '{ax.get_title(loc='left') or ax.get_title()}' has no unit on its axis"
        assert len(units_of(ax)) == 1, f"{name}: '{ax.get_title(loc='left') or ax.get_title()}' mixes {units_of(ax)}"


def test_no_title_or_label_of_a_capture_run_is_cut_off(capture_figures):
    outside = {name: texts_outside(fig) for name, fig in capture_figures.items()}
    assert not any(outside.values()), outside


def test_the_momentum_panels_name_what_changes_momentum_and_every_figure_the_outcome(capture_figures):
    fig = capture_figures["dynamics_capture.png"]
    momentum = [ax.get_title() for ax in fig.axes if "momentum" in ax.get_title()]
    assert len(momentum) == 2 and all("tidal force" in t and "gravity gradient" in t for t in momentum), momentum
    for name, fig in capture_figures.items():
        assert re.match(r"run outcome: captured at \d+(\.\d+)? s", fig._suptitle.get_text()), name


def test_the_phase_axis_keeps_every_phase_off_its_border(capture_figures):
    ax = next(a for a in capture_figures["controller_phases.png"].axes if a.get_ylabel() == "phase")
    low, high = ax.get_ylim()
    assert low < 0 and high > 6  # 0 wait ... 6 aborted all inside
    assert [t.get_text() for t in ax.get_yticklabels()][-1] == "6 aborted"


def test_campaign_plots_leave_out_seeds_and_constants(tmp_path):
    """A campaign of a dispersed rate, a sensor seed and a one-value grid: the metric is drawn
    against the rate alone; the figure says the others were left out and why."""
    cases = 8
    rates = [0.5 + 0.4 * k for k in range(cases)]
    pq.write_table(
        pa.table(
            {
                "case": list(range(cases)),
                "status": ["completed"] * cases,
                "outcome": ["captured", "aborted", "undecided", "captured"] * 2,
                "error": [""] * cases,
                "run.duration": [30.0] * cases,
                "components.dynamics.parameters.bodies.target.twist.rate": rates,
                "components.pose_sensor.parameters.seed": [101.0 + k % 3 for k in range(cases)],
                "components.imu.parameters.noise_seed": [201.0 + k % 2 for k in range(cases)],
                "peak_force": [1.0 + r for r in rates],
            }
        ),
        tmp_path / "cases.parquet",
    )
    (tmp_path / "campaign.json").write_text(
        json.dumps(
            {
                "metrics": {"peak_force": {"unit": "N"}},
                "dispersed": [
                    "components.dynamics.parameters.bodies.target.twist.rate",
                    "components.pose_sensor.parameters.seed",
                    "components.imu.parameters.noise_seed",
                ],
                "grid": ["run.duration"],
                "units": {"components.dynamics.parameters.bodies.target.twist.rate": "deg/s"},
                "grid_values": {"run.duration": ["30 s"]},
            }
        )
    )
    made = dict(figures(tmp_path))
    for name in ("peak_force_vs_parameters.png", "outcomes.png"):
        fig = made[name]
        drawn = [ax.get_xlabel() for ax in fig.axes if ax.get_lines() or ax.collections]
        assert drawn == ["twist.rate (deg/s)"], (name, drawn)
        note = fig._suptitle.get_text().replace("\n", " ")
        for left_out in (
            "pose_sensor.parameters.seed (a seed)",
            "imu.parameters.noise_seed (a seed)",
            "run.duration (one value)",
        ):
            assert left_out in note, (name, note)
        assert not texts_outside(fig), (name, texts_outside(fig))
