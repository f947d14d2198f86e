"""fusiond as an rmw_zenoh node: the keys, attachments and liveliness tokens ROS 2 nodes on rmw_zenoh use.

With `[ros] interop = "rmw_zenoh"` the daemon speaks rmw_zenoh's protocol itself,
so `ros2 topic list/echo` and any rmw_zenoh subscriber see its topics and rmw_zenoh
publishers feed it, with no bridge. Every detail below follows ros2/rmw_zenoh's
`rmw_zenoh_cpp/src/detail/` sources (Jazzy 0.2.4 and later, Kilted, Rolling; read
at the commits named in the README's ROS 2 section):

- Data key (liveliness_utils.cpp, `TopicInfo::TopicInfo`):
  `<domain_id>/<topic without leading/trailing '/'>/<DDS type name>/<RIHS01 type hash>`,
  e.g. `0/odometry/filtered/nav_msgs::msg::dds_::Odometry_/RIHS01_3cc9...`.
- Attachment on every sample (attachment_helpers.cpp, `AttachmentData::serialize_to_zbytes`;
  rmw_publisher_data.cpp, `PublisherData::publish`): Zenoh's serialisation of
  (int64 sequence number, int64 source timestamp in ns of the system clock,
  std::array<uint8_t, 16> GID), the array being a sequence (LEB128 length 16, then the
  bytes): 33 bytes. The sequence number starts at 1 per publisher. Before 0.2.4
  (e.g. the first Jazzy releases) the attachment was a different, key/value format: not
  supported. An rmw_zenoh subscriber drops a sample without an attachment
  (rmw_subscription_data.cpp: "Unable to obtain attachment").
- GID (liveliness_utils.cpp, `Entity::Entity`): XXH3-128 of the entity's liveliness key
  expression, low 64 bits then high 64 bits, each little-endian.
- Liveliness tokens (liveliness_utils.cpp, `Entity::Entity`, `KeyexprIndex`):
  node `@ros2_lv/<domain>/<zid>/<nid>/<nid>/NN/<enclave>/<namespace>/<name>` (rmw_node_data.cpp
  passes the node id as both ids), publisher `MP` and subscription `MS`
  `@ros2_lv/<domain>/<zid>/<nid>/<id>/MP|MS/<enclave>/<namespace>/<node>/<topic>/<type>/<hash>/<qos>`,
  every name with '/' replaced by '%' (`mangle_name`): the default enclave and
  namespace "/" become "%". Ids are one counter per context, the node taking the
  first (rmw_context_impl_s.cpp `get_next_entity_id`).
- QoS in the token (liveliness_utils.cpp `qos_to_keyexpr`, defaults in qos.cpp):
  `<reliability>:<durability>:<history>,<depth>:<deadline s>,<ns>:<lifespan s>,<ns>:<liveliness>,<s>,<ns>`,
  a field equal to rmw_zenoh's default (RELIABLE, VOLATILE, KEEP_LAST, depth 42,
  infinite durations, AUTOMATIC) left empty. fusiond's endpoints are reliable,
  volatile, keep-last: depth 10 (rclcpp's usual queue) and 100 for /tf (tf2_ros's
  broadcaster QoS), so their QoS reads `::,10:,:,:,,` / `::,100:,:,:,,`.

zenoh-python's `zenoh.ext.z_serialize` does Zenoh's serialisation; rosbags gives
type hashes (`fusiond.codecs.type_hash`); `xxhash` the GID.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Callable
from typing import Any, Final

import xxhash
import zenoh
from zenoh.ext import Int64, z_serialize

from ..codecs import dds_type_name, type_hash
from ..logs import get_logger

log = get_logger("fusiond.rmw_zenoh")

ADMIN_SPACE: Final = "@ros2_lv"
NODE: Final = "NN"
PUBLISHER: Final = "MP"
SUBSCRIPTION: Final = "MS"
DEFAULT_DEPTH: Final = 42  # rmw_zenoh's default history depth (qos.cpp): elided from the token
QUEUE_DEPTH: Final = 10  # fusiond's endpoints: rclcpp's usual queue depth
TF_DEPTH: Final = 100  # tf2_ros's broadcaster QoS depth


def mangle(name: str) -> str:
    """liveliness_utils.cpp `mangle_name`: '/' -> '%' (Zenoh key chunks cannot be empty)."""
    return name.replace("/", "%")


def topic_name(key: str) -> str:
    """The ROS topic of a fusiond key: "odometry/filtered" -> "/odometry/filtered"."""
    return "/" + key.strip("/")


def topic_key(domain_id: int, topic: str, msgtype: str) -> str:
    """The data key expression of a topic (liveliness_utils.cpp `TopicInfo`)."""
    return f"{domain_id}/{topic.strip('/')}/{dds_type_name(msgtype)}/{type_hash(msgtype)}"


def qos_keyexpr(depth: int) -> str:
    """A reliable, volatile, keep-last(depth) endpoint's QoS chunk (everything else default)."""
    d = "" if depth == DEFAULT_DEPTH else str(depth)
    return f"::,{d}:,:,:,,"


