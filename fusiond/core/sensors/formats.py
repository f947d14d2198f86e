"""A sensor kind's wire formats found by the kind's name or its sample's type: the registry's side of the codecs.

``fusiond.codecs`` is generic over ``KindCodec`` and imports nothing of the core, since the kinds' own
``codec`` modules import it; what names a kind, or asks which kind a sample is of, sits here beside the
registry that knows them. ``make_decoder`` and ``encode_sample`` are the codecs' ``decoder_for`` and
``encode_with`` behind that look-up (a sensor's `kind` tag, or the sample being encoded).

The codecs (and rosbags behind them) are imported inside each function, as ``SensorKind.decoder`` does, so
that the fusion core, which imports this package, loads without them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...samples import Sample
from .kind import SensorKind
from .registry import KINDS, kind_named

if TYPE_CHECKING:
    from ...codecs.kind_codec import KindCodec
    from ...codecs.wire import Decoder

_BY_SAMPLE: dict[type, tuple[SensorKind, "KindCodec"]] = {}  # sample type -> (its kind's descriptor, its codec)


def codec_named(name: str) -> "KindCodec":
    """The codec of the kind ``name`` (``SensorKind.codec``); a ValueError for a kind that is not registered,
    or offers no codec."""
    found = kind_named(name).codec()
    if found is None:
        raise ValueError(f"sensor kind {name!r} offers no codec")
    return found


def codec_of(sample: object) -> "KindCodec":
    """The codec of the kind whose sample ``sample`` is (its exact type); a ValueError for another.

    Asked once a sample by ``encode_sample`` (`fusiond play` re-encoding a bag): the answer is kept by
    sample type while the kind that gave it stays registered under its name."""
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


def make_decoder(kind: "str | KindCodec", encoding: str, sensor: str, *, msgtype: str | None = None) -> "Decoder":
    """The bytes -> sample function of one sensor of ``kind`` (its name, or its ``KindCodec``); it raises
    only DecodeError (``codecs.decoders.decoder_for``: ``msgtype`` picks the ROS type of a kind that reads
    several). An unknown kind or encoding is a ValueError at construction: a configuration bug, not a bad
    message."""
    from ...codecs.decoders import decoder_for
    from ...codecs.kind_codec import KindCodec

    codec = kind if isinstance(kind, KindCodec) else codec_named(kind)
    return decoder_for(codec, encoding, sensor, msgtype=msgtype)


def encode_sample(sample: Sample, encoding: str, msgtype: str | None = None) -> bytes:
    """Any sample as its sensor would publish it, by its kind's codec (``msgtype``: the ROS type of a kind
    that reads several, a pose sensor's; its kind's first by default)."""
    from ...codecs.sample_encoders import encode_with

    return encode_with(codec_of(sample), sample, encoding, msgtype)


__all__ = ["codec_named", "codec_of", "encode_sample", "make_decoder"]
