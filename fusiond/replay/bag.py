"""Sensor samples and ROS 2 CDR payloads from ROS 1 and ROS 2 bags (rosbags' AnyReader).

Replay and `fusiond play` read bags through here, so both see the same topics,
the same order (bag receive time) and the same samples the live codecs make.

rosbags and the codecs are imported where a bag is opened or read, not with this module: a replay
reading ahead (``read_ahead``) opens its bags in a child, and the fusing process never needs them.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from functools import lru_cache
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

from fusiond.core.sensors.registry import KINDS, kind_of
from fusiond.samples import Sample
from fusiond.replay import bag1_records
from fusiond.errors import BagError  # importable from here, as before
from fusiond.logs import get_logger

if TYPE_CHECKING:
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import Connection
    from rosbags.typesys.store import Typestore

    from fusiond.config import SensorConfig

log = get_logger(__name__)


def expected(sensor: SensorConfig) -> tuple[str, Callable[[Any, str], Sample]]:
    """(ROS message type, message -> sample) of a sensor, as its kind's descriptor says (a pose
    sensor's `msgtype` selects its type)."""
    kind = kind_of(sensor)
    return kind.ros_type(sensor), kind.from_ros()


def sensor_kind(sensor: SensorConfig) -> str:
    """The config's `kind` tag (msgspec keeps it on the class, not the instance)."""
    return str(type(sensor).__struct_config__.tag)


class BagSamples:
    """The configured sensors' messages in a bag, in bag (receive-time) order.

    Iterating yields samples; `raw_cdr()` yields the ROS 2 CDR payloads instead.
    Messages that do not deserialize are skipped and counted in `decode_errors`.
    Close it (or use it as a context manager) to release the bag files.
    """

    def __init__(self, reader: AnyReader, selected: dict[str, tuple[SensorConfig, list[Connection]]],
                 missing: list[str], names: str = "bag") -> None:
        self._reader = reader
        self._names = names
        self._by_topic = {topic: sensor for topic, (sensor, _) in selected.items()}
        self._connections = [c for _, conns in selected.values() for c in conns]
        self.topics: dict[str, str] = {sensor.name: topic for topic, (sensor, _) in selected.items()}
        self.missing = missing
        self.bag_topics: dict[str, str] = {t: i.msgtype or "" for t, i in reader.topics.items()}  # all, for errors
        self.total = sum(c.msgcount for c in self._connections)
        self.decode_errors = 0

    def __iter__(self) -> Iterator[Sample]:
        from fusiond.codecs import bag_fast_path

        reader = self._reader
        ros1 = not reader.is2
        convert = {}
        recorded = {c.topic: c.msgtype for c in self._connections}
        for topic, s in self._by_topic.items():
            msgtype, from_ros = expected(s)
            if recorded.get(topic, msgtype) != msgtype:  # the same definition under another name (same_definition):
                convert[topic] = (s.name, recorded[topic], from_ros, None)  # read as recorded, fields alike
                continue
            # a struct fast path only where the kind's codec offers one: a pose sensor reading
            # nav_msgs/msg/Odometry makes poses, not the odometry's samples
            codec = kind_of(s).codec()
            fast = None if codec is None else bag_fast_path(reader.typestore, codec, msgtype, ros1)
            convert[topic] = (s.name, msgtype, from_ros, fast)
        deserialize = reader.deserialize
        for connection, _, raw in self._messages():
            name, msgtype, from_ros, fast = convert[connection.topic]
            if fast is not None:  # odometry and IMU: read straight into the sample
                sample = fast(raw, name)
                if sample is not None:
                    yield sample
                    continue
            try:
                msg = deserialize(raw, msgtype)
            except Exception:  # AnyReaderError on a bad message, or anything rosbags raises on garbage
                self.decode_errors += 1
                continue
            yield from_ros(msg, name)

    def raw_cdr(self) -> Iterator[tuple[int, SensorConfig, bytes]]:
        """(bag time ns, sensor, ROS 2 CDR) as zenoh-bridge-ros2dds would publish the message.

        ROS 2 bags already hold CDR. ROS 1 messages are converted at byte level
        against the ROS 2 (Humble) types, which drops the ROS 1 header's `seq`.
        """
        from fusiond.codecs import typestore

        is2 = self._reader.is2
        for connection, bag_time, raw in self._messages():
            sensor = self._by_topic[connection.topic]
            if is2:
                yield bag_time, sensor, bytes(raw)
                continue
            try:
                cdr = typestore().ros1_to_cdr(raw, expected(sensor)[0])
            except Exception:
                self.decode_errors += 1
                continue
            yield bag_time, sensor, bytes(cdr)

    def _messages(self) -> Iterator[tuple[Connection, int, bytes]]:
        """The reader's messages; what rosbags raises on a damaged chunk (a corrupt compressed block,
        a truncated record) becomes a BagError naming the bag, not a traceback halfway through."""
        try:  # delegated: what the reader raises reaches here, what the consumer raises does not
            yield from bag1_records.messages(self._reader, self._connections)
        except Exception as err:  # noqa: BLE001 - rosbags raises builtins (OSError, AssertionError) on garbage
            raise BagError(damaged_ros2(self._names, err) or unreadable(self._names, err)) from None

    def close(self) -> None:
        if self._reader.stack is not None:
            self._reader.close()

    def __enter__(self) -> BagSamples:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


