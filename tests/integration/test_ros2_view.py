"""`orchestrator run CFG --ros2 ENDPOINT` against a stand-in for the ROS side: a plain Zenoh router
on loopback (what rmw_zenohd is) and, in this test, a peer session that listens the way rmw_zenoh's
graph cache and subscriptions do (rmw_zenoh_cpp/src/detail: graph_cache.cpp's liveliness
subscriber on ``@ros2_lv/**``, liveliness_utils.cpp's token grammar, rmw_subscription_data.cpp's
subscriber on the data key, attachment_helpers.cpp's attachment). Everything checked here is
decoded by code of this file, from rmw_zenoh's facts, not by components.ros2.rmw_zenoh:

- tokens parse (node, one MP per topic, QoS TRANSIENT_LOCAL depth 1 on latched topics) and every
  data key is ``<domain>/<topic>/<DDS type>/<RIHS01 hash>`` with the hashes published for ROS 2;
- every sample has a 33-byte attachment, sequence numbers 1, 2, ... per publisher, and the GID a
  graph cache computes from the publisher's token (XXH3-128);
- the CDR payloads, decoded by mcap-ros2-support (not rosbags), equal signals.parquet bit for bit,
  and each is byte for byte the rosbag2 export's message of that topic and stamp;
- a late joiner (an AdvancedSubscriber with history, as a TRANSIENT_LOCAL subscription) gets
  /tf_static from the publisher's cache; an unreachable router: a warning naming it, the run completes.
"""

from __future__ import annotations

import json
import os
import queue
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading

import numpy as np
import pytest
import xxhash

from tests.conftest import ROOT, orchestrator
from tests.integration.test_rosbag_export import _equal, _ns, _parquet, _stamps, _vector, _xyz
from tests.unit.test_rmw_zenoh import PUBLISHED_HASHES

pytestmark = pytest.mark.integration

DOMAIN = 7
CONFIG = ROOT / "configs" / "capture_tumbling_target.yaml"
ROUTER = """
import sys, zenoh
config = zenoh.Config()
config.insert_json5("mode", '"router"')
config.insert_json5("listen/endpoints", '["%s"]')
config.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(config)
print("ready", flush=True)
sys.stdin.read()   # until the test closes our stdin
session.close()
"""

# the stand-in router runs Zenoh's own runtime, as rmw_zenohd does: not bus.RUNTIME, which the
# test process (bus.session_config) puts in the environment
ROUTER_ENV = {k: v for k, v in os.environ.items() if k != "ZENOH_RUNTIME"}


def _start_router(endpoint: str) -> subprocess.Popen:
    process = subprocess.Popen(
        [sys.executable, "-c", ROUTER % endpoint],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=ROUTER_ENV,
    )
    assert process.stdout.readline().strip() == "ready"
    return process


def _stop_router(process: subprocess.Popen) -> None:
    process.stdin.close()
    try:
        process.wait(timeout=10)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _parse_token(key: str) -> dict:
    """A liveliness token as rmw_zenoh's ``Entity::make(keyexpr)`` reads it."""
    parts = key.split("/")
    assert parts[0] == "@ros2_lv" and len(parts) >= 9 and all(parts), key
    entity = {
        "domain": int(parts[1]),
        "zid": parts[2],
        "nid": parts[3],
        "id": parts[4],
        "kind": parts[5],
        "enclave": parts[6].replace("%", "/"),
        "namespace": parts[7].replace("%", "/"),
        "node": parts[8].replace("%", "/"),
    }
    if entity["kind"] != "NN":
        assert len(parts) == 13, key
        entity.update(topic=parts[9].replace("%", "/"), type=parts[10].replace("%", "/"), hash=parts[11], qos=parts[12])
    return entity


def _ros_type(dds_type: str) -> str:
    """``pkg::msg::dds_::Name_`` -> ``pkg/msg/Name`` (design.md's type names)."""
    match = re.fullmatch(r"(\w+)::(msg)::dds_::(\w+)_", dds_type)
    assert match, dds_type
    return "/".join(match.groups())


