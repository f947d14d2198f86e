"""Samples -> bytes as their sensor would publish them, in any of the three encodings, by their kind's codec
(``KindCodec.encode``, in the kind's package, handed in by the caller).

The inverse of the decoders: `fusiond play` publishes bags with it, the benchmarks and the tests build their
inputs with it, and the decoders warm rosbags' serialisers on its output.
"""

from __future__ import annotations

from fusiond.samples import Sample

from .kind_codec import KindCodec


def encode_with(codec: KindCodec, sample: Sample, encoding: str, msgtype: str | None = None) -> bytes:
    """``sample`` as its sensor would publish it, by its kind's ``codec`` (``msgtype``: the ROS type of a kind
    that reads several, a pose sensor's; its kind's first by default)."""
    if codec.encode is None:
        raise ValueError(f"sensor kind {codec.name!r} has no encoder")
    return codec.encode(sample, encoding, msgtype or codec.ros_types[0])


__all__ = ["encode_with"]