ROS1_MAGIC = b"#ROSBAG V2.0\n"  # the first line of every ROS 1 bag (format 2.0, the one rosbag writes)


def _starts_as_ros1(path: Path) -> bool:
    try:
        with path.open("rb") as f:
            return f.read(len(ROS1_MAGIC)) == ROS1_MAGIC
    except OSError:
        return True  # unreadable for another reason: rosbags says which


def _open_reader(paths: Sequence[Path]) -> AnyReader:
    if not paths:
        raise BagError("no bag given")
    for p in paths:
        if not p.exists():
            raise BagError(f"{p}: no such bag")
    # rosbags tells ROS 1 from ROS 2 by the ".bag" suffix: a ROS 2 bag directory reached through a
    # link named *.bag is opened at its real path; one really named *.bag cannot be read as such
    paths = [p.resolve() if p.is_dir() and p.suffix == ".bag" else p for p in paths]
    for p in paths:
        if p.is_dir() and p.suffix == ".bag":
            raise BagError(f"{p}: a ROS 2 bag directory named *.bag is read as a ROS 1 bag by rosbags; "
                           "rename it (or link it under another name)")
    ros1 = [p.suffix == ".bag" for p in paths]
    if any(ros1) and not all(ros1):
        raise BagError("cannot mix ROS 1 .bag files and ROS 2 bags in one replay")
    names = _names(paths)  # errors name the bags as given, a directory read from its storage file included
    paths = [_storage_file(p) if p.is_dir() and not (p / "metadata.yaml").exists() else p for p in paths]
    for p in paths:  # what rosbags would say in its own words, said in the user's
        if p.is_dir() and not (p / "metadata.yaml").exists():
            raise BagError(f"{p}: not a readable ROS 1/ROS 2 bag (a ROS 2 bag directory holds metadata.yaml and "
                           "its .db3 or .mcap files: this one has no metadata.yaml, and not one storage file "
                           "to read without it)")
        if p.is_file() and p.suffix == ".bag" and not _starts_as_ros1(p):
            raise BagError(f"{p}: not a readable ROS 1/ROS 2 bag (a ROS 1 bag starts with "
                           f"{ROS1_MAGIC.decode().strip()!r}: this file does not)")
    from rosbags.highlevel import AnyReaderError  # here, not at import: a replay reading ahead reads in a child

    try:
        return _opened(paths, None, names)
    except AnyReaderError as err:
        # rosbags' answer to a ROS 2 bag recorded without message definitions (before Iron): "Bag
        # contains no type definitions. Instantiate AnyReader with a default_typestore argument."
        if "default_typestore" not in str(err):
            raise BagError(damaged_ros2(names, err, paths)
                           or unreadable(names, err) + _repair_hint(paths, err)) from None
    from fusiond.codecs import typestore

    return _opened(paths, typestore(), names)  # the standard (Humble) definitions


def _storage_file(directory: Path) -> Path:
    """A ROS 2 bag directory without its metadata.yaml (a recorder cut off before writing it) that holds one
    storage file (.db3 or .mcap): that file, which rosbags reads on its own (the log says so); else the
    directory, refused by the caller."""
    files = sorted(directory.glob("*.db3")) + sorted(directory.glob("*.mcap"))
    if len(files) != 1:
        return directory
    log.warning("bag_metadata_missing", bag=str(directory), reading=str(files[0]),
                reason="no metadata.yaml: its one storage file is read on its own")
    return files[0]


def _names(paths: Sequence[Path]) -> str:
    return ", ".join(str(p) for p in paths)