def gid_of(liveliness_keyexpr: str) -> bytes:
    """The entity's 16-byte GID: XXH3-128 of its token key, low64 then high64, little-endian."""
    v = xxhash.xxh3_128_intdigest(liveliness_keyexpr.encode())
    return (v & 0xFFFF_FFFF_FFFF_FFFF).to_bytes(8, "little") + (v >> 64).to_bytes(8, "little")


def attachment(sequence_number: int, source_timestamp_ns: int, gid: bytes) -> bytes:
    """rmw_zenoh's per-sample attachment in Zenoh's serialisation (33 bytes)."""
    return z_serialize((Int64(sequence_number), Int64(source_timestamp_ns), gid)).to_bytes()


class RmwPublisher:
    """A Zenoh publisher on a topic's rmw_zenoh key that attaches seq/timestamp/GID to each sample.

    `put` is called by one thread at a time (the one holding the daemon's core, or its health
    thread for /diagnostics), so the sequence counter needs no lock.
    """

    def __init__(self, node: RmwNode, topic: str, msgtype: str, depth: int, express: bool) -> None:
        self.topic = topic
        self.msgtype = msgtype
        self.key = topic_key(node.domain_id, topic, msgtype)
        self.token_key = node.entity_keyexpr(PUBLISHER, topic, msgtype, depth)
        self.gid = gid_of(self.token_key)
        self._pub = node.session.declare_publisher(self.key, encoding=zenoh.Encoding.APPLICATION_CDR,
                                                   express=express)
        self._token = node.session.liveliness().declare_token(self.token_key)
        self._seq = 0
        self._clock = time.time_ns  # rmw_zenoh: get_system_time_in_ns (system clock)

    def put(self, payload: bytes) -> None:
        self._seq += 1  # rmw_zenoh starts at 1 (PublisherData: sequence_number_(1), then ++)
        self._pub.put(payload, attachment=attachment(self._seq, self._clock(), self.gid))

    @property
    def sequence_number(self) -> int:
        """The sequence number of the last sample put (0: none yet)."""
        return self._seq

    def undeclare(self) -> None:
        self._token.undeclare()
        self._pub.undeclare()


class RmwSubscriber:
    """A Zenoh subscriber on a topic's rmw_zenoh key, with its MS liveliness token.

    The callback gets the Zenoh sample; the attachment is not needed to decode (the
    payload is the CDR message), so samples of publishers that omit it are taken too.
    """

    def __init__(self, node: RmwNode, topic: str, msgtype: str, callback: Any, depth: int) -> None:
        self.topic = topic
        self.key = topic_key(node.domain_id, topic, msgtype)
        self.token_key = node.entity_keyexpr(SUBSCRIPTION, topic, msgtype, depth)
        self._sub = node.session.declare_subscriber(self.key, callback)
        self._token = node.session.liveliness().declare_token(self.token_key)

    def undeclare(self) -> None:
        self._token.undeclare()
        self._sub.undeclare()


class RmwNode:
    """One ROS node on an open session: its NN token, and the publishers and subscriptions it declares."""

    def __init__(self, session: zenoh.Session, domain_id: int, name: str, namespace: str = "/",
                 enclave: str = "/") -> None:
        self.session = session
        self.domain_id = domain_id
        self.name = name
        self.namespace = namespace
        self.enclave = enclave
        self.zid = str(session.zid())
        self._ids = itertools.count()
        self._lock = threading.Lock()
        self.node_id = self._next_id()
        self.token_key = (f"{ADMIN_SPACE}/{domain_id}/{self.zid}/{self.node_id}/{self.node_id}/{NODE}/"
                          f"{mangle(enclave)}/{mangle(namespace)}/{mangle(name)}")
        self._token = session.liveliness().declare_token(self.token_key)
        self._entities: list[Any] = []

    def _next_id(self) -> int:
        with self._lock:
            return next(self._ids)

    def entity_keyexpr(self, kind: str, topic: str, msgtype: str, depth: int) -> str:
        """The liveliness key of a publisher (MP) or subscription (MS) of this node; takes the next id."""
        return (f"{ADMIN_SPACE}/{self.domain_id}/{self.zid}/{self.node_id}/{self._next_id()}/{kind}/"
                f"{mangle(self.enclave)}/{mangle(self.namespace)}/{mangle(self.name)}/"
                f"{mangle(topic)}/{dds_type_name(msgtype)}/{type_hash(msgtype)}/{qos_keyexpr(depth)}")

    def publisher(self, topic: str, msgtype: str, depth: int = QUEUE_DEPTH, express: bool = False) -> RmwPublisher:
        pub = RmwPublisher(self, topic, msgtype, depth, express)
        self._entities.append(pub)
        log.info("ros_publisher_declared", topic=topic, key=pub.key, token=pub.token_key)
        return pub

    def subscriber(self, topic: str, msgtype: str, callback: Callable[[zenoh.Sample], None] | Any,
                   depth: int = QUEUE_DEPTH) -> RmwSubscriber:
        sub = RmwSubscriber(self, topic, msgtype, callback, depth)
        self._entities.append(sub)
        log.info("ros_subscription_declared", topic=topic, key=sub.key, token=sub.token_key)
        return sub

    def undeclare(self) -> None:
        """The node's own token (entities are undeclared by their owners)."""
        self._token.undeclare()
