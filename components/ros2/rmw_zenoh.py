"""rmw_zenoh's wire conventions (ROS 2 Jazzy and later), so a plain Zenoh session is a ROS 2 node.

Every fact here is pinned to ros2/rmw_zenoh (``rmw_zenoh_cpp/src/detail/``, the AdvancedPublisher
era of the Jazzy branch and rolling) and its ``docs/design.md``:

- data key expression ``<domain_id>/<topic, leading and trailing '/' stripped>/<DDS type
  name>/<type hash>`` (liveliness_utils.cpp ``TopicInfo::TopicInfo``; design.md "Topic and Service
  name mapping"), e.g. ``0/chatter/std_msgs::msg::dds_::String_/RIHS01_df668c74...``;
- DDS type name ``pkg::msg::dds_::Name_`` (design.md; message_type_support ``get_name``) and the
  REP-2011 type hash ``RIHS01_<64 hex>`` (``rosidl_stringify_type_hash`` in rmw_publisher_data.cpp);
- payload: the CDR message with its 4-byte encapsulation header, as rosidl_typesupport_fastrtps
  writes it (rmw_publisher_data.cpp ``publish``);
- attachment on every sample: int64 sequence number (from 1), int64 source timestamp (ns, the
  publisher's system clock), the publisher's 16-byte GID as a sequence, in Zenoh's serialization
  format (attachment_helpers.cpp ``serialize_to_zbytes``: numbers little endian, a fixed array as
  a LEB128 length then its bytes), 8 + 8 + 1 + 16 = 33 bytes; ``RMW_GID_STORAGE_SIZE`` is 16
  (rmw/types.h since Iron);
- liveliness tokens ``@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<NN|MP|MS|SS|SC>/<enclave>/
  <namespace>/<node name>[/<topic>/<type>/<hash>/<qos>]``, each name mangled ('/' -> '%'), the
  QoS as ``qos_to_keyexpr`` writes it: only fields that differ from rmw_zenoh's default (KEEP_LAST
  42, RELIABLE, VOLATILE, infinite durations, AUTOMATIC) are written (liveliness_utils.cpp
  ``Entity::Entity``, ``qos_to_keyexpr``; qos.cpp); a node's token has its id twice
  (rmw_node_data.cpp); the GID is XXH3-128 of the token's key, low 64 bits then high 64, each
  little endian (liveliness_utils.cpp ``Entity::Entity``), which is how a remote graph cache
  computes it from the token as well;
- publishers: congestion control DROP (BLOCK for KEEP_ALL), reliability RELIABLE; a TRANSIENT_LOCAL one is an
  AdvancedPublisher with a cache of ``depth`` samples, publisher detection, and (RELIABLE) sporadic
  heartbeats every 500 ms (rmw_publisher_data.cpp ``PublisherData::make``); a TRANSIENT_LOCAL
  subscription is an AdvancedSubscriber with history (late publishers detected, ``depth`` samples),
  subscriber detection, heartbeat recovery (rmw_subscription_data.cpp ``SubscriptionData::init``).
  Jazzy has them since rmw_zenoh 0.2.2 (its release notes in ros/rosdistro#44533: "Introduce the
  advanced publisher and subscriber (#469)"); before, a PublicationCache and a QueryingSubscriber.
"""

from __future__ import annotations

import itertools
import re
import struct
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, TypedDict

if TYPE_CHECKING:
    import zenoh

ADMIN_SPACE = "@ros2_lv"  # liveliness_utils.cpp ADMIN_SPACE
NODE, PUBLISHER, SUBSCRIPTION = "NN", "MP", "MS"
GID_SIZE = 16  # rmw/types.h RMW_GID_STORAGE_SIZE (Iron and later)
ATTACHMENT = struct.Struct("<qqB16s")  # seq, source timestamp, LEB128(16) = 0x10, GID
TOPIC_MAX_LENGTH = 255 - 8  # rmw/validate_full_topic_name.h RMW_TOPIC_MAX_NAME_LENGTH
HEARTBEAT_MS = 500  # rmw_publisher_data.cpp SAMPLE_MISS_DETECTION_HEARTBEAT_PERIOD

# rmw/types.h enum values, as qos_to_keyexpr writes them
RELIABLE, BEST_EFFORT = 1, 2
TRANSIENT_LOCAL, VOLATILE = 1, 2
KEEP_LAST, KEEP_ALL = 1, 2
DEFAULT_DEPTH = 10  # rclcpp's default publisher/subscription depth (rmw_qos_profile_default)
_ZENOH_DEFAULTS = {"reliability": RELIABLE, "durability": VOLATILE, "history": KEEP_LAST, "depth": 42}  # qos.cpp

_HASH = re.compile(r"RIHS01_[0-9a-f]{64}")
_MSGTYPE = re.compile(r"([A-Za-z][A-Za-z0-9_]*)/(msg|srv|action)/([A-Za-z][A-Za-z0-9_]*)")


