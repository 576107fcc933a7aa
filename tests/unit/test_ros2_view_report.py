"""The ROS 2 view's counts (components/ros2/stream_report.py, RosPublishers in
components/ros2/observer.py): what it writes to ros2.report.json and the line the run prints."""

from __future__ import annotations

import json

import pytest

from components.errors import ComponentError
from components.ros2 import stream_report
from components.ros2.observer import RosPublishers
from components.ros2.stream_report import FAILED, NO_LINK, StreamCounts
from components.rosbag import RosTopic

CLOCK = RosTopic("/clock", "rosgraph_msgs/msg/Clock", [])
TF_STATIC = RosTopic("/tf_static", "tf2_msgs/msg/TFMessage", [], True)
BAD = RosTopic("/imu-1/imu", "sensor_msgs/msg/Imu", [])


class Publisher:
    """A transport's publisher: ``put`` records, or raises as a dead rclpy process's does."""

    def __init__(self, log: list, dead: bool, subscribed: list[bool]):
        self.log, self.dead, self.subscribed = log, dead, subscribed

    def put(self, data: bytes, source_timestamp_ns: int) -> None:
        if self.dead:
            raise ComponentError("the rclpy node has exited")
        self.log.append(data)

    def has_subscribers(self) -> bool:
        return self.subscribed[0]


class Node:
    def __init__(self, dead: bool = False):
        self.sent: dict[str, list[bytes]] = {}
        self.dead = dead
        self.subscribed = [False]

    def publisher(self, topic, msgtype, typestore, latched=False, block=False):
        return Publisher(self.sent.setdefault(topic, []), self.dead, self.subscribed)


def _batch(n: int, start: int = 0):
    return [
        (CLOCK, [(k, b"c%d" % k) for k in range(start, start + n)]),
        (TF_STATIC, [(start, b"static")]),
        (BAD, [(start, b"x")]),
    ]


def test_published_and_dropped_per_topic_and_the_latched_topic_again_once_subscribed():
    warnings = []
    counts = StreamCounts()
    publishers = RosPublishers(None, None, None, warnings.append, counts)
    publishers.publish(_batch(3), up=True)  # no node yet (no router): dropped
    node = Node()
    publishers.node = node
    publishers.publish(_batch(4, start=3), up=False)  # the link is down: dropped
    publishers.publish(_batch(5, start=7), up=True)
    assert counts.published == {"/clock": 5, "/tf_static": 1}
    assert counts.dropped == {"/clock": 7, "/tf_static": 2} and counts.why == {NO_LINK: 9}
    assert node.sent == {"/clock": [b"c%d" % k for k in range(7, 12)], "/tf_static": [b"static"]}
    assert warnings == [
        "topic /imu-1/imu not published: ROS 2 rejects the name (it contains '-' "
        "(only letters, digits, '_' and '/' are allowed))"
    ]
    publishers.link_back()
    publishers.resend_latched()  # nobody subscribed yet: not sent
    assert node.sent["/tf_static"] == [b"static"]
    node.subscribed[0] = True
    publishers.resend_latched()
    publishers.resend_latched()  # once
    assert node.sent["/tf_static"] == [b"static", b"static"] and counts.published["/tf_static"] == 2
    assert publishers.sent == 7 and publishers.missing() == []


def test_a_publish_that_raises_is_a_drop_and_the_view_goes_on():
    warnings = []
    counts = StreamCounts()
    publishers = RosPublishers(Node(dead=True), None, ["/clock", "/tf"], warnings.append, counts)
    publishers.publish(_batch(3))
    publishers.publish(_batch(2, start=3))
    assert counts.published == {} and counts.dropped == {"/clock": 5} and counts.why == {FAILED: 5}
    # the observer says each warning once
    assert set(warnings) == {"publishing on /clock failed (ComponentError); its messages are dropped (counted)"}
    assert publishers.missing() == ["/tf"]


def test_the_report_round_trips_and_the_summary_says_the_numbers(tmp_path):
    counts = StreamCounts()
    counts.sent("/clock", 150)
    counts.sent("/tf", 150)
    counts.drop("/clock", NO_LINK, 40)
    counts.drop("/tf", NO_LINK, 40)
    counts.drop("/tf", FAILED, 1)
    counts.rows, counts.links_lost, counts.links_back = 190, 1, 1
    path = tmp_path / stream_report.REPORT
    counts.write(path)
    report = stream_report.read(path)
    assert report == json.loads(path.read_text()) == counts.as_dict()
    assert [p.name for p in tmp_path.iterdir()] == [stream_report.REPORT]
    assert stream_report.summary(report, 201) == (
        "ROS 2 view: 300 messages published on 2 topics; of the 201 rows sent to it, 190 arrived; "
        "dropped: 81 messages (/tf 41, /clock 40; no link: 80, publish failed: 1); "
        "the link to the ROS 2 router went down 1 time(s), came back 1"
    )


def test_a_clean_run_and_a_missing_report():
    counts = StreamCounts()
    counts.sent("/clock", 201)
    counts.rows = 201
    assert (
        stream_report.summary(counts.as_dict(), 201)
        == "ROS 2 view: 201 messages published on 1 topics; of the 201 rows sent to it, 201 arrived; dropped: none"
    )
    assert (
        stream_report.summary(None, 201, exit_code=-9)
        == "ROS 2 view: no report from its process (it exited with code -9); what it delivered is unknown"
    )


def test_a_file_that_is_not_a_report_is_none(tmp_path):
    path = tmp_path / stream_report.REPORT
    assert stream_report.read(path) is None
    path.write_text("[1, 2]")
    assert stream_report.read(path) is None
    path.write_text('{"published": {}}')
    assert stream_report.read(path) is None
    with pytest.raises(ValueError):
        StreamCounts().drop("/clock", "tired")


def test_a_signal_during_a_publish_still_stops_the_view():
    from components.observer_shell import Stop

    class Stopped(Node):
        def publisher(self, topic, msgtype, typestore, latched=False, block=False):
            publisher = super().publisher(topic, msgtype, typestore, latched, block)
            publisher.put = lambda data, ns: (_ for _ in ()).throw(Stop())
            return publisher

    counts = StreamCounts()
    with pytest.raises(Stop):
        RosPublishers(Stopped(), None, None, lambda text: None, counts).publish(_batch(2))
    assert counts.dropped == {}
