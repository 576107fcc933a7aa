"""A robot as ROS packages ship it, and the slips a new user makes, through the real CLI.

The Franka Panda of example-robot-data (pip), its URDF untouched (package:// URIs, .dae visuals, a
mimic finger), on a 500 kg bus (models/ros/panda_on_bus.urdf.xacro): check, a short run, and a
saved view whose .rrd holds geometry for every visual link. Then each bad input with its exit code
and message, a live recording directory refused, Ctrl-C when SIGINT was ignored on entry, and the
summary of a stopped run.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap

import pyarrow.parquet as pq
import pytest
import yaml

from tests.conftest import ROOT, needs, orchestrator, part_files, wait_for_step, wait_until

pytestmark = pytest.mark.integration

PANDA = ROOT / "configs" / "panda_on_bus.yaml"


def panda_config(tmp_path, duration="0.3 s", **run) -> str:
    config = yaml.safe_load(PANDA.read_text())
    config["run"].update(duration=duration, **run)
    for entry in config["components"].values():
        params = entry["parameters"]
        for body in (params.get("bodies") or {}).values():
            body["urdf"] = str(ROOT / "models" / "ros" / "panda_on_bus.urdf.xacro")
        if "urdf" in params:
            params["urdf"] = str(ROOT / "models" / "ros" / "panda_on_bus.urdf.xacro")
    path = tmp_path / "panda.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


@needs("robots", "the Panda of example-robot-data")
@needs("view", "the Rerun view (save:)")
def test_panda_from_example_robot_data_checks_runs_and_is_drawn(tmp_path):
    from tests.integration.test_viewer import read_rrd

    config = panda_config(tmp_path)
    check = orchestrator("check", config, timeout=300)
    assert check.returncode == 0, check.stderr
    # no warning: the link without mass (panda_link8) is on a fixed joint, harmless
    warnings = [line for line in check.stderr.splitlines() if line.startswith("warning:")]
    assert warnings == [], warnings
    rrd = tmp_path / "panda.rrd"
    run = orchestrator("run", config, "--record", tmp_path / "rec", "--view", f"save:{rrd}", timeout=600)
    assert run.returncode == 0, run.stderr
    assert "completed: 300 steps of 300" in run.stderr.strip().splitlines()[-1]
    table = pq.read_table(tmp_path / "rec" / "signals.parquet")
    assert table.num_rows == 301
    q7, q8 = (table.column(f"dynamics.sat.q[{i}]").to_numpy() for i in (7, 8))
    assert abs(q7 - q8).max() < 1e-9  # the mimic finger follows
    error = max(abs(table.column(f"controller.ee_error[{i}]").to_numpy()).max() for i in range(3))
    assert error < 1e-4, error
    # every visual link has geometry in the .rrd: the bus box and the 11 .dae meshes as triangles
    entities = read_rrd(rrd)
    visuals = {
        path.split("/links/")[1].split("/")[0]: entry["static"]
        for path, entry in entities.items()
        if "/links/" in path and "/visual_" in path
    }
    expected = {"bus"} | {f"panda_link{i}" for i in range(8)} | {"panda_hand", "panda_leftfinger", "panda_rightfinger"}
    assert set(visuals) == expected
    for link, components in visuals.items():
        if link != "bus":
            assert any(c.endswith("triangle_indices") for c in components), (link, components)
    assert "not drawn" not in run.stderr


def bad_urdf_config(tmp_path, link: str, duration="0.01 s", step="1 ms", extra_body="") -> str:
    (tmp_path / "bad.urdf").write_text(
        textwrap.dedent(f"""\
        <robot name="bad">
          <link name="base"><inertial><mass value="10"/>
            <inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial></link>
          {link}
          <joint name="j" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
            <limit lower="-1" upper="1" effort="10" velocity="1"/></joint>
        </robot>""")
    )
    path = tmp_path / "bad.yaml"
    path.write_text(
        textwrap.dedent(f"""\
        run: {{name: bad, epoch: 2022-09-18T12:00:00Z, duration: {duration}, step: {step}}}
        components:
          dynamics:
            type: dynamics.dart
            parameters: {{bodies: {{b: {{urdf: bad.urdf, frame: lvlh{extra_body}}}}}}}
        """)
    )
    return path


GOOD_ARM = '<link name="arm"><inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1"/></inertial></link>'


@pytest.mark.parametrize(
    "link, words",
    [
        (
            '<link name="arm"><inertial><mass value="1"/><inertia ixx="1" iyy="0.1" izz="0.1"/></inertial></link>',
            "link 'arm': the inertia breaks the triangle inequality: principal moment 1 > 0.1 + 0.1 kg m^2",
        ),
        (
            '<link name="arm"><inertial><mass value="1"/><inertia ixx="-0.1" iyy="0.1" izz="0.1"/></inertial></link>',
            "link 'arm': the inertia is not positive definite",
        ),
        (
            '<link name="arm"><visual><geometry><mesh filename="package://ghost_pkg/m.dae"/></geometry></visual>'
            '<inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1"/></inertial></link>',
            "link 'arm' visual mesh package://ghost_pkg/m.dae: package 'ghost_pkg' not found (looked in: run.packages",
        ),
    ],
)
def test_bad_urdf_refused_at_check(tmp_path, link, words):
    result = orchestrator("check", bad_urdf_config(tmp_path, link))
    assert result.returncode == 2, result.stderr
    assert words in result.stderr and "Traceback" not in result.stderr, result.stderr


def test_zero_mass_link_warned_at_check_and_at_run(tmp_path):
    massless = '<link name="arm"/>'
    config = bad_urdf_config(tmp_path, massless)
    words = "link 'arm' has no mass (nor anything welded to it), but joint 'j' moves it"
    check = orchestrator("check", config)
    assert (
        check.returncode == 0
        and f"warning: {config}: components.dynamics.parameters.bodies.b: bad.urdf: {words}" in check.stderr
    ), check.stderr
    run = orchestrator("run", config, "--record", tmp_path / "rec")
    assert words in run.stderr, run.stderr
    events = [json.loads(line) for line in (tmp_path / "rec" / "events.jsonl").read_text().splitlines()]
    assert any(e["event"] == "warning" and words in e["message"] for e in events)


def test_step_too_coarse_warned_with_the_figure(tmp_path):
    config = bad_urdf_config(tmp_path, GOOD_ARM, duration="2 h", step="1 h")
    check = orchestrator("check", config)
    assert check.returncode == 0, check.stderr
    assert (
        "the step is too coarse for the dynamics: the orbit's rate (mean motion at the lowest orbit), "
        "0.00124 rad/s, turns it 4.46 rad (256 deg) per step of 3600 s"
    ) in check.stderr, check.stderr
    assert "use a step of at most 80.7 s" in check.stderr


@pytest.mark.parametrize(
    "text, code, words",
    [
        (
            b"run: {name: x, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 1 ms}\n# caf\xe9\ncomponents: {}\n",
            2,
            "not UTF-8 text (byte 0xe9 at line 2); save the config as UTF-8",
        ),
        (
            b"run: {name: x, epoch: 2022-09-18T12:00:00Z, duration: 1e400 s, step: 1 ms}\n"
            b"components: {c: {type: test.constant}}\n",
            2,
            "run.duration: expected a duration of at most 100 years",
        ),
        (
            b"run: {name: x, epoch: 2022-09-18T12:00:00Z, duration: 3000 d, step: 1 us}\n"
            b"components: {c: {type: test.constant}}\n",
            2,
            "run.duration: 2.59e+14 steps of 1 us; at most 1e+12 steps",
        ),
        (
            b"run: {name: x, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 1 s}\n"
            b"components: {o: {type: orbit.kepler, parameters: {semi_major_axis: 6000 km, eccentricity: 0,"
            b" inclination: 51 deg, raan: 0, arg_perigee: 0, mean_anomaly: 0}}}\n",
            2,
            "a is measured from Earth's centre, not its surface: for an altitude of 6000 km, a = '12378.1 km'",
        ),
        (
            b"run: {name: x, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 1 s, packages: {mine: ./nowhere}}\n"
            b"components: {c: {type: test.constant}}\n",
            2,
            "run.packages.mine: directory './nowhere' not found",
        ),
    ],
)
def test_bad_config_exit_code_and_message(tmp_path, text, code, words):
    path = tmp_path / "c.yaml"
    path.write_bytes(text)
    for command in ("check", "run"):
        result = orchestrator(command, path)
        assert result.returncode == code, result.stderr
        assert words in result.stderr and "Traceback" not in result.stderr, result.stderr


LONG = """\
run: {name: NAME, epoch: 2022-09-18T12:00:00Z, duration: 600 s, step: 10 ms, realtime: 1.0}
components:
  src: {type: test.counter}
  int: {type: test.integrator}