def type_hash(typestore, msgtype: str) -> str:
    """The REP-2011 type hash of ``msgtype`` (e.g. ``std_msgs/msg/String``): ``RIHS01_<64 hex>``,
    from the message definitions in ``typestore`` (rosbags)."""
    value = typestore.hash_rihs01(msgtype)
    if not _HASH.fullmatch(value):
        raise ValueError(f"{msgtype}: type hash {value!r} is not RIHS01_<64 hex>")
    return value


def dds_type_name(msgtype: str) -> str:
    """``pkg/msg/Name`` -> ``pkg::msg::dds_::Name_``, the type name in rmw_zenoh's keys and tokens."""
    match = _MSGTYPE.fullmatch(msgtype)
    if match is None:
        raise ValueError(f"{msgtype!r} is not a ROS 2 type name (package/msg/Name)")
    package, kind, name = match.groups()
    return f"{package}::{kind}::dds_::{name}_"


def check_topic_name(name: str) -> str | None:
    """Why ROS 2 rejects ``name`` as a fully qualified topic name, or None. The rules of
    rmw_validate_full_topic_name (rmw/validate_full_topic_name.h), in its order."""
    if not name:
        return "it is empty"
    if not name.startswith("/"):
        return "it is not absolute (it must start with '/')"
    if name.endswith("/"):
        return "it ends with '/'" if name != "/" else "it names no topic"
    bad = sorted({c for c in name if not (c.isascii() and (c.isalnum() or c in "_/"))})
    if bad:
        return f"it contains {''.join(bad)!r} (only letters, digits, '_' and '/' are allowed)"
    if "//" in name:
        return "it contains '//'"
    if any(token[:1].isdigit() for token in name.split("/")):
        return "a part of it starts with a digit"
    if len(name) > TOPIC_MAX_LENGTH:
        return f"it is {len(name)} characters long (at most {TOPIC_MAX_LENGTH})"
    return None


def topic_key(domain_id: int, topic: str, msgtype: str, typestore) -> str:
    """The data key expression of ``topic`` (fully qualified) carrying ``msgtype``."""
    return f"{int(domain_id)}/{topic.strip('/')}/{dds_type_name(msgtype)}/{type_hash(typestore, msgtype)}"


def encode_attachment(sequence: int, source_timestamp_ns: int, gid: bytes) -> bytes:
    """The 33-byte attachment of a sample: sequence number, source timestamp (ns), publisher GID."""
    if len(gid) != GID_SIZE:
        raise ValueError(f"a GID has {GID_SIZE} bytes, not {len(gid)}")
    return ATTACHMENT.pack(int(sequence), int(source_timestamp_ns), GID_SIZE, bytes(gid))


def decode_attachment(data: bytes) -> tuple[int, int, bytes]:
    """(sequence number, source timestamp in ns, GID) of a sample's attachment."""
    data = bytes(data)
    if len(data) != ATTACHMENT.size:
        raise ValueError(f"an attachment has {ATTACHMENT.size} bytes, not {len(data)}")
    sequence, timestamp, length, gid = ATTACHMENT.unpack(data)
    if length != GID_SIZE:
        raise ValueError(f"the attachment's GID length is {length}, not {GID_SIZE}")
    return sequence, timestamp, gid


def mangle(name: str) -> str:
    """A name in a liveliness token: each '/' as '%' (liveliness_utils.cpp ``mangle_name``)."""
    return name.replace("/", "%")


def qos_keyexpr(
    *, reliability: int = RELIABLE, durability: int = VOLATILE, history: int = KEEP_LAST, depth: int = DEFAULT_DEPTH
) -> str:
    """The QoS part of a token (liveliness_utils.cpp ``qos_to_keyexpr``): fields equal to rmw_zenoh's
    defaults are left empty; deadline, lifespan and liveliness are the defaults (infinite, AUTOMATIC)."""

    def field(key, value):
        return "" if value == _ZENOH_DEFAULTS[key] else str(value)

    return (
        f"{field('reliability', reliability)}:{field('durability', durability)}:"
        f"{field('history', history)},{field('depth', depth)}:,:,:,,"
    )


def token_key(
    domain_id: int,
    zid: str,
    node_id: int,
    entity_id: int,
    kind: str,
    enclave: str,
    namespace: str,
    node_name: str,
    topic: tuple[str, str, str, str] | None = None,
) -> str:
    """A liveliness token's key; ``topic``: (name, DDS type name, type hash, QoS) for MP and MS."""
    parts = [
        ADMIN_SPACE,
        str(int(domain_id)),
        zid,
        str(node_id),
        str(entity_id),
        kind,
        mangle(enclave),
        mangle(namespace),
        mangle(node_name),
    ]
    if topic is not None:
        name, dds_type, hash_, qos = topic
        parts += [mangle(name), mangle(dds_type), mangle(hash_), qos]
    return "/".join(parts)


