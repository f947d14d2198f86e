"""Wire formats: bytes on a Zenoh key or in a bag <-> fusiond samples, and the CDR of the outputs.

Its own package below both `transport/` (the live daemon, `fusiond play`) and
`replay/` (bags), so that neither has to import the other to share one
definition of the formats. No Zenoh import here: pure functions over bytes.

- `wire`: ROS type names, payload limit, `DecodeError` and its reasons, stamps.
- `rosbags_cdr`: the rosbags type store; CDR (de)serialisation through it.
- `kind_codec`: `KindCodec`, what the codecs need of a sensor kind, found by name or sample type.
- `builtin_kinds`: the codecs of the odometry and IMU kinds (the GPS's and pose's are their packages').
- `from_ros`: rosbags messages -> samples (live CDR and bags, ROS 1 and 2).
- `cdr_fast_path`: struct reading of Odometry / Imu CDR, rosbags behind it.
- `bag_readers`: the same for a bag's raw messages, ROS 1 included.
- `json_msgpack`: the JSON / msgpack Structs, their decoder and encoder.
- `decoders`: `make_decoder`, one sensor's bytes -> samples, by its kind's codec and encoding.
- `sample_encoders`: samples -> bytes as their sensor publishes them.
- `output_encoders`: the CDR of the fused pose, odometry and position.
- `ros_messages`: TF, diagnostics, set_pose, rmw_zenoh type names and hashes.
"""

from .bag_readers import bag_fast_path, flat_layout
from .decoders import decode_odometry_cdr, decode_pose_cdr, make_decoder, ros_converter, ros_msgtype
from .from_ros import imu_from_ros, odom_from_ros
from .json_msgpack import ImuMessage, OdomMessage
from .kind_codec import KindCodec, codec_named, codec_of
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
from .sample_encoders import encode_imu_sample, encode_odom_sample, encode_sample
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
    "TYPESTORE", "DecodeError", "Decoder", "Encoding", "ImuMessage", "KindCodec", "OdomMessage",
    "Payload", "bag_fast_path", "codec_named", "codec_of", "decode_odometry_cdr", "decode_pose_cdr",
    "encode_imu_sample", "encode_navsat_cdr", "encode_odom_sample", "encode_odometry_cdr",
    "encode_pose_cdr", "encode_sample", "flat_layout", "imu_from_ros", "make_decoder",
    "odom_from_ros", "ros_converter", "ros_msgtype", "stamp_to_ros", "typestore",
    "DIAGNOSTIC_ARRAY", "ERROR", "OK", "TF_MESSAGE", "WARN", "DiagnosticStatus", "SetPose", "SetPoseMessage",
    "check_set_pose", "dds_type_name", "decode_set_pose", "encode_diagnostic_array_cdr", "encode_tf_cdr", "encode_tf_tree_cdr",
    "type_hash",
]


def __getattr__(name: str) -> object:
    """`TYPESTORE`: the Humble type store, built when first asked for (see `typestore`)."""
    if name == "TYPESTORE":
        return typestore()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
