"""What the codecs need of a sensor kind (``KindCodec``), handed to them by their caller.

A kind owns its wire formats: its sample's ROS converter, its JSON / msgpack Struct, its encoder and,
for a kind read a thousand times a second, its struct fast path. The kind's package declares them in a
``KindCodec`` its descriptor returns from ``SensorKind.codec()``, imported only when a decoder is first
asked for, so that the fusion core loads without the codecs. The codecs here are generic over
``KindCodec``: ``decoders.decoder_for`` and ``sample_encoders.encode_with`` take one and read no table of
kinds.

Finding a kind's codec by its name or its sample's type is the registry's business, a floor above
(``fusiond.core.sensors.formats``): this package imports nothing of the core, at load or in a function, so
that the kinds' packages may import it without an import circle.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .cdr_fast_path import Fields

__all__ = ["KindCodec", "TailFields"]

# the base types of a message's fields after its Header, in wire order (``bag_readers.flat_layout``'s names),
# and (their values, the stamp, the sensor's name) -> the sample
TailFields = tuple[tuple[str, ...], Callable[[tuple[Any, ...], float, str], Any]]


@dataclass(frozen=True, slots=True)
class KindCodec:
    """One sensor kind's wire formats.

    - ``name``: the kind's `kind` tag; ``sample_type``: the sample it decodes to.
    - ``ros_types``: the ROS types it reads, the first the default (a kind of several lets its sensor pick).
    - ``from_ros``: (rosbags message of a ROS 1 or ROS 2 store, sensor name) -> sample.
    - ``encode``: (sample, encoding, ROS type) -> bytes as its sensor publishes them; None: no encoder.
    - ``message_type``, ``from_message``: the JSON / msgpack Struct and (Struct, sensor) -> sample;
      None: the kind reads ros2-cdr only.
    - ``repeated``: (has child_frame_id?, the float64 block's reader class, a ``cdr_fast_path.Fields``) of
      the struct fast path of its first ROS type (a Header, that child_frame_id, one run of float64s), for
      a kind read at the daemon's highest rates; None: rosbags reads it.
    - ``zero``: a sample whose CDR ``encode`` makes, to generate rosbags' deserialisers at start-up.
    - ``tail``: (``TailFields``) for a first ROS type that is a Header then fixed-size base fields, which a
      bag replay then reads by struct (``bag_readers``), not through rosbags: faster, and without rosbags'
      numpy arrays (a replay's reading child imports numpy only for its doctor: ``replay.read_ahead``);
      None: rosbags reads it.
    """

    name: str
    sample_type: type
    ros_types: tuple[str, ...]
    from_ros: Callable[[Any, str], Any]
    encode: Callable[[Any, str, str], bytes] | None = None
    message_type: type | None = None
    from_message: Callable[[Any, str], Any] | None = None
    repeated: tuple[bool, type[Fields]] | None = None
    zero: Any = None
    tail: TailFields | None = None