connections: {int.u: src.n}
"""


def test_overwrite_against_a_live_run_is_refused_and_the_live_run_keeps_every_row(tmp_path):
    config = tmp_path / "live.yaml"
    config.write_text(LONG.replace("NAME", "livelock").replace("duration: 600 s", "duration: 3 s"))
    record = tmp_path / "rec"
    live = subprocess.Popen(
        [sys.executable, "-m", "orchestrator.cli", "run", str(config), "--record", str(record)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        wait_for_step("livelock", 5, run=live)
        for extra in (["--overwrite"], []):
            other = orchestrator("run", config, "--record", record, *extra, "--set", "run.realtime=0")
            assert other.returncode == 2, other.stderr
            assert f"run livelock (pid {live.pid}, started " in other.stderr, other.stderr
            assert "is recording into this directory now" in other.stderr and "--overwrite" not in other.stderr
        _, err = live.communicate(timeout=300)
    finally:
        if live.poll() is None:
            live.kill()
            live.wait()
    assert live.returncode == 0, err
    assert "completed: 300 steps of 300" in err
    assert pq.read_table(record / "signals.parquet").column("step").to_pylist() == list(range(301))
    events = [json.loads(line)["event"] for line in (record / "events.jsonl").read_text().splitlines()]
    assert events[0] == "start" and events.count("start") == 1 and events[-1] == "end"
    again = orchestrator("run", config, "--record", record, "--overwrite", "--set", "run.realtime=0")
    assert again.returncode == 0, again.stderr  # the lock ended with its run


def test_stopped_run_summary_agrees_with_events(tmp_path):
    config = tmp_path / "stop.yaml"
    config.write_text(LONG.replace("NAME", "stopme"))
    record = tmp_path / "rec"
    live = subprocess.Popen(
        [sys.executable, "-m", "orchestrator.cli", "run", str(config), "--record", str(record)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        wait_for_step("stopme", 5, run=live)
        assert orchestrator("stop", "--run", "stopme").returncode == 0
        _, err = live.communicate(timeout=120)
    finally:
        if live.poll() is None:
            live.kill()
            live.wait()
    assert live.returncode == 0, err
    last = err.strip().splitlines()[-1]
    assert last.startswith("run stopme stopped by request: "), last
    end = json.loads((record / "events.jsonl").read_text().splitlines()[-1])
    assert end["event"] == "end" and end["status"] == "stopped by request"


def test_ctrl_c_ends_a_run_that_inherited_sigint_ignored(tmp_path):
    """A run started with `&` from a script has SIGINT ignored (POSIX); it still ends on one."""
    config = tmp_path / "bg.yaml"
    config.write_text(LONG.replace("NAME", "background"))
    record = tmp_path / "rec"

    def ignore_sigint():
        signal.signal(signal.SIGINT, signal.SIG_IGN)

    live = subprocess.Popen(
        [sys.executable, "-m", "orchestrator.cli", "run", str(config), "--record", str(record)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=ignore_sigint,
    )
    try:
        wait_for_step("background", 5, run=live)
        live.send_signal(signal.SIGINT)
        _, err = live.communicate(timeout=120)
    finally:
        if live.poll() is None:
            live.kill()
            live.wait()
    assert live.returncode == 130, err
    assert err.strip().splitlines()[-1].startswith("run background interrupted: "), err
    wait_until(lambda: part_files(record / "signals.parquet"), "the recording's parts", timeout=30)