def _gid(token: str) -> bytes:
    """liveliness_utils.cpp: XXH3-128 of the token, the low 64 bits then the high 64, little endian."""
    digest = xxhash.xxh3_128(token.encode()).digest()  # big endian: high half first
    return digest[8:][::-1] + digest[:8][::-1]


def _decoders(typestore, msgtypes):
    """mcap-ros2-support's decoders from the ROS 2 message definitions (the schema text)."""
    from mcap_ros2._dynamic import generate_dynamic

    return {t: generate_dynamic(t, typestore.generate_msgdef(t, ros_version=2)[0])[t] for t in msgtypes}


class RosSide:
    """The ROS side of the test: a peer of the router, with a graph-cache liveliness subscriber and
    a data subscriber; on the first /tf_static token, a late-joining TRANSIENT_LOCAL subscription."""

    def __init__(self, endpoint: str):
        import zenoh
        import zenoh.ext

        from components import bus

        self.endpoint = endpoint
        self.closed = False
        self.session = zenoh.open(bus.session_config(connect=[endpoint], mesh=True))
        self._late_session = None  # the late joiner: another node, so a session of its own
        self.tokens: dict[str, bool] = {}
        self.samples: list[tuple[str, bytes, bytes | None]] = []  # (key, payload, attachment)
        self.late: list[bytes] = []
        self.live_tf_static: list[bytes] = []
        self._late_sub = None
        self._pending: queue.Queue = queue.Queue()
        self._arrived = threading.Condition()
        self.liveliness = self.session.liveliness().declare_subscriber("@ros2_lv/**", self._token, history=True)
        self.data = self.session.declare_subscriber(f"{DOMAIN}/**", self._sample)
        self.thread = threading.Thread(target=self._declare_late, daemon=True)
        self.thread.start()

    def _token(self, sample) -> None:
        import zenoh

        key = str(sample.key_expr)
        self.tokens[key] = sample.kind == zenoh.SampleKind.PUT
        if "/MP/" in key and "/%tf_static/" in key and self._late_sub is None:
            self._pending.put(_parse_token(key))

    def _sample(self, sample) -> None:
        attachment = sample.attachment.to_bytes() if sample.attachment is not None else None
        with self._arrived:
            self.samples.append((str(sample.key_expr), sample.payload.to_bytes(), attachment))
            self._arrived.notify_all()
        if "/tf_static/" in str(sample.key_expr):
            self.live_tf_static.append(sample.payload.to_bytes())

    def _declare_late(self) -> None:
        import zenoh
        import zenoh.ext

        from components import bus

        entity = self._pending.get()
        if entity is None:
            return
        key = f"{DOMAIN}/tf_static/{entity['type'].replace('/', '%')}/{entity['hash']}"
        # rmw_subscription_data.cpp: TRANSIENT_LOCAL -> history with late publishers detected,
        # depth samples, subscriber detection, heartbeat recovery
        self._late_session = zenoh.open(bus.session_config(connect=[self.endpoint], mesh=True))
        self._late_sub = zenoh.ext.declare_advanced_subscriber(
            self._late_session,
            key,
            lambda s: self.late.append(s.payload.to_bytes()),
            subscriber_detection=True,
            history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=1),
            recovery=zenoh.ext.RecoveryConfig(heartbeat=True),
        )

    def last_sequences(self) -> dict[str, int]:
        """Each data key's highest sequence number received (the attachment's first int64)."""
        last: dict[str, int] = {}
        for key, _, attachment in list(self.samples):
            last[key] = max(last.get(key, 0), int.from_bytes(attachment[:8], "little", signed=True))
        return last

    def wait_for(self, count: int, timeout_s: float) -> None:
        """Until every publisher's last message has come (their sequence numbers, from 1, add up to
        the ``count`` the observer published), or the time is up (the test then says what is missing)."""
        with self._arrived:
            self._arrived.wait_for(lambda: sum(self.last_sequences().values()) >= count, timeout_s)

    def close(self) -> None:
        self.closed = True
        self._pending.put(None)
        self.thread.join(timeout=5)
        for declared in (self._late_sub, self.data, self.liveliness):
            if declared is not None:
                declared.undeclare()
        for session in (self._late_session, self.session):
            if session is not None:
                session.close()


