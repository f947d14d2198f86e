"""The codecs of the odometry and IMU kinds (``KindCodec``), written in this package beside the struct
fast paths they use (``cdr_fast_path``, and ``bag_readers`` for a bag's raw messages); registered when
the codecs load, so that finding them imports nothing of the core. A kind whose codecs live in its
own package (the GPS's, the pose's) is found through its descriptor instead
(``kind_codec.codec_named``).
"""

from __future__ import annotations

from typing import Final

from fusiond.samples import ImuSample, OdomSample

from .cdr_fast_path import ImuFields, OdomFields
from .from_ros import imu_from_ros, odom_from_ros
from .json_msgpack import ImuMessage, OdomMessage, imu_from_message, odom_from_message
from .kind_codec import KindCodec, register_codec
from .sample_encoders import encode_imu_sample, encode_odom_sample
from .wire import IMU, ODOMETRY

# Odometry and IMU run at up to 1 kHz: the struct fast path reads them (``repeated``).
ODOM: Final = register_codec(KindCodec(
    "odom", OdomSample, (ODOMETRY,), odom_from_ros, lambda s, encoding, _: encode_odom_sample(s, encoding),
    OdomMessage, odom_from_message, (True, OdomFields), OdomSample("", 0.0, (0.0,) * 3, (0.0,) * 3, (0.0,) * 36)))
IMU_CODEC: Final = register_codec(KindCodec(
    "imu", ImuSample, (IMU,), imu_from_ros, lambda s, encoding, _: encode_imu_sample(s, encoding),
    ImuMessage, imu_from_message, (False, ImuFields),
    ImuSample("", 0.0, (0.0, 0.0, 0.0, 1.0), (0.0,) * 9, (0.0,) * 3, (0.0,) * 9)))

__all__ = ["IMU_CODEC", "ODOM"]
