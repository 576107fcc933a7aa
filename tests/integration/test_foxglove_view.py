"""`orchestrator run CFG --view foxglove:PORT` with a Foxglove WebSocket protocol client (the
`websockets` package, not the Foxglove app): the advertised channels are the topics of the rosbag2
export of the same run, recorded at the same time, and every message received is, byte for byte,
that export's message of the same topic and log time. Bad input: a port in use, an unknown mode."""

from __future__ import annotations

import asyncio
import json
import re
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from tests.conftest import ROOT, needs, orchestrator

pytestmark = pytest.mark.integration

SUBPROTOCOL = "foxglove.sdk.v1"  # what foxglove-sdk 0.30 accepts (the app's newer name of foxglove.websocket.v1)
MESSAGE_DATA = 0x01
FETCH_ASSET_RESPONSE = 0x04
DEADLINE_S = 240.0  # start-up may compile numba kernels on a fresh machine


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Client:
    """Connects (retrying until the server listens), subscribes to every advertised channel and
    keeps what it receives until the server closes the connection."""

    def __init__(self, port: int, run: subprocess.Popen):
        self.port, self.run = port, run
        self.channels: dict[int, dict] = {}
        self.messages: list[tuple[str, int, bytes]] = []  # (topic, log time ns, payload)
        self.server_info: dict | None = None
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._main, daemon=True)
        self.thread.start()

    def _main(self):
        try:
            asyncio.run(self._session())
        except BaseException as e:  # reported by the test
            self.error = e

    async def _session(self):
        import websockets

        deadline = time.monotonic() + DEADLINE_S
        while True:
            try:
                # no size limit: a camera's depth image is 1.2 MB (websockets' default limit: 1 MiB)
                ws = await websockets.connect(f"ws://127.0.0.1:{self.port}", subprotocols=[SUBPROTOCOL], max_size=None)
                break
            except OSError:
                if self.run.poll() is not None or time.monotonic() > deadline:
                    raise
                await asyncio.sleep(0.02)  # poll: the server listens once the observer is up
        async with ws:
            try:
                while time.monotonic() < deadline:
                    frame = await asyncio.wait_for(ws.recv(), deadline - time.monotonic())
                    if isinstance(frame, str):
                        await self._control(ws, json.loads(frame))
                    elif frame[0] == MESSAGE_DATA:
                        subscription, log_time = struct.unpack_from("<IQ", frame, 1)
                        self.messages.append((self.channels[subscription]["topic"], log_time, bytes(frame[13:])))
            except websockets.ConnectionClosed:
                pass  # the run is over: the observer stops its server

    async def _control(self, ws, message: dict):
        if message["op"] == "serverInfo":
            self.server_info = message
        elif message["op"] == "advertise":
            for channel in message["channels"]:
                self.channels[channel["id"]] = channel  # subscription id = channel id
            await ws.send(
                json.dumps(
                    {
                        "op": "subscribe",
                        "subscriptions": [{"id": c["id"], "channelId": c["id"]} for c in message["channels"]],
                    }
                )
            )


