"""The JSON / msgpack wire format of the sensors: the decoder of a sensor's JSON or msgpack key given its
kind's Struct, the encoding of a Struct as either, and the field types the kinds' Structs share.

For sensors that do not speak ROS 2 CDR: the ROS fields flattened into one object per message, `stamp` in
seconds. Each kind declares its Struct in its package's ``codec`` (``fusiond/core/sensors/*/codec.py``);
their docstrings are the format's documentation (README points there).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Annotated, Any

import msgspec

from fusiond.samples import Sample

from .wire import Decoder, DecodeError, Payload, check_size

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]
Cov9 = Annotated[tuple[float, ...], msgspec.Meta(min_length=9, max_length=9)]
Cov36 = Annotated[tuple[float, ...], msgspec.Meta(min_length=36, max_length=36)]


def structured_decoder(wire_type: type, from_message: Callable[[Any, str], Sample], encoding: str,
                       sensor: str) -> Decoder:
    """The bytes -> sample function of a sensor whose kind's Struct is ``wire_type`` (made a sample by
    ``from_message``) on a `json` or `msgpack` key; it raises only DecodeError. Another encoding is a
    ValueError."""
    if encoding == "json":
        parser: Any = msgspec.json.Decoder(wire_type)
        syntax = "json_invalid"
    elif encoding == "msgpack":
        parser = msgspec.msgpack.Decoder(wire_type)
        syntax = "msgpack_invalid"
    else:
        raise ValueError(f"unknown encoding {encoding!r}, expected ros2-cdr, json or msgpack")

    def decode_structured(payload: Payload) -> Sample:
        check_size(payload)
        try:
            message = parser.decode(payload)
        except msgspec.ValidationError as exc:
            raise DecodeError("schema_invalid", str(exc)) from None
        except msgspec.DecodeError as exc:
            raise DecodeError(syntax, str(exc)) from None
        if not math.isfinite(message.stamp):
            raise DecodeError("schema_invalid", f"stamp must be finite, got {message.stamp}")
        return from_message(message, sensor)

    return decode_structured


_json_encoder = msgspec.json.Encoder()
_msgpack_encoder = msgspec.msgpack.Encoder()


def encode_structured(message: msgspec.Struct, encoding: str) -> bytes:
    """``message`` as ``encoding`` (`json` or `msgpack`; another is a ValueError)."""
    if encoding == "json":
        return _json_encoder.encode(message)
    if encoding == "msgpack":
        return _msgpack_encoder.encode(message)
    raise ValueError(f"unknown encoding {encoding!r}, expected ros2-cdr, json or msgpack")


__all__ = ["Cov9", "Cov36", "Quat", "Vec3", "encode_structured", "structured_decoder"]