@pytest.fixture(scope="module")
def router():
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    process = _start_router(endpoint)
    try:
        yield endpoint
    finally:
        _stop_router(process)


@pytest.fixture(scope="module")
def live(router, tmp_path_factory):
    """The capture scenario, 2 s at 10 ms paced at real time (so that the late joiner comes while
    it runs), every row to ROS 2 (ros2.rate 100 Hz), recorded; then exported as rosbag2."""
    record = tmp_path_factory.mktemp("ros2") / "rec"
    ros = RosSide(router)
    try:
        result = orchestrator(
            "run",
            CONFIG,
            "--set",
            "run.duration=2 s",
            "--set",
            "run.realtime=1",
            "--set",
            "ros2.rate=100 Hz",
            "--record",
            record,
            "--ros2",
            router,
            env={**os.environ, "ROS_DOMAIN_ID": str(DOMAIN)},
        )
        sent = re.search(r"run over: (\d+) messages published", result.stderr)
        if sent:  # the last ones may still be on their way through the router when the run returns
            ros.wait_for(int(sent.group(1)), timeout_s=20)
    finally:
        ros.close()
    assert result.returncode == 0, result.stderr
    bag = record.parent / "bag"
    exported = orchestrator("export", record, "--rosbag2", bag)
    assert exported.returncode == 0, exported.stderr
    return ros, record, bag, result


def test_graph_tokens_name_the_node_and_a_publisher_per_topic(live):
    ros, _, _, _ = live
    entities = [_parse_token(k) for k in ros.tokens]
    nodes = [e for e in entities if e["kind"] == "NN"]
    assert [(e["node"], e["namespace"], e["enclave"], e["domain"]) for e in nodes] == [
        ("zenorbit_capture_tumbling_target", "/", "/", DOMAIN)
    ]
    assert nodes[0]["nid"] == nodes[0]["id"]
    publishers = {e["topic"]: e for e in entities if e["kind"] == "MP"}
    assert all(e["zid"] == nodes[0]["zid"] and e["nid"] == nodes[0]["nid"] for e in publishers.values())
    assert {
        "/clock",
        "/tf",
        "/tf_static",
        "/imu/imu",
        "/wrist_ft/wrench",
        "/pose_sensor/pose",
        "/dynamics/servicer/joint_states",
        "/dynamics/servicer/robot_description",
    } <= set(publishers)
    for topic, e in publishers.items():
        msgtype = _ros_type(e["type"])
        assert e["hash"] == "RIHS01_" + PUBLISHED_HASHES[msgtype], topic
        latched = topic == "/tf_static" or topic.endswith("/robot_description")
        assert e["qos"] == (":1:,1:,:,:,," if latched else "::,10:,:,:,,"), (topic, e["qos"])
    assert ros.tokens and not any(ros.tokens.values()), "every token is undeclared at the end of the run"


def test_samples_carry_rmw_zenohs_attachment_and_key(live):
    ros, _, _, _ = live
    publishers = {
        f"{DOMAIN}/{e['topic'].strip('/')}/{e['type']}/{e['hash']}": token
        for token in ros.tokens
        if (e := _parse_token(token))["kind"] == "MP"
    }
    sequences: dict[str, list[int]] = {}
    for key, payload, attachment in ros.samples:
        assert key in publishers, f"a sample on {key}, which no publisher token announces"
        assert attachment is not None and len(attachment) == 33
        sequence, timestamp, length = np.frombuffer(attachment[:16], "<i8").tolist() + [attachment[16]]
        assert length == 16 and attachment[17:] == _gid(publishers[key])
        assert timestamp > 1_600_000_000 * 10**9  # the system clock (ns since 1970), as rmw_zenoh's
        sequences.setdefault(key, []).append(sequence)
        assert payload[:4] == b"\x00\x01\x00\x00"  # CDR, little endian encapsulation
    # rmw_zenoh's publishers count from 1, each sample one more (no gap: the next test)
    assert sequences and all(s == sorted(set(s)) and s[0] >= 1 for s in sequences.values())


