"""The viewer.rerun observer end to end: real orchestrator, components and Zenoh; .rrd read back with Rerun.

A web-view test loads the served page in headless Chromium and takes a screenshot (skipped when no
Chromium is installed: ``apt-get install -y chromium``). Set ZENORBIT_VIEWER_SCREENSHOT=FILE.png to
keep the screenshot.
"""

from __future__ import annotations

import base64
import json
import os
import queue
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from components.extras import missing
from tests.conftest import ROOT, component_processes, orchestrator

RrdReader = pytest.importorskip("rerun.chunk", reason=missing("view", "testing the viewer")).RrdReader

pytestmark = pytest.mark.integration

FAKE_CONTROLLER = '''
"""Stand-in controller with closed-form outputs: a 0.1 m circle away from the torso, followed 0.3 s late."""
import numpy as np
from components.controller.view import ControllerView
from components.sdk import Component, Parameter, Variable


class FakeController(Component):
    type_name = "controller.fake"
    view = ControllerView          # drawn as the controllers are: paths, errors, torques
    parameters = (Parameter("joints", "int", default=14, description="number of joint torques"),)

    @classmethod
    def declare(cls, params, run):
        n = params["joints"]
        return [Variable("q", "input", (n,), "rad", 0.0, "joint positions"),
                Variable("tau", "output", (n,), "N*m", 0.0, "joint torques"),
                Variable("ee_position", "output", (3,), "m", 0.0, "end effector, W"),
                Variable("ee_position_desired", "output", (3,), "m", 0.0, "desired end effector, W"),
                Variable("ee_error", "output", (6,), "m, rad", 0.0, "position and orientation error")]

    def __init__(self, params, run):
        self.n = params["joints"]

    def outputs(self, t):
        def path(s):
            return np.array([0.45, 0.45 + 0.1 * np.cos(s), 0.3 + 0.1 * np.sin(s)])
        desired, actual = path(t), path(t - 0.3)
        return {"tau": 1e-3 * np.sin(t + np.arange(self.n)), "ee_position": actual, "ee_position_desired": desired,
                "ee_error": np.concatenate([desired - actual, 0.01 * np.sin([t, 2 * t, 3 * t])])}

    def initialize(self, t0_ns, inputs):
        return self.outputs(t0_ns * 1e-9)

    def do_step(self, t_ns, h_ns, inputs):
        return self.outputs((t_ns + h_ns) * 1e-9)

    def get_state(self):
        return {}

    def set_state(self, state):
        pass
'''


def humanoid_config(directory: Path, name: str, duration: str = "1 s") -> Path:
    """configs/free_floating_humanoid.yaml (or an orbit-only config without it) plus a stand-in controller."""
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "fake_controller.py").write_text(FAKE_CONTROLLER)
    source = ROOT / "configs" / "free_floating_humanoid.yaml"
    config = yaml.safe_load(source.read_text())
    config["run"].update(name=name, duration=duration)
    body = config["components"]["dynamics"]["parameters"]["bodies"]["humanoid"]
    body["urdf"] = str((source.parent / body["urdf"]).resolve())
    config["components"]["controller"] = {"type": "fake_controller.py:FakeController"}
    config["connections"].update({"dynamics.humanoid.tau": "controller.tau", "controller.q": "dynamics.humanoid.q"})
    path = directory / "config.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


def read_rrd(path) -> dict:
    """{entity: {"rows": temporal rows, "timelines": set, "static": set of components, "data": {component: values}}}."""
    import pyarrow as pa

    entities: dict = {}
    for chunk in RrdReader(path).stream():
        entry = entities.setdefault(chunk.entity_path, {"rows": 0, "timelines": set(), "static": set(), "data": {}})
        batch = chunk.to_record_batch()
        names = [n for n in batch.schema.names if n != "rerun.controls.RowId"]
        if chunk.is_static:
            entry["static"] |= set(names)
            continue
        entry["rows"] += chunk.num_rows
        entry["timelines"] |= set(chunk.timeline_names)
        for name in names:
            column = batch.column(name)
            if pa.types.is_duration(column.type):
                column = column.cast(pa.int64())
            entry["data"].setdefault(name, []).extend(column.to_pylist())
    return entities


def viewer_processes(tag: str) -> list[str]:
    out = subprocess.run(["ps", "-ww", "-eo", "pid=,args="], capture_output=True, text=True).stdout
    return [line for line in out.splitlines() if "components.viewer.observer" in line and tag in line]