def gid_of(token: str) -> bytes:
    """An entity's GID: XXH3-128 of its token's key, low then high 64 bits, little endian."""
    import xxhash

    return xxhash.xxh3_128_intdigest(token.encode()).to_bytes(GID_SIZE, "little")


def qualify(topic: str, namespace: str) -> str:
    """A topic name made fully qualified: a relative one goes under the node's namespace."""
    if topic.startswith("/"):
        return topic
    return namespace.rstrip("/") + "/" + topic


class _PublisherOptions(TypedDict):
    """The keywords a publisher is declared with (again, after a lost link)."""

    congestion_control: zenoh.CongestionControl
    reliability: zenoh.Reliability


class Publisher:
    """One ROS 2 publisher: its key expression, token and sequence numbers (made by :meth:`Node.publisher`)."""

    def __init__(
        self,
        session,
        key: str,
        token: str,
        latched: bool,
        depth: int,
        block: bool = False,
        subscribed: Callable[[], bool] = lambda: False,
    ):
        import zenoh
        import zenoh.ext

        self.key = key
        self.token_key = token
        self.latched = latched
        self._subscribed = subscribed
        self.gid = gid_of(token)
        self.sequence = 0
        congestion = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
        options = self._options = _PublisherOptions(
            congestion_control=congestion, reliability=zenoh.Reliability.RELIABLE
        )
        self._session = session
        if latched:  # late joiners get the cache through their AdvancedSubscriber's history query
            self._publisher = zenoh.ext.declare_advanced_publisher(
                session,
                key,
                cache=zenoh.ext.CacheConfig(depth),
                publisher_detection=True,
                sample_miss_detection=zenoh.ext.MissDetectionConfig(
                    heartbeat=None, sporadic_heartbeat=HEARTBEAT_MS / 1000
                ),
                **options,
            )
        else:
            self._publisher = session.declare_publisher(key, **options)
        self._token = session.liveliness().declare_token(token)

    def declare_again(self) -> None:
        """After the link to the router came back: a volatile publisher's declaration anew, so that
        its session asks again which subscribers match (seen under load: a publisher whose matching
        state was not renewed across a router restart sent nothing more). Its token, gid and
        sequence numbers stay; a latched one keeps its cache (it is sent again anyway)."""
        if self.latched:
            return
        old, self._publisher = self._publisher, self._session.declare_publisher(self.key, **self._options)
        try:
            old.undeclare()
        except Exception:  # the session may be closing
            pass

    def has_subscribers(self) -> bool:
        """Whether a ROS 2 subscription to this topic and type is known: its liveliness token (MS),
        as rmw_zenoh's graph cache matches them."""
        return self._subscribed()

    def put(self, cdr: bytes, source_timestamp_ns: int) -> None:
        """Send one message (CDR with its encapsulation header), numbered from 1."""
        self.sequence += 1
        self._publisher.put(bytes(cdr), attachment=encode_attachment(self.sequence, source_timestamp_ns, self.gid))

    def close(self) -> None:
        for declared in (self._token, self._publisher):
            try:
                declared.undeclare()
            except Exception:  # the session may be closed already
                pass


class Subscriber:
    """One ROS 2 subscription: ``handler(cdr bytes, (sequence, source timestamp ns, gid))`` is
    called on Zenoh's thread for each sample (made by :meth:`Node.subscriber`)."""

    def __init__(
        self, session, key: str, token: str, handler: Callable[[bytes, tuple], None], latched: bool, depth: int
    ):
        import zenoh.ext

        self.key = key
        self.token_key = token

        def on_sample(sample) -> None:
            if sample.attachment is None:  # rmw_zenoh drops such a sample too
                return
            try:
                attachment = decode_attachment(sample.attachment.to_bytes())
            except ValueError:
                return
            handler(sample.payload.to_bytes(), attachment)

        if latched:
            self._subscriber = zenoh.ext.declare_advanced_subscriber(
                session,
                key,
                on_sample,
                subscriber_detection=True,
                history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=depth),
                recovery=zenoh.ext.RecoveryConfig(periodic_queries=None, heartbeat=True),
            )
        else:
            self._subscriber = session.declare_subscriber(key, on_sample)
        self._token = session.liveliness().declare_token(token)

    def close(self) -> None:
        for declared in (self._token, self._subscriber):
            try:
                declared.undeclare()
            except Exception:
                pass


_ids_lock = threading.Lock()
_ids: dict[str, itertools.count] = {}  # zid -> the session's entity ids (rmw_zenoh: one counter per context)


def _next_id(zid: str) -> int:
    with _ids_lock:
        return next(_ids.setdefault(zid, itertools.count()))