def unreadable(names: str, err: BaseException) -> str:
    """One line: which files could not be read as a bag and what rosbags said (its messages can
    span lines, a YAML parser's for one; builtins such as AssertionError can carry no text)."""
    from rosbags.highlevel import AnyReaderError

    text = " ".join(str(err).split())
    if not isinstance(err, AnyReaderError):
        text = f"{type(err).__name__}: {text}" if text else type(err).__name__
    return f"{names}: not a readable ROS 1/ROS 2 bag ({text})"


def did_you_mean(wanted: str, topics: Iterable[str]) -> str:
    """' (did you mean /x?)' for the bag topic closest to ``wanted`` (a topic, with or without its
    leading slash), or '' when none is close: for the errors and warnings about an absent topic."""
    import difflib  # here, not with the module: the reading child imports that on a replay's critical path

    want = "/" + wanted.lstrip("/")
    names = {"/" + t.lstrip("/"): t for t in topics}
    close = difflib.get_close_matches(want, list(names), n=1, cutoff=0.6)
    return f" (did you mean {names[close[0]]}?)" if close else ""


SQLITE_DAMAGE = "database disk image is malformed"  # SQLite's words for a file cut short or overwritten
MCAP_MAGIC = b"\x89MCAP0\r\n"


def _mcap_cut_short(paths: Sequence[Path]) -> bool:
    """An .mcap file that starts as one (its magic) and does not end as one: a recording stopped mid-write."""
    files = [f for p in paths for f in ([p] if p.is_file() else sorted(p.glob("*.mcap"))) if f.suffix == ".mcap"]
    for f in files:
        try:
            with f.open("rb") as fh:
                head = fh.read(len(MCAP_MAGIC))
                fh.seek(max(f.stat().st_size - len(MCAP_MAGIC), 0))
                tail = fh.read()
        except OSError:
            continue
        if head == MCAP_MAGIC and tail != MCAP_MAGIC:
            return True
    return False


def damaged_ros2(names: str, err: BaseException, paths: Sequence[Path] = ()) -> str | None:
    """One plain sentence for a ROS 2 bag whose storage is damaged or cut short (the recorder killed, the disk
    full), naming the tool that recovers it, or None when ``err`` is not that. rosbag's ``reindex`` is ROS 1's
    (an index at the end of the file); a ROS 2 .db3 is an SQLite database and an .mcap file has its own tool."""
    if SQLITE_DAMAGE in str(err):
        return (f"{names}: the ROS 2 bag's SQLite file is damaged or cut short (recording stopped mid-write), so it "
                "cannot be replayed as it is; copy out every row it still reads with `sqlite3 IN.db3 .dump | sed "
                "'s/^ROLLBACK;.*/COMMIT;/' | sqlite3 OUT.db3` (the dump ends in ROLLBACK where the file breaks) and "
                "replay OUT.db3 itself (no metadata.yaml needed; `ros2 bag reindex` writes one for ROS 2 tools)")
    if _mcap_cut_short(paths):
        return (f"{names}: the ROS 2 bag's MCAP file is cut short (recording stopped mid-write, no footer), so it "
                "cannot be replayed as it is; `mcap recover IN.mcap -o OUT.mcap` (the mcap CLI) rewrites what "
                "survives, then replay OUT.mcap")
    return None


def _repair_hint(paths: Sequence[Path], err: Exception) -> str:
    """How to repair a ROS 1 bag whose index is damaged (a recording cut short: the recorder killed,
    the disk full): ROS 1 keeps the index at the end of the file, and ``rosbag reindex`` rebuilds it."""
    if any(p.suffix == ".bag" for p in paths) and "index" in str(err).lower():
        return ("; a ROS 1 recording cut short (recorder killed, disk full) has no index at its end: "
                "`rosbag reindex FILE.bag` rebuilds it (ROS 1 tools), then replay the repaired file")
    return ""


def _opened(paths: Sequence[Path], default: Typestore | None, names: str = "") -> AnyReader:
    """An open AnyReader; BagError when the files cannot be read, naming them ``names`` (default: ``paths``).
    Types come from the bag's own definitions; ``default`` (the Humble store, ~70 ms to build) only for a
    bag that has none."""
    names = names or _names(paths)
    from rosbags.highlevel import AnyReader, AnyReaderError

    try:
        reader = AnyReader(list(paths), default_typestore=default)
        reader.open()
    except Exception as err:  # noqa: BLE001 - on garbage rosbags raises builtins too (UnicodeDecodeError
        # on a PNG named .bag, AssertionError on a damaged ROS 1 index, FileNotFoundError without metadata)
        if default is None and isinstance(err, AnyReaderError) and not damaged_ros2("", err):
            raise
        raise BagError(damaged_ros2(names, err, paths)
                       or unreadable(names, err) + _repair_hint(paths, err)) from None
    return reader