def test_messages_equal_the_recording_and_the_export(live):
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_typestore

    ros, record, bag, _result = live
    typestore = get_typestore(Stores.ROS2_JAZZY)
    by_topic: dict[str, list[bytes]] = {}
    types = {}
    for key, payload, _ in ros.samples:
        _, *topic, dds_type, _ = key.split("/")
        types["/" + "/".join(topic)] = _ros_type(dds_type)
        by_topic.setdefault("/" + "/".join(topic), []).append(payload)
    decode = _decoders(typestore, set(types.values()))
    topics = {t: [decode[types[t]](p) for p in payloads] for t, payloads in by_topic.items()}

    columns = _parquet(record)
    row_of = {int(ns): row for row, ns in enumerate(_stamps(record, columns))}
    # every row when the observer keeps up; like the viewer it reads a dropping publisher, so on a
    # loaded machine rows may be left out before it (that all it sent arrives: the next test)
    clock = [_ns(m.clock) for m in topics["/clock"]]
    assert len(clock) > 1 and clock == sorted(set(clock)) and set(clock) <= set(row_of)

    def rows(messages):
        return [row_of[_ns(m.header.stamp)] for m in messages]

    imu = topics["/imu/imu"]
    _equal([_xyz(m.angular_velocity) for m in imu], _vector(columns, "imu.rate", 3)[rows(imu)])
    _equal([_xyz(m.linear_acceleration) for m in imu], _vector(columns, "imu.specific_force", 3)[rows(imu)])
    wrench = topics["/wrist_ft/wrench"]
    _equal(
        [_xyz(m.wrench.force) + _xyz(m.wrench.torque) for m in wrench],
        _vector(columns, "wrist_ft.wrench", 6)[rows(wrench)],
    )
    joints = topics["/dynamics/servicer/joint_states"]
    joint_stamps = [_ns(m.header.stamp) for m in joints]
    assert len(joint_stamps) > 1 and joint_stamps == sorted(set(joint_stamps))
    n_joints = len(joints[0].name)
    _equal([m.position for m in joints], _vector(columns, "dynamics.servicer.q", n_joints)[rows(joints)])
    _equal([m.velocity for m in joints], _vector(columns, "dynamics.servicer.qd", n_joints)[rows(joints)])

    exported: dict[str, list[bytes]] = {}
    with open(next(bag.glob("*.mcap")), "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=True):
            exported.setdefault(channel.topic, []).append(bytes(message.data))
    assert {"/clock", "/tf", "/imu/imu", "/dynamics/servicer/joint_states"} <= by_topic.keys() <= exported.keys()
    for topic, payloads in by_topic.items():  # in order, byte for byte the export's (all of them, unloaded)
        remaining = iter(exported[topic])
        assert all(any(p == e for e in remaining) for p in payloads), f"{topic}: not the export's messages in order"


def test_every_message_published_reaches_the_ros_side(live):
    """From the first message the listener got on each topic, none missing, up to the last one
    published (what went out before the router told the observer of the subscription is not
    delivered, as on any volatile ROS 2 topic)."""
    ros, _, _, result = live
    sequences: dict[str, list[int]] = {}
    for key, _, attachment in ros.samples:
        sequences.setdefault(key, []).append(int.from_bytes(attachment[:8], "little", signed=True))
    assert all(s == list(range(s[0], s[0] + len(s))) for s in sequences.values()), "a gap in a topic's sequence"
    sent = int(re.search(r"run over: (\d+) messages published", result.stderr).group(1))
    assert sum(ros.last_sequences().values()) == sent, "every publisher's last message reached the ROS side"


def _events(record, kind: str) -> list[dict]:
    lines = (record / "events.jsonl").read_text().splitlines()
    return [e for e in map(json.loads, lines) if e.get("kind", e.get("event")) == kind]


def test_the_report_counts_every_message_and_the_run_says_it(live):
    _ros, record, _, result = live
    report = json.loads((record / "ros2.report.json").read_text())
    sent = int(re.search(r"run over: (\d+) messages published", result.stderr).group(1))
    assert sum(report["published"].values()) == sent and report["dropped"] == {} and report["why"] == {}
    assert report["links_lost"] == report["links_back"] == 0
    # every row that arrived gives one /clock message (ros2.rate is the step rate)
    assert report["published"]["/clock"] == report["rows"] > 1
    (event,) = _events(record, "ros2_stream")
    assert event["published"] == report["published"] and 0 < report["rows"] <= event["rows_sent"]
    line = (
        f"ROS 2 view: {sent} messages published on {len(report['published'])} topics; of the "
        f"{event['rows_sent']} rows sent to it, {report['rows']} arrived; dropped: none"
    )
    assert line in result.stdout + result.stderr


class RosSubscriber(RosSide):
    """A ROS side whose node has a TRANSIENT_LOCAL subscription (its MS token, as rmw_zenoh
    declares it) to each latched topic the observer announces, with the publisher's type and hash."""

    def __init__(self, endpoint: str):
        self._subscriptions: queue.Queue = queue.Queue()
        self._declared: list = []
        super().__init__(endpoint)
        self._declarer = threading.Thread(target=self._declare, daemon=True)
        self._declarer.start()

    def _token(self, sample) -> None:
        super()._token(sample)
        key = str(sample.key_expr)
        if "/MP/" in key and _parse_token(key)["qos"].startswith(":1:"):  # TRANSIENT_LOCAL
            self._subscriptions.put(_parse_token(key))

    def _declare(self) -> None:
        zid = str(self.session.info.zid())
        node = f"@ros2_lv/{DOMAIN}/{zid}/0/0/NN/%/%/listener"
        self._declared.append(self.session.liveliness().declare_token(node))
        for n, entity in enumerate(iter(self._subscriptions.get, None), start=1):
            topic, dds_type = entity["topic"].replace("/", "%"), entity["type"].replace("/", "%")
            key = f"@ros2_lv/{DOMAIN}/{zid}/0/{n}/MS/%/%/listener/{topic}/{dds_type}/{entity['hash']}/:1:,1:,:,:,,"
            self._declared.append(self.session.liveliness().declare_token(key))

    def close(self) -> None:
        self._subscriptions.put(None)
        self._declarer.join(timeout=5)
        for token in self._declared:
            token.undeclare()
        super().close()


def _read_until(stream, text: str, lines: list[str]) -> None:
    for line in stream:
        lines.append(line)
        if text in line:
            return
    raise AssertionError(f"the run ended without {text!r}:\n" + "".join(lines))


def test_a_restarted_router_gets_the_rest_of_the_stream_and_the_latched_topics_again(tmp_path):
    """The router goes down mid-run and comes back on the same endpoint: the observer says so,
    counts what it could not send, resumes, and sends /tf_static and robot_description again once
    a subscription to them is known; from then on every message arrives."""
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    record = tmp_path / "rec"
    router = _start_router(endpoint)
    first = second = run = None
    lines: list[str] = []
    try:
        first = RosSide(endpoint)
        run = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "orchestrator.cli",
                "run",
                str(CONFIG),
                "--set",
                "run.duration=10 s",
                "--set",
                "run.realtime=1",
                "--set",
                "ros2.rate=100 Hz",
                "--record",
                str(record),
                "--ros2",
                endpoint,
            ],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env={**os.environ, "ROS_DOMAIN_ID": str(DOMAIN)},
        )
        _read_until(run.stdout, "publishing the run to ROS 2", lines)
        with first._arrived:
            assert first._arrived.wait_for(lambda: len(first.samples) > 50, 60), "no data before the restart"
        _stop_router(router)
        router = None
        first.close()  # what it got is the stream before the restart
        _read_until(run.stdout, "is down", lines)
        router = _start_router(endpoint)
        second = RosSubscriber(endpoint)
        _read_until(run.stdout, "the stream resumes", lines)
        lines += run.stdout.readlines()  # to the end of the run
        assert run.wait(timeout=120) == 0, "".join(lines)
        sent = int(re.search(r"run over: (\d+) messages published", "".join(lines)).group(1))
        second.wait_for(sent, timeout_s=20)
    finally:
        if run is not None and run.poll() is None:
            run.kill()
            run.wait()
        for side in (first, second):
            if side is not None and not side.closed:
                side.close()
        if router is not None:
            _stop_router(router)
    output = "".join(lines)
    assert first.samples and second.samples
    # after the restart: no gap on any topic, up to each publisher's last message
    sequences: dict[str, list[int]] = {}
    for key, _, attachment in second.samples:
        sequences.setdefault(key, []).append(int.from_bytes(attachment[:8], "little", signed=True))
    assert all(s == list(range(s[0], s[0] + len(s))) for s in sequences.values()), "a gap after the restart"
    assert sum(second.last_sequences().values()) == sent
    # the latched topics came again, live, to the new subscription: the same bytes as the first time
    for topic in ("tf_static", "dynamics/servicer/robot_description"):
        before = [p for k, p, _ in first.samples if k.startswith(f"{DOMAIN}/{topic}/")]
        after = [p for k, p, _ in second.samples if k.startswith(f"{DOMAIN}/{topic}/")]
        assert len(before) == 1 and after == before, topic
    report = json.loads((record / "ros2.report.json").read_text())
    assert report["links_lost"] == report["links_back"] == 1
    assert sum(report["published"].values()) == sent
    # each row gives one /clock message: published, or dropped while the router was away
    assert report["published"]["/clock"] + report["dropped"].get("/clock", 0) == report["rows"]
    assert set(report["why"]) <= {"no link"}
    (event,) = _events(record, "ros2_stream")
    assert event["links_lost"] == 1 and event["published"] == report["published"]
    assert f"ROS 2 view: {sent} messages published on {len(report['published'])} topics" in output
    if report["dropped"]:
        assert f"dropped: {sum(report['dropped'].values())} messages" in output and "went down 1 time(s)" in output


