"""What the codecs need of a sensor kind (``KindCodec``), and where they find it: by the kind's name
(``codec_named``) or by its sample's type (``codec_of``).

A kind owns its wire formats: its sample's ROS converter, its JSON / msgpack Struct, its encoder and,
for a kind read a thousand times a second, its struct fast path. The kind's package declares them in a
``KindCodec`` its descriptor returns from ``SensorKind.codec()``, imported only when a decoder is first
asked for, so that the fusion core loads without the codecs. The codecs here are generic over
``KindCodec``: ``decoders.make_decoder`` and ``sample_encoders.encode_sample`` read no table of kinds.

Every kind's codec is the registry's to name: ``codec_named`` and ``codec_of`` ask the kind's descriptor
when first asked, as the kinds import the codecs only when asked for a decoder. Nothing of the core is
imported when this package loads.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .cdr_fast_path import Fields

__all__ = ["KindCodec", "codec_named", "codec_of"]


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


_BY_SAMPLE: dict[type, tuple[object, KindCodec]] = {}  # sample type -> (its kind's descriptor, its codec)


def codec_named(name: str) -> KindCodec:
    """The codec of the kind ``name`` (``SensorKind.codec``); a ValueError for a kind that is not registered,
    or offers no codec."""
    from ..core.sensors.registry import kind_named  # the kind's package declares it: asked when first needed

    found = kind_named(name).codec()
    if found is None:
        raise ValueError(f"sensor kind {name!r} offers no codec")
    return found


def codec_of(sample: object) -> KindCodec:
    """The codec of the kind whose sample ``sample`` is (its exact type); a ValueError for another.

    Asked once a sample by ``encode_sample`` (`fusiond play` re-encoding a bag): the answer is kept by
    sample type while the kind that gave it stays registered under its name."""
    from ..core.sensors.registry import KINDS  # the kind's package declares it: asked when first needed

    sample_type = type(sample)
    kept = _BY_SAMPLE.get(sample_type)
    if kept is not None and KINDS.get(kept[1].name) is kept[0]:
        return kept[1]
    for described in list(KINDS.values()):
        if described.sample_type is sample_type:
            codec = described.codec()
            if codec is not None:
                _BY_SAMPLE[sample_type] = (described, codec)
                return codec
    raise ValueError(f"no sensor kind's codec encodes a {sample_type.__name__}")