class Node:
    """A ROS 2 node on a Zenoh session: its token (``ros2 node list``), publishers and
    subscriptions (``ros2 topic list``). The session is the caller's: connected to the ROS side's
    router (``rmw_zenohd``), and closed by the caller after :meth:`close`."""

    def __init__(self, session, domain_id: int, name: str, namespace: str = "/", enclave: str = "/"):
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
            raise ValueError(f"node name {name!r}: letters, digits and '_', not starting with a digit")
        if namespace != "/" and (problem := check_topic_name(namespace)):
            raise ValueError(f"node namespace {namespace!r}: {problem}")
        self.session = session
        self.domain_id = int(domain_id)
        self.name, self.namespace, self.enclave = name, namespace, enclave
        self.zid = str(session.info.zid())
        self.id = _next_id(self.zid)
        self.token_key = token_key(self.domain_id, self.zid, self.id, self.id, NODE, enclave, namespace, name)
        self._token = session.liveliness().declare_token(self.token_key)
        self.entities: list[Publisher | Subscriber] = []
        self._subscriptions: dict[str, tuple[str, str]] = {}  # MS token -> (topic, DDS type): the graph's subscriptions
        self._graph = None

    def _graph_sample(self, sample) -> None:
        import zenoh

        key = str(sample.key_expr)
        parts = key.split("/")
        if len(parts) != 13 or parts[5] != SUBSCRIPTION:
            return
        if sample.kind == zenoh.SampleKind.PUT:
            self._subscriptions[key] = (parts[9], parts[10])  # mangled topic, DDS type name
        else:
            self._subscriptions.pop(key, None)

    def _subscribed(self, topic: str, msgtype: str) -> Callable[[], bool]:
        """Whether the graph has a subscription to ``topic`` (fully qualified) of ``msgtype``."""
        wanted = (mangle(topic), dds_type_name(msgtype))

        def subscribed() -> bool:
            if self._graph is None:  # on first use only; the tokens already there come too (history)
                self._graph = self.session.liveliness().declare_subscriber(
                    f"{ADMIN_SPACE}/{self.domain_id}/**", self._graph_sample, history=True
                )
            return wanted in list(self._subscriptions.values())

        return subscribed

    def _entity_token(self, kind: str, topic: str, msgtype: str, typestore, qos: str) -> tuple[str, str]:
        topic = qualify(topic, self.namespace)
        if problem := check_topic_name(topic):
            raise ValueError(f"topic {topic!r}: ROS 2 rejects it: {problem}")
        key = topic_key(self.domain_id, topic, msgtype, typestore)
        token = token_key(
            self.domain_id,
            self.zid,
            self.id,
            _next_id(self.zid),
            kind,
            self.enclave,
            self.namespace,
            self.name,
            (topic, dds_type_name(msgtype), type_hash(typestore, msgtype), qos),
        )
        return key, token

    @staticmethod
    def _qos(latched: bool) -> tuple[str, int]:
        # latched: as tf2's static broadcaster and robot_state_publisher (depth 1, TRANSIENT_LOCAL)
        depth = 1 if latched else DEFAULT_DEPTH
        return qos_keyexpr(durability=TRANSIENT_LOCAL if latched else VOLATILE, depth=depth), depth

    def publisher(self, topic: str, msgtype: str, typestore, latched: bool = False, block: bool = False) -> Publisher:
        """A publisher of ``msgtype`` on ``topic``; ``latched``: TRANSIENT_LOCAL, depth 1.
        ``block``: congestion control BLOCK, as rmw_zenoh has it for KEEP_ALL only: a put waits
        for a congested link rather than dropping the message (for a sender that may wait)."""
        qos, depth = self._qos(latched)
        key, token = self._entity_token(PUBLISHER, topic, msgtype, typestore, qos)
        publisher = Publisher(
            self.session, key, token, latched, depth, block, self._subscribed(qualify(topic, self.namespace), msgtype)
        )
        self.entities.append(publisher)
        return publisher

    def subscriber(
        self, topic: str, msgtype: str, typestore, handler: Callable[[bytes, tuple], None], latched: bool = False
    ) -> Subscriber:
        """A subscription to ``topic``; ``handler(cdr, (sequence, source timestamp ns, gid))``."""
        qos, depth = self._qos(latched)
        key, token = self._entity_token(SUBSCRIPTION, topic, msgtype, typestore, qos)
        subscriber = Subscriber(self.session, key, token, handler, latched, depth)
        self.entities.append(subscriber)
        return subscriber

    def close(self) -> None:
        """Undeclare the publishers, subscriptions and the node's token."""
        for entity in reversed(self.entities):
            entity.close()
        self.entities = []
        for declared in (self._graph, self._token):
            if declared is None:
                continue
            try:
                declared.undeclare()
            except Exception:
                pass