def test_a_late_joiner_gets_tf_static_from_the_publishers_cache(live):
    ros, _, bag, _ = live
    from mcap.reader import make_reader

    with open(next(bag.glob("*.mcap")), "rb") as f:
        (static,) = [bytes(m.data) for _, c, m in make_reader(f).iter_messages() if c.topic == "/tf_static"]
    # sent once, before the late joiner came (unless the router had not yet told the observer of
    # this volatile subscription: then only the cache below has it)
    assert ros.live_tf_static in ([static], [])
    assert ros.late == [static]  # which got it from the cache


def test_an_unreachable_router_warns_and_the_run_completes(tmp_path):
    endpoint = f"tcp/127.0.0.1:{_free_port()}"  # nothing listens there
    record = tmp_path / "rec"
    result = orchestrator("run", CONFIG, "--set", "run.duration=0.1 s", "--record", record, "--ros2", endpoint)
    assert result.returncode == 0, result.stderr
    assert f"cannot reach the ROS 2 router at {endpoint}" in result.stderr
    assert len(_parquet(record)["time"]) == 11


def test_a_router_that_comes_up_during_the_run_gets_the_rest_of_it(tmp_path):
    """No router at the start: the warning; the router started upon it: the observer's retry
    links to it, and the ROS side sees the node and the /clock of the later rows."""
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    run = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "orchestrator.cli",
            "run",
            str(CONFIG),
            "--set",
            "run.duration=12 s",
            "--set",
            "run.realtime=1",
            "--ros2",
            endpoint,
        ],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "ROS_DOMAIN_ID": str(DOMAIN)},
    )
    router = ros = None
    lines: list[str] = []
    try:
        for line in run.stderr:
            lines.append(line)
            if f"cannot reach the ROS 2 router at {endpoint}" in line:
                break
        router = _start_router(endpoint)
        ros = RosSide(endpoint)
        lines += run.stderr.readlines()  # to the end of the run
        assert run.wait(timeout=120) == 0, "".join(lines)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
        if ros is not None:
            ros.close()
        if router is not None:
            _stop_router(router)
    assert any("publishing the run to ROS 2" in line for line in lines), "".join(lines)
    assert any(_parse_token(k)["kind"] == "NN" for k in ros.tokens)
    clock = [p for key, p, _ in ros.samples if key.startswith(f"{DOMAIN}/clock/")]
    assert len(clock) > 10