@pytest.fixture(scope="module")
def saved_run(tmp_path_factory):
    """One 1 s humanoid run (10 ms steps) recorded and viewed into an .rrd: (recording dir, .rrd, stderr)."""
    base = tmp_path_factory.mktemp("viewer_run")
    config = humanoid_config(base, "viewer_save")
    rrd = base / "live.rrd"
    env = {**os.environ, "ZENORBIT_RUNTIME_DIR": str(base / "runtime")}
    result = orchestrator("run", config, "--record", base / "rec", "--view", f"save:{rrd}", env=env, timeout=120)
    assert result.returncode == 0, result.stderr
    return base / "rec", rrd, result.stderr


def test_saved_view_has_robot_orbit_and_plots_at_the_viewer_rate(saved_run):
    """Rows reach the viewer through a publisher that drops rather than hold up a step: on a busy
    machine (the observer runs niced) some may be lost. What arrives is at the viewer rate, every
    entity has each row that arrived, and the values are the recorded ones."""
    rec, rrd, stderr = saved_run
    data = pq.read_table(rec / "signals.parquet").to_pydict()
    steps = np.array(data["step"])
    shown = steps[steps % 3 == 0]  # 30 Hz of sim time at 10 ms steps: every 3rd step, from step 0
    assert len(shown) == 34
    entities = read_rrd(rrd)
    signal_entity = entities["/signals/orbit/v_eci"]["data"]
    logged = signal_entity["step"]  # the rows that reached the viewer
    assert 0 < len(logged) <= len(shown) and set(logged) <= set(shown) and logged == sorted(set(logged)), logged
    at = np.isin(steps, logged)
    from components.viewer.robot import read_geometry

    links = read_geometry(ROOT / "models" / "humanoid_torso.urdf").links
    expected = [f"/world/dynamics/humanoid/links/{link}" for link in links] + [
        "/world/dynamics/humanoid/com",
        "/world/dynamics/humanoid/gg_torque",
        "/world/dynamics/humanoid/tidal_force",
        "/world/controller/ee_desired",
        "/world/controller/ee_actual",
        "/world/lvlh",
        "/plots/controller/ee_position/desired",
        "/plots/controller/ee_position/actual",
        "/plots/controller/ee_error/position",
        "/plots/controller/ee_error/orientation",
        "/plots/controller/tau",
        "/plots/dynamics/humanoid/momentum/linear",
        "/plots/dynamics/humanoid/momentum/angular",
        "/plots/dynamics/humanoid/gg_torque_norm",
        "/orbit/orbit/trail",
        "/orbit/orbit/spacecraft",
        "/signals/orbit/v_eci",
        "/signals/dynamics/humanoid.q",
        "/signals/dynamics/humanoid.twist",
    ]
    for path in expected:
        assert path in entities, f"{path} missing; entities: {sorted(entities)}"
        assert entities[path]["rows"] == len(logged), path
        assert entities[path]["timelines"] == {"sim_time", "step"}, path
    for path in ("/orbit/earth", "/orbit/orbit/spacecraft/lvlh", "/notes"):
        assert entities[path]["static"], path
    # the rows are the recorded ones: same steps, same times, same values
    assert signal_entity["sim_time"] == [int(k) * 10_000_000 for k in logged]
    v = np.column_stack([np.array(data[f"orbit.v_eci[{i}]"])[at] for i in range(3)])
    assert np.array_equal(np.array(signal_entity["Scalars:scalars"]), v)
    desired = np.column_stack([np.array(data[f"controller.ee_position_desired[{i}]"])[at] for i in range(3)])
    points = np.array([p[0] for p in entities["/world/controller/ee_desired"]["data"]["Points3D:positions"]])
    assert np.allclose(points, desired, atol=1e-6)
    assert RrdReader(rrd).blueprints(), "the layout is saved with the data"
    assert f"saved {len(logged)} rows" in stderr
    assert not component_processes("viewer_save") and not viewer_processes("viewer_save")


def test_replay_of_the_recording_shows_what_the_live_view_showed(saved_run, tmp_path):
    rec, live, _ = saved_run
    replayed = tmp_path / "replay.rrd"
    result = orchestrator("view", rec, "--view", f"save:{replayed}", timeout=60)
    assert result.returncode == 0, result.stderr
    live_rows = {path: e["rows"] for path, e in read_rrd(live).items() if e["rows"]}
    replay_rows = {path: e["rows"] for path, e in read_rrd(replayed).items() if e["rows"]}
    # the same entities; the replay reads the recording, so it has every row at the viewer rate
    # (34 of the 101 steps), the live view those the publisher did not drop
    assert set(replay_rows) == set(live_rows)
    assert set(replay_rows.values()) == {34}, replay_rows
    assert all(live_rows[path] <= 34 for path in live_rows), live_rows
    assert orchestrator("view", tmp_path / "nothing_here").returncode == 2
    assert orchestrator("view", rec, "--view", "save:no_suffix").returncode == 2