def _select(reader: AnyReader, sensors: Sequence[SensorConfig]
            ) -> tuple[dict[str, tuple[SensorConfig, list[Connection]]], list[str]]:
    topics = reader.topics
    selected: dict[str, tuple[SensorConfig, list[Connection]]] = {}
    missing: list[str] = []
    for sensor in sensors:
        kind = sensor_kind(sensor)
        if kind not in KINDS:
            raise BagError(f"sensor {sensor.name!r}: kind {kind!r} is not a registered sensor kind")
        topic = next((t for t in ("/" + sensor.key, sensor.key) if t in topics), None)
        if topic is None:
            missing.append(sensor.name)
            continue
        want = expected(sensor)[0]
        found = {c.msgtype for c in topics[topic].connections if not same_definition(c, want, reader.is2)}
        if found and found != {want}:
            hint = " (set its msgtype)" if len(KINDS[kind].ros_types) > 1 else ""
            raise BagError(
                f"topic {topic} (sensor {sensor.name!r}) has type {', '.join(sorted(found))}, "
                f"expected {want} for {'an' if kind[0] in 'aeiou' else 'a'} {kind} sensor{hint}"
            )
        selected[topic] = (sensor, list(topics[topic].connections))
    if not selected:
        wanted = ", ".join("/" + s.key for s in sensors) or "(no sensors configured)"
        have = ", ".join(f"{t} [{i.msgtype}]" for t, i in topics.items()) or "none"
        raise BagError(f"none of the configured topics is in the bag: wanted {wanted}; the bag has {have}")
    return selected, missing


@lru_cache(maxsize=None)
def _ros1_digest(msgtype: str) -> str | None:
    """The ROS 1 MD5 sum of ``msgtype`` in ROS 1 Noetic's definitions (None for a type it does not know),
    computed once a type: ``fusiond info`` asks it of every topic of an unknown type."""
    from rosbags.typesys import Stores, get_typestore
    from rosbags.typesys.base import TypesysError

    try:
        return get_typestore(Stores.ROS1_NOETIC).generate_msgdef(msgtype, ros_version=1)[1]
    except TypesysError:
        return None


def same_definition(connection: Connection, want: str, ros2: bool) -> bool:
    """A ROS 1 connection of another type name whose definition is ``want``'s: its MD5 sum (which ROS 1
    computes from the fields, not the name) is ``want``'s in ROS 1 Noetic's definitions. A driver that
    re-registers nav_msgs/Odometry under its own package (``my_msgs/Odometry``) records the same bytes; the
    log says which type the topic is read as. ROS 2's type hash holds the name: no such match there."""
    if ros2 or connection.msgtype == want or not connection.digest or connection.digest != _ros1_digest(want):
        return False
    log.warning("topic_read_as", topic=connection.topic, msgtype=connection.msgtype, read_as=want,
                reason="the same ROS 1 definition (MD5) under another name")
    return True


def open_bag_samples(paths: Sequence[Path | str], sensors: Sequence[SensorConfig]) -> BagSamples:
    """Open bags for the configured sensors; each sensor's topic is "/" + key (or the bare key).

    Raises BagError for a missing or unreadable bag, a topic of the wrong type, or
    when no configured topic is present; sensors without a topic are listed in `.missing`.
    """
    reader = _open_reader([Path(p) for p in paths])
    try:
        selected, missing = _select(reader, sensors)
    except BaseException:
        reader.close()
        raise
    return BagSamples(reader, selected, missing, _names([Path(p) for p in paths]))


def open_reader(paths: Sequence[Path | str]) -> AnyReader:
    """An open rosbags reader of the bags, refused as ``open_bag_samples`` refuses them (BagError, one line);
    for tools that read every topic (``fusiond info`` / ``init``). The caller closes it."""
    return _open_reader([Path(p) for p in paths])


def iter_raw_cdr(paths: Sequence[Path | str], sensors: Sequence[SensorConfig]
                 ) -> Iterator[tuple[int, SensorConfig, bytes]]:
    """(bag time ns, sensor, ROS 2 CDR) in bag order; the bag is closed when the iteration ends."""
    with open_bag_samples(paths, sensors) as bag:
        yield from bag.raw_cdr()