def _bag(bag) -> dict[tuple[str, int], set[bytes]]:
    """{(topic, log time): payloads} and {topic: schema name} of the export, read with `mcap`."""
    from mcap.reader import make_reader

    (path,) = bag.glob("*.mcap")
    messages: dict[tuple[str, int], set[bytes]] = {}
    schemas: dict[str, str] = {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            messages.setdefault((channel.topic, message.log_time), set()).add(bytes(message.data))
            schemas[channel.topic] = schema.name
    return messages, schemas


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    """The demo, 2 s, recorded and served to a client; then the recording exported."""
    record = tmp_path_factory.mktemp("foxglove") / "rec"
    port = _free_port()
    run = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "orchestrator.cli",
            "run",
            str(ROOT / "configs/humanoid_tracking.yaml"),
            "--set",
            "run.duration=2 s",
            "--record",
            str(record),
            "--view",
            f"foxglove:{port}",
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        client = Client(port, run)
        _out, err = run.communicate(timeout=DEADLINE_S)
        client.thread.join(timeout=30)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
    assert run.returncode == 0, err
    assert not client.thread.is_alive(), "the server did not close the connection at the end of the run"
    assert client.error is None, repr(client.error)
    bag = record.parent / "bag"
    exported = orchestrator("export", record, "--rosbag2", bag)
    assert exported.returncode == 0, exported.stderr
    return client, _bag(bag), err


def test_channels_are_the_exports_topics(live):
    client, (_, schemas), _ = live
    advertised = {c["topic"]: c for c in client.channels.values()}
    assert {topic: c["schemaName"] for topic, c in advertised.items()} == schemas
    assert {"/clock", "/tf", "/dynamics/humanoid/joint_states", "/dynamics/humanoid/robot_description"} <= set(schemas)
    assert all(c["encoding"] == "cdr" and c["schemaEncoding"] == "ros2msg" for c in advertised.values())
    assert advertised["/dynamics/humanoid/joint_states"]["schema"].startswith("std_msgs/Header header\nstring[] name")


def test_messages_equal_the_exports(live):
    client, (bag, schemas), _ = live
    received = {topic for topic, _, _ in client.messages}
    assert received == set(schemas), "every topic, the latched robot_description included, reached the client"
    for topic, log_time, payload in client.messages:
        assert payload in bag.get((topic, log_time), set()), f"{topic} at {log_time}: not the export's message"
    clock_stamps = sorted(t for topic, t, _ in client.messages if topic == "/clock")
    assert len(clock_stamps) == len(set(clock_stamps)) > 1  # decimated rows, in order, none twice


def test_port_in_use_is_refused_before_the_run():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = orchestrator(
            "run", ROOT / "configs/humanoid_tracking.yaml", "--set", "run.duration=0.01 s", "--view", f"foxglove:{port}"
        )
    assert result.returncode == 2
    assert f"port {port}" in result.stderr and "in use" in result.stderr


@pytest.mark.parametrize("view, expected", [("foxgloves", "foxglove"), ("foxglove:abc", "port number")])
def test_bad_view(view, expected):
    result = orchestrator("run", ROOT / "configs/humanoid_tracking.yaml", "--view", view)
    assert result.returncode == 2
    assert expected in result.stderr


@needs("robots", "the Panda of example-robot-data")
def test_meshes_are_served_to_the_3d_panel():
    """Foxglove's fetchAsset for the Panda's meshes (package:// URIs as its robot_description names
    them) answers the file's bytes, found independently in the installed example-robot-data; any
    other file is refused."""
    from importlib.metadata import distribution

    import foxglove
    import numpy as np
    import yaml
    from rosbags.typesys import Stores, get_typestore

    from components.plotting import RecordedRun
    from components.ros_topics import run_topics
    from components.rosbag import RosContext
    from components.viewer.foxglove_observer import DISTRO, RosChannels, serve

    config = yaml.safe_load((ROOT / "configs/panda_on_bus.yaml").read_text())
    channels = RosChannels(["time"], config, str(ROOT / "configs"), foxglove.Context())
    channels.build(np.zeros(1), np.zeros((1, 1)))
    context = RosContext(
        RecordedRun(config, {}, np.zeros(1), str(ROOT / "configs")), get_typestore(Stores(DISTRO)), print
    )
    (description,) = [t for t in run_topics(context, lambda _: None) if t.name.endswith("robot_description")]
    uris = set(re.findall(r'filename="([^"]+)"', description.messages[0][1].data))
    assert uris and all(u.startswith("package://example-robot-data/") for u in uris)
    share = Path(distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data"))
    uri = "package://example-robot-data/robots/panda_description/meshes/visual/link3.dae"
    assert uri in uris
    expected = (share / "robots/panda_description/meshes/visual/link3.dae").read_bytes()

    server = serve(channels, name="assets", port=0)
    try:
        answers = asyncio.run(_fetch(server.port, [uri, "file:///etc/passwd", "/etc/passwd"]))
    finally:
        server.stop()
    assert answers[0] == (0, expected)
    assert answers[1][0] == answers[2][0] == 1 and not answers[1][1] and not answers[2][1]


async def _fetch(port: int, uris: list[str]) -> list[tuple[int, bytes]]:
    """fetchAsset each URI; (status: 0 found, 1 not, data) in the order asked."""
    import websockets

    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL], max_size=None) as ws:
        for request, uri in enumerate(uris):
            await ws.send(json.dumps({"op": "fetchAsset", "uri": uri, "requestId": request}))
        answers = {}
        while len(answers) < len(uris):
            frame = await asyncio.wait_for(ws.recv(), 30)
            if isinstance(frame, bytes) and frame[0] == FETCH_ASSET_RESPONSE:
                request, status, length = struct.unpack_from("<IBI", frame, 1)
                answers[request] = (status, bytes(frame[10 + length :]))
    return [answers[i] for i in range(len(uris))]
