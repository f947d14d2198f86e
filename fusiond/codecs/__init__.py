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

from .bag_readers import bag_fast_path, flat_layout
from .decoders import decode_odometry_cdr, decode_pose_cdr, decoder_for, ros_msgtype
from .kind_codec import KindCodec
from .output_encoders import encode_navsat_cdr, encode_odometry_cdr, encode_pose_cdr
from .ros_messages import (
    DIAGNOSTIC_ARRAY,
    ERROR,
    OK,
    TF_MESSAGE,
    WARN,
    DiagnosticStatus,
    SetPose,
    SetPoseMessage,
    check_set_pose,
    dds_type_name,
    decode_set_pose,
    encode_diagnostic_array_cdr,
    encode_tf_cdr,
    encode_tf_tree_cdr,
    type_hash,
)
from .rosbags_cdr import typestore
from .sample_encoders import encode_with
from .wire import (
    IMU,
    MAX_PAYLOAD,
    NAVSATFIX,
    ODOMETRY,
    POSE_COV_STAMPED,
    POSE_STAMPED,
    REASONS,
    DecodeError,
    Decoder,
    Encoding,
    Payload,
    stamp_to_ros,
)

__all__ = [
    "IMU", "MAX_PAYLOAD", "NAVSATFIX", "ODOMETRY", "POSE_COV_STAMPED", "POSE_STAMPED", "REASONS",
    "TYPESTORE", "DecodeError", "Decoder", "Encoding", "KindCodec",
    "Payload", "bag_fast_path", "decode_odometry_cdr", "decode_pose_cdr", "decoder_for",
    "encode_navsat_cdr", "encode_odometry_cdr",
    "encode_pose_cdr", "encode_with", "flat_layout",
    "ros_msgtype", "stamp_to_ros", "typestore",
    "DIAGNOSTIC_ARRAY", "ERROR", "OK", "TF_MESSAGE", "WARN", "DiagnosticStatus", "SetPose", "SetPoseMessage",
    "check_set_pose", "dds_type_name", "decode_set_pose", "encode_diagnostic_array_cdr", "encode_tf_cdr", "encode_tf_tree_cdr",
    "type_hash",
]


def __getattr__(name: str) -> object:
    """`TYPESTORE`: the Humble type store, built when first asked for (see `typestore`)."""
    if name == "TYPESTORE":
        return typestore()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