def test_observer_follows_the_bus_contract(tmp_path):
    """Without the orchestrator: rows and END on `signals`, the `_viewer` token, exit when told."""
    import zenoh

    from components import bus

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    endpoint = f"tcp/127.0.0.1:{port}"
    run_id = f"contract-{os.getpid()}"
    columns = ["a.x[0]", "a.x[1]", "b.n"]
    rrd = tmp_path / "contract.rrd"
    setup = tmp_path / "viewer.json"
    setup.write_text(
        json.dumps(
            {
                "columns": columns,
                "config": {"components": {"a": {"type": "test.constant"}}},
                "step_ns": 1_000_000,
                "config_dir": str(tmp_path),
                "epoch": "2022-09-18T12:00:00Z",
                "mode": "save",
                "file": str(rrd),
                "open_browser": False,
            }
        )
    )
    session = zenoh.open(bus.session_config(listen=[endpoint]))
    seen: queue.Queue = queue.Queue()
    watch = session.liveliness().declare_subscriber(
        bus.run_key(run_id, "alive", "_viewer", "0"), lambda sample: seen.put(sample.kind)
    )
    token = session.liveliness().declare_token(bus.run_key(run_id, "alive", "orchestrator"))
    out = bus.publisher(session, bus.run_key(run_id, "signals"), drop=True)
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "components.viewer.observer",
            "--connect",
            endpoint,
            "--run-id",
            run_id,
            "--setup",
            str(setup),
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        assert seen.get(timeout=30) == zenoh.SampleKind.PUT
        header = bus.SIGNALS_HEADER
        for k in range(50):
            out.put(header.pack(k, k * 1e-3) + np.array([k, -k, 0.5 * k], dtype=np.float64).tobytes())
        out.put(b"junk")  # a malformed row is counted, not fatal
        out.put(b"END")
        assert process.wait(timeout=30) == 0
        assert seen.get(timeout=30) == zenoh.SampleKind.DELETE
    finally:
        if process.poll() is None:
            process.kill()
        del token, watch
        session.close()
    log = process.stdout.read()
    assert "saved 50 rows" in log and "ignored 1 signal rows" in log, log
    entities = read_rrd(rrd)
    assert entities["/signals/a/x"]["rows"] == 50 and entities["/signals/b/n"]["rows"] == 50
    assert entities["/signals/a/x"]["data"]["Scalars:scalars"][7] == [7.0, -7.0]


def test_observer_exits_when_the_orchestrator_goes_away(tmp_path):
    import zenoh

    from components import bus

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    endpoint = f"tcp/127.0.0.1:{port}"
    run_id = f"orphan-{os.getpid()}"
    setup = tmp_path / "viewer.json"
    setup.write_text(json.dumps({"columns": ["a.y"], "config": {}, "mode": "save", "file": str(tmp_path / "o.rrd")}))
    session = zenoh.open(bus.session_config(listen=[endpoint]))
    seen: queue.Queue = queue.Queue()
    watch = session.liveliness().declare_subscriber(
        bus.run_key(run_id, "alive", "_viewer", "0"), lambda sample: seen.put(sample.kind)
    )
    token = session.liveliness().declare_token(bus.run_key(run_id, "alive", "orchestrator"))
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "components.viewer.observer",
            "--connect",
            endpoint,
            "--run-id",
            run_id,
            "--setup",
            str(setup),
        ],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        assert seen.get(timeout=30) == zenoh.SampleKind.PUT
        token.undeclare()
        assert process.wait(timeout=60) == 0
    finally:
        if process.poll() is None:
            process.kill()
        del watch
        session.close()