@pytest.mark.parametrize(
    "sets, expected",
    [
        (["ros2.topics=[/clock, /imu-1/imu]"], "ros2.topics[1]: ROS 2 rejects the topic name '/imu-1/imu'"),
        (["ros2.topic=[/clock]"], "ros2.topic: unknown key"),
        (["ros2.distro=humble"], "ros2.distro"),
    ],
)
def test_bad_ros2_sections_are_refused_at_check(sets, expected):
    result = orchestrator("check", CONFIG, *[a for s in sets for a in ("--set", s)])
    assert result.returncode == 2
    assert expected in result.stderr


def test_a_bad_endpoint_is_refused():
    result = orchestrator("run", CONFIG, "--ros2", "localhost:7447")
    assert result.returncode == 2 and "--ros2.endpoint" in result.stderr


def _ros2_with_rmw_zenoh() -> bool:
    if shutil.which("ros2") is None:
        return False
    found = subprocess.run(["ros2", "pkg", "prefix", "rmw_zenoh_cpp"], capture_output=True, timeout=60)
    return found.returncode == 0


@pytest.mark.ros2
@pytest.mark.skipif(not _ros2_with_rmw_zenoh(), reason="needs ROS 2 with rmw_zenoh_cpp (ros2 pkg prefix rmw_zenoh_cpp)")
def test_ros2_topic_echo_sees_the_runs_clock_through_rmw_zenohd(tmp_path):
    """The real thing: rmw_zenohd as the router, `ros2 topic echo /clock` and `ros2 topic list` as the
    ROS side (RMW_IMPLEMENTATION=rmw_zenoh_cpp), against the demo paced at real time."""
    env = {**os.environ, "RMW_IMPLEMENTATION": "rmw_zenoh_cpp", "ROS_DOMAIN_ID": str(DOMAIN)}
    router = subprocess.Popen(
        ["ros2", "run", "rmw_zenoh_cpp", "rmw_zenohd"],
        env=env,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    run = None
    try:
        run = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "orchestrator.cli",
                "run",
                str(CONFIG),
                "--set",
                "run.duration=30 s",
                "--set",
                "run.realtime=1",
                "--ros2",
                "tcp/localhost:7447",
            ],
            cwd=ROOT,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        echo = subprocess.run(
            ["ros2", "topic", "echo", "--once", "/clock", "rosgraph_msgs/msg/Clock"],
            env=env,
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert echo.returncode == 0, echo.stderr
        assert "clock:" in echo.stdout and "sec:" in echo.stdout and "nanosec:" in echo.stdout
        listed = subprocess.run(["ros2", "topic", "list"], env=env, capture_output=True, text=True, timeout=60)
        assert {"/clock", "/tf", "/tf_static", "/dynamics/servicer/joint_states"} <= set(listed.stdout.split())
        nodes = subprocess.run(["ros2", "node", "list"], env=env, capture_output=True, text=True, timeout=60)
        assert "/zenorbit_capture_tumbling_target" in nodes.stdout.split()
    finally:
        for process in (run, router):
            if process is not None and process.poll() is None:
                os.killpg(process.pid, signal.SIGINT)
                try:
                    process.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    os.killpg(process.pid, signal.SIGKILL)
                    process.wait()
