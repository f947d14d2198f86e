"""Wire formats: bytes on a Zenoh key or in a bag <-> fusiond samples, and the CDR of the outputs.

Its own package below both `transport/` (the live daemon, `fusiond play`) and
`replay/` (bags), so that neither has to import the other to share one
definition of the formats. No Zenoh import here: pure functions over bytes.

- `wire`: ROS type names, payload limit, `DecodeError` and its reasons, stamps.
- `rosbags_cdr`: the rosbags type store; CDR (de)serialisation through it.
- `kind_codec`: `KindCodec`, what the codecs need of a sensor kind. Each kind declares its own (ROS
  converter, JSON / msgpack Struct, encoder, struct fast path) in its package's `codec` module under
  `fusiond/core/sensors/`, and every function here takes one from its caller: nothing here names or looks up
  a kind, and nothing here imports the core (finding a kind's codec by its name or its sample's type is
  `fusiond.core.sensors.formats`).
- `cdr_fast_path`: struct reading of a Header + float64-block message's CDR, rosbags behind it.
- `bag_readers`: the same for a bag's raw messages, ROS 1 included.
- `json_msgpack`: the decoder and encoder of a kind's JSON / msgpack Struct.
- `decoders`: `decoder_for`, one sensor's bytes -> samples, by its kind's codec and encoding.
- `sample_encoders`: `encode_with`, samples -> bytes as their sensor publishes them, by their kind's codec.
- `output_encoders`: the CDR of the fused pose, odometry and position.
- `ros_messages`: TF, diagnostics, set_pose, rmw_zenoh type names and hashes.
"""

from __future__ import annotations

from ..lazy_exports import lazy_exports

# public name -> the module of this package that defines it, imported on first use: a bag's decoding needs
# neither numpy nor the encoders (a replay's reading child opens its bags without them)
_EXPORTS = {
    "bag_fast_path": "bag_readers",
    "flat_layout": "bag_readers",
    "decode_odometry_cdr": "decoders",
    "decode_pose_cdr": "decoders",
    "decoder_for": "decoders",
    "ros_msgtype": "decoders",
    "KindCodec": "kind_codec",
    "encode_navsat_cdr": "output_encoders",
    "encode_odometry_cdr": "output_encoders",
    "encode_pose_cdr": "output_encoders",
    "DIAGNOSTIC_ARRAY": "ros_messages",
    "ERROR": "ros_messages",
    "OK": "ros_messages",
    "TF_MESSAGE": "ros_messages",
    "WARN": "ros_messages",
    "DiagnosticStatus": "ros_messages",
    "SetPose": "ros_messages",
    "SetPoseMessage": "ros_messages",
    "check_set_pose": "ros_messages",
    "dds_type_name": "ros_messages",
    "decode_set_pose": "ros_messages",
    "encode_diagnostic_array_cdr": "ros_messages",
    "encode_tf_cdr": "ros_messages",
    "encode_tf_tree_cdr": "ros_messages",
    "type_hash": "ros_messages",
    "typestore": "rosbags_cdr",
    "encode_with": "sample_encoders",
    "IMU": "wire",
    "MAX_PAYLOAD": "wire",
    "NAVSATFIX": "wire",
    "ODOMETRY": "wire",
    "POSE_COV_STAMPED": "wire",
    "POSE_STAMPED": "wire",
    "REASONS": "wire",
    "DecodeError": "wire",
    "Decoder": "wire",
    "Encoding": "wire",
    "Payload": "wire",
    "stamp_to_ros": "wire",
}

__all__, _exported, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
__all__ = sorted([*__all__, "TYPESTORE"])


def __getattr__(name: str) -> object:
    """A public name, imported from its module when first read; `TYPESTORE`: the Humble type store, built
    when first asked for (see `typestore`)."""
    if name == "TYPESTORE":
        from .rosbags_cdr import typestore

        return typestore()
    return _exported(name)
