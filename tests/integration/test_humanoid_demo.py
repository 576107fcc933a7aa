"""The paper's demo (configs/humanoid_tracking.yaml) end to end: the real `orchestrator run
--record` (orbit.kepler + dynamics.dart + controller.computed_torque over Zenoh, Jacobi at 1 kHz),
its acceptance numbers (IAC-22 Section 5, Figs. 5-7), the fixed-base controller for comparison,
and the plots.

Two runs in parallel, once per module: the demo (15 s) and the same trajectory under the
fixed-base computed torque, cut at 8 s (the first 7 s of the 10 s move: the peak speed, most of
the base's reaction).
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest

from components.rotations import quat_to_matrix
from tests.conftest import ROOT, component_processes, orchestrator

pytestmark = pytest.mark.integration

CONFIG = ROOT / "configs" / "humanoid_tracking.yaml"
START, DURATION = 1.0, 10.0  # the move, as in the config
FIXED_UNTIL = 8.0


def load(directory) -> dict[str, np.ndarray]:
    table = pq.read_table(directory / "signals.parquet")
    return {name: table.column(name).to_numpy() for name in table.column_names}


def vector(data, name, n):
    return np.column_stack([data[f"{name}[{i}]"] for i in range(n)])


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("humanoid")
    commands = {
        "free_floating": ["run", CONFIG, "--record", base / "free_floating"],
        "fixed": [
            "run",
            CONFIG,
            "--record",
            base / "fixed",
            "--set",
            "components.controller.parameters.base_model=fixed",
            "--set",
            f"run.duration={FIXED_UNTIL:g} s",
        ],
    }
    procs = {
        name: subprocess.Popen(
            [sys.executable, "-m", "orchestrator.cli", *map(str, args)],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for name, args in commands.items()
    }
    results = {}
    for name, proc in procs.items():
        try:
            _, err = proc.communicate(timeout=300)
        finally:
            if proc.poll() is None:
                proc.kill()
        results[name] = (proc.returncode, err)
    for name, (code, err) in results.items():
        assert code == 0, f"{name}: {err}"
    for name in commands:
        start = json.loads((base / name / "events.jsonl").read_text().splitlines()[0])
        assert not component_processes(start["run_id"]), name
    return {name: load(base / name) for name in commands} | {"dir": base}


def errors(data):
    e = vector(data, "controller.ee_error", 6)
    return np.linalg.norm(e[:, :3], axis=1), np.linalg.norm(e[:, 3:], axis=1)


def test_demo_tracks_the_papers_trajectory(runs):
    data = runs["free_floating"]
    t = data["time"]
    assert t[-1] == pytest.approx(15.0) and len(t) == 15001
    position, orientation = errors(data)
    move = (t >= START) & (t <= START + DURATION)
    tau = vector(data, "controller.tau", 14)
    sigma = data["controller.sigma_min"]
    print(
        f"\nfinal error {position[-1]:.2e} m, {orientation[-1]:.2e} rad; during the move max {position[move].max():.2e} m, "
        f"{orientation[move].max():.2e} rad; overall max {position.max():.2e} m; max |tau| {np.abs(tau).max():.4f} N m; "
        f"min sigma_min(J_g) {sigma.min():.3f}"
    )
    # acceptance (the issue): < 1 mm and < 1 mrad at the end, < 5 mm while moving, |tau| <= 1 N m
    assert position[-1] < 1e-3 and orientation[-1] < 1e-3
    assert position[move].max() < 5e-3
    assert position.max() < 5e-3 and orientation.max() < 1e-2
    assert np.abs(tau).max() <= 1.0  # paper Fig. 7: within +-1 N m
    # regression: just under 10x the measured values (final 9.1e-9 m and 2.1e-8 rad; during the
    # move 5.0e-7 m and 2.4e-6 rad; max |tau| 0.035 N m), so tracking 10x worse fails
    assert position[-1] < 8e-8 and orientation[-1] < 2e-7
    assert position[move].max() < 4.5e-6 and orientation[move].max() < 2.2e-5
    assert np.abs(tau).max() < 0.3
    assert not np.any(tau[:, :7])  # the locked left arm gets nothing
    assert sigma.min() > 0.1  # away from singularities all along


def test_base_moves_by_reaction_while_the_end_effector_tracks_in_the_inertial_frame(runs):
    data = runs["free_floating"]
    base = vector(data, "dynamics.humanoid.position", 3)
    quat = vector(data, "dynamics.humanoid.orientation", 4)
    ee = vector(data, "controller.ee_position", 3)
    drift = np.linalg.norm(base[-1] - base[0])
    turn = 2 * np.degrees(np.arccos(min(1.0, abs(quat[-1] @ quat[0]))))
    print(
        f"\nbase drift {drift * 1e3:.1f} mm, base rotation {turn:.2f} deg, end effector moved "
        f"{np.linalg.norm(ee[-1] - ee[0]):.4f} m in W"
    )
    assert drift > 5e-3 and turn > 2.0  # the torso reacts (co-rotation with LVLH alone: ~1 deg)
    # the end effector ends 0.5 m along the torso's *initial* x axis, in W: tracking is inertial,
    # and not relative to the torso, which has turned
    R0, R1 = quat_to_matrix(quat[0]), quat_to_matrix(quat[-1])
    assert np.allclose(R0.T @ (ee[-1] - ee[0]), [0.5, 0.0, 0.0], atol=1e-4)
    assert not np.allclose(R1.T @ (ee[-1] - ee[0]), [0.5, 0.0, 0.0], atol=1e-3)


def test_fixed_base_controller_tracks_worse(runs):
    free, fixed = runs["free_floating"], runs["fixed"]

    def window(d):
        return (d["time"] >= START) & (d["time"] <= FIXED_UNTIL)

    p_free, o_free = (e[window(free)] for e in errors(free))
    p_fixed, o_fixed = (e[window(fixed)] for e in errors(fixed))
    print(
        f"\nmax error over [{START:g}, {FIXED_UNTIL:g}] s: free-floating {p_free.max():.2e} m, {o_free.max():.2e} rad; "
        f"fixed base {p_fixed.max():.2e} m, {o_fixed.max():.2e} rad"
    )
    assert p_fixed.max() > 3 * p_free.max()
    assert o_fixed.max() > 3 * o_free.max()


def plotted(fig, title_part: str, label: str | None = None) -> list:
    """The data of the lines (all, or the one labelled ``label``) on the axes whose title holds ``title_part``."""
    ax = next(a for a in fig.axes if any(title_part in a.get_title(loc) for loc in ("center", "left")))
    return [line for line in ax.get_lines() if label is None or line.get_label() == label]


def test_plots_of_the_recording(runs, tmp_path):
    """The plots show the recording: the lines' data read back against its columns."""
    from orchestrator.plots.recording import figures, plot_recording

    record = runs["dir"] / "free_floating"
    written = plot_recording(record, tmp_path / "plots")
    assert [p.name for p in written] == [
        "orbit_track.png",
        "dynamics_humanoid.png",
        "controller_path.png",
        "controller_error.png",
        "controller_torque.png",
        "controller_base.png",
    ]
    assert all(path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for path in written)
    made, data = dict(figures(record)), runs["free_floating"]
    t, error = data["time"], vector(data, "controller.ee_error", 6)
    # tracking error, in mm and mrad, per axis and its norm
    for title, part in (("position error", error[:, :3]), ("orientation error", error[:, 3:])):
        for i, axis in enumerate("xyz"):
            (line,) = plotted(made["controller_error.png"], title, axis)
            assert np.array_equal(line.get_xdata(), t) and np.array_equal(line.get_ydata(), part[:, i] * 1e3)
        (norm,) = plotted(made["controller_error.png"], title, "norm")
        assert np.allclose(norm.get_ydata(), np.linalg.norm(part, axis=1) * 1e3, rtol=1e-12, atol=0)
    # joint torques: one line per driven joint, each a tau column
    tau = vector(data, "controller.tau", sum(name.startswith("controller.tau[") for name in data))
    lines = plotted(made["controller_torque.png"], "joint torques")
    driven = np.flatnonzero(np.any(tau != 0.0, axis=0))
    assert len(lines) == len(driven) > 0
    for line, i in zip(lines, driven):
        assert np.array_equal(line.get_ydata(), tau[:, i]), line.get_label()
    # the path (in the base's initial frame: a rotation, so the distances are the recording's)
    (desired,), (obtained,) = (
        plotted(made["controller_path.png"], "end-effector path", label) for label in ("desired", "obtained")
    )
    p_d, p = (np.column_stack(line.get_data_3d()) for line in (desired, obtained))
    recorded_p, recorded_p_d = (
        vector(data, "controller.ee_position", 3),
        vector(data, "controller.ee_position_desired", 3),
    )
    assert np.allclose(np.linalg.norm(p - p_d, axis=1), np.linalg.norm(recorded_p - recorded_p_d, axis=1), atol=1e-12)
    assert np.allclose(p_d[0], 0.0) and np.linalg.norm(p_d[-1]) == pytest.approx(0.5, abs=1e-9)  # the 0.5 m move
    # the base's reaction: its displacement in mm
    base = vector(data, "dynamics.humanoid.position", 3)
    (x,) = plotted(made["controller_base.png"], "base displacement", "x")
    assert np.array_equal(x.get_ydata(), (base[:, 0] - base[0, 0]) * 1e3) and np.ptp(x.get_ydata()) > 0


@pytest.mark.parametrize(
    "override, key",
    [
        ("components.controller.parameters.kp=[100, 100, 100]", "components.controller.parameters.kp"),
        (
            "components.controller.parameters.end_effector=arm_right_hand",
            "components.controller.parameters.end_effector",
        ),
        (
            "components.controller.parameters.joints=[arm_right_1_joint, arm_right_9_joint]",
            "components.controller.parameters.joints",
        ),
        (
            "components.controller.parameters.trajectory.displacement=2 m",
            "components.controller.parameters.trajectory.displacement",
        ),
    ],
)
def test_bad_controller_config_is_refused_before_anything_starts(override, key):
    result = orchestrator("run", CONFIG, "--set", override, timeout=60)
    assert result.returncode == 2
    assert key in result.stderr and "Traceback" not in result.stderr