def test_spawn_mode_streams_to_a_listening_desktop_viewer(tmp_path):
    """spawn connects to a viewer already listening on its port; here a headless `rerun --save` stands in."""
    rerun_exe = shutil.which("rerun")
    if rerun_exe is None:
        pytest.skip("the `rerun` executable (rerun-sdk) is not on PATH")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    config_home = tmp_path / "xdg"  # the stand-in viewer with analytics off, user config untouched
    (config_home / "rerun").mkdir(parents=True)
    (config_home / "rerun" / "analytics.json").write_text(
        json.dumps(
            {
                "analytics_enabled": False,
                "analytics_id": "test",
                "metadata": {},
                "config_file_path": str(config_home / "rerun" / "analytics.json"),
                "data_dir_path": str(tmp_path / "data"),
            }
        )
    )
    received = tmp_path / "received.rrd"
    listener = subprocess.Popen(
        [rerun_exe, "--port", str(port), "--save", str(received)],
        env={**os.environ, "XDG_CONFIG_HOME": str(config_home)},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 30
        while True:
            with socket.socket() as probe:
                if probe.connect_ex(("127.0.0.1", port)) == 0:
                    break
            assert time.monotonic() < deadline and listener.poll() is None, "the stand-in viewer did not start"
            time.sleep(0.1)
        config = humanoid_config(tmp_path, "viewer_spawn")
        env = {
            **os.environ,
            "ZENORBIT_RUNTIME_DIR": str(tmp_path / "runtime"),
            "ZENORBIT_RERUN_SPAWN_PORT": str(port),
            "DISPLAY": os.environ.get("DISPLAY") or ":0",
        }
        result = orchestrator("run", config, "--view", "spawn", env=env, timeout=120)
        assert result.returncode == 0, result.stderr
    finally:
        listener.send_signal(signal.SIGINT)
        try:
            listener.wait(timeout=20)
        except subprocess.TimeoutExpired:
            listener.kill()
            listener.wait()
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a streamed .rrd has no footer
        entities = read_rrd(received)
    # streamed through the publisher that drops rather than waits: the rows that arrived, at the
    # viewer rate (every 3rd of the 101 steps: 34 at most), in both entities
    torso = entities["/world/dynamics/humanoid/links/torso"]
    streamed = torso["data"]["step"]
    assert 0 < len(streamed) <= 34 and all(k % 3 == 0 for k in streamed) and streamed == sorted(set(streamed)), streamed
    assert torso["rows"] == entities["/plots/controller/tau"]["rows"] == len(streamed)
    assert entities["/plots/controller/tau"]["data"]["step"] == streamed
    assert not viewer_processes("viewer_spawn")


def test_spawn_without_a_display_is_refused_before_the_run(tmp_path):
    config = humanoid_config(tmp_path, "viewer_nodisplay")
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    if not sys.platform.startswith("linux"):
        pytest.skip("the display check is Linux-only")
    # the refusal comes after the CLI's imports (the humanoid's dynamics), which a loaded machine
    # slows past a minute: the conftest's generous bound, only there to end a hang
    result = orchestrator("run", config, "--view", "spawn", env=env)
    assert result.returncode == 2 and "no display" in result.stderr, result.stderr
    assert not component_processes("viewer_nodisplay-")  # refused before the run: nothing started
    replay = orchestrator("view", tmp_path, "--view", "spawn", env=env)
    assert replay.returncode == 2 and "no display" in replay.stderr, replay.stderr


# ------------------------------------------------------------------------------------------ web view


def chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        found = shutil.which(name)
        if found:
            return found
    return None


CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--enable-unsafe-swiftshader",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def screenshot(url: str, png: Path, *, settle_s: float = 3.0, timeout_s: float = 60.0, size=(1280, 800)) -> list[str]:
    """Load ``url`` in headless Chromium, wait for the Rerun app to start and its picture to settle
    (two equal frames ``settle_s`` apart), save a PNG.

    Chromium's own --screenshot/--virtual-time-budget fires before the WebAssembly viewer has
    compiled, so this drives Chromium over the DevTools protocol on a pipe (--remote-debugging-pipe:
    NUL-terminated JSON on fds 3 and 4), with no extra Python package. Returns the console lines."""
    to_browser_r, to_browser_w = os.pipe()
    from_browser_r, from_browser_w = os.pipe()

    def child_fds():
        os.dup2(to_browser_r, 3)
        os.dup2(from_browser_w, 4)

    profile = tempfile.mkdtemp(prefix="zenorbit-chromium-")
    process = subprocess.Popen(
        [
            chromium(),
            *CHROMIUM_FLAGS,
            f"--user-data-dir={profile}",
            f"--window-size={size[0]},{size[1]}",
            "--remote-debugging-pipe",
            "about:blank",
        ],
        pass_fds=(3, 4),
        preexec_fn=child_fds,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    os.close(to_browser_r)
    os.close(from_browser_w)
    inbox: queue.Queue = queue.Queue()
    console: list[str] = []

    def read():
        pending = b""
        with os.fdopen(from_browser_r, "rb", buffering=0) as stream:
            while chunk := stream.read(1 << 16):
                pending += chunk
                while b"\0" in pending:
                    message, pending = pending.split(b"\0", 1)
                    inbox.put(json.loads(message))

    threading.Thread(target=read, daemon=True).start()
    writer = os.fdopen(to_browser_w, "wb", buffering=0)
    ids = iter(range(1, 1 << 30))

    def pump(until: float, want_id: int | None = None):
        while True:
            remaining = until - time.monotonic()
            if remaining <= 0:
                if want_id is not None:
                    raise TimeoutError(f"Chromium did not answer request {want_id}")
                return None
            try:
                message = inbox.get(timeout=min(remaining, 0.5))
            except queue.Empty:
                continue
            if message.get("method") == "Runtime.consoleAPICalled":
                console.append(" ".join(str(a.get("value", "")) for a in message["params"]["args"]))
            if want_id is not None and message.get("id") == want_id:
                if "error" in message:
                    raise RuntimeError(f"Chromium: {message['error']}")
                return message["result"]

    def call(method, params=None, session=None, timeout=30.0):
        request_id = next(ids)
        message = {"id": request_id, "method": method, "params": params or {}}
        if session:
            message["sessionId"] = session
        writer.write(json.dumps(message).encode() + b"\0")
        return pump(time.monotonic() + timeout, request_id)

    try:
        page = next(t for t in call("Target.getTargets")["targetInfos"] if t["type"] == "page")
        session = call("Target.attachToTarget", {"targetId": page["targetId"], "flatten": True})["sessionId"]
        call("Runtime.enable", session=session)
        call(
            "Emulation.setDeviceMetricsOverride",
            {"width": size[0], "height": size[1], "deviceScaleFactor": 1, "mobile": False},
            session=session,
        )
        call("Page.navigate", {"url": url}, session=session)
        deadline = time.monotonic() + timeout_s
        while not any("App started" in line for line in console) and time.monotonic() < deadline:
            pump(min(deadline, time.monotonic() + 0.5))
        # the viewer then streams the data in (slowly, on a software rasterizer): wait for two equal frames
        previous = None
        while time.monotonic() < deadline:
            pump(min(deadline, time.monotonic() + settle_s))
            data = call("Page.captureScreenshot", {"format": "png"}, session=session)["data"]
            if data == previous:
                break
            previous = data
        png.write_bytes(base64.b64decode(data))
        try:
            call("Browser.close", timeout=5)
        except Exception:
            pass
    finally:
        writer.close()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        shutil.rmtree(profile, ignore_errors=True)
    return console


def test_web_view_renders_in_headless_chromium(tmp_path):
    if chromium() is None:
        pytest.skip("headless Chromium not found (Debian: apt-get install -y chromium); web view screenshot not taken")
    from PIL import Image

    config = humanoid_config(tmp_path, "viewer_web", duration="3 s")
    log = tmp_path / "orchestrator.log"
    env = {**os.environ, "ZENORBIT_RUNTIME_DIR": str(tmp_path / "runtime")}
    # stdin a terminal: the orchestrator then keeps the web view up after the run until it is stopped
    # (without one it stops the viewer 30 s after the run, which a slow machine may need for the page)
    terminal, terminal_child = os.openpty()
    with open(log, "w") as stderr:
        run = subprocess.Popen(
            [sys.executable, "-m", "orchestrator.cli", "run", str(config), "--view", "web"],
            cwd=ROOT,
            env=env,
            stdin=terminal_child,
            stdout=stderr,
            stderr=stderr,
            text=True,
        )
    os.close(terminal_child)
    try:
        deadline = time.monotonic() + 90
        while "run over" not in log.read_text():
            assert run.poll() is None, log.read_text()
            assert time.monotonic() < deadline, log.read_text()
            time.sleep(0.2)
        url = next(w for w in log.read_text().split() if w.startswith("http://127.0.0.1:"))
        png = tmp_path / "web_view.png"
        console = screenshot(url, png)
        assert any("App started" in line for line in console), console[-20:]
        image = Image.open(png).convert("RGB")
        assert image.size == (1280, 800)
        pixels = np.asarray(image).reshape(-1, 3)
        assert pixels.std() > 20 and len(np.unique(pixels, axis=0)) > 500, "the page looks blank"
        assert not any("Data source failed" in line for line in console), [line for line in console if "rror" in line]
        keep = os.environ.get("ZENORBIT_VIEWER_SCREENSHOT")
        if keep:
            shutil.copy(png, keep)
    finally:
        if run.poll() is None:
            run.send_signal(signal.SIGTERM)  # the web view serves until the run is stopped
        run.wait(timeout=60)
        os.close(terminal)
    assert not component_processes("viewer_web") and not viewer_processes("viewer_web")
