"""The GPS kind's wire formats (``CODEC``, a ``fusiond.codecs.KindCodec``): sensor_msgs/NavSatFix read
from a bag or from ROS 2 CDR through rosbags, its JSON / msgpack Struct (``GpsMessage``), and its encoder
(``encode_gps_sample``).

Imported only when a decoder or encoder of a GPS is first asked for (``GpsKind.codec``), so that the
fusion core loads without the codecs and rosbags. rosbags' generic path reads a fix on the wire (a GPS runs
at 1-100 Hz); a bag's fixes are read by struct (``KindCodec.tail``): a third of rosbags' time, and no
numpy (rosbags makes the covariance a numpy array), which a replay's reading child imports only for its
doctor (``replay.read_ahead``).
"""

from __future__ import annotations

from typing import Any, Final

import msgspec

from ....codecs.json_msgpack import Cov9, encode_structured
from ....codecs.kind_codec import KindCodec
from ....codecs.rosbags_cdr import float_array, ros_header, ros_types, serialize
from ....codecs.wire import NAVSATFIX
from .sample import GpsSample


class GpsMessage(msgspec.Struct, kw_only=True):
    """A GPS fix on a `json` or `msgpack` key (sensor_msgs/NavSatFix's fields).

    - `stamp`: seconds; `latitude`, `longitude` in degrees (WGS84), `altitude` in m.
    - `status`: NavSatStatus.status (-1 no fix: skipped and counted; default 0).
    - `position_covariance`: 9 numbers, row-major ENU, m^2 (default zeros), and
      `position_covariance_type` (0 unknown, default; 1 approximated; 2 diagonal; 3 known).
    """

    stamp: float
    latitude: float
    longitude: float
    altitude: float = 0.0
    status: int = 0
    position_covariance: Cov9 = (0.0,) * 9
    position_covariance_type: int = 0


def gps_from_ros(msg: Any, sensor: str) -> GpsSample:
    """A rosbags sensor_msgs/msg/NavSatFix (ROS 1 or ROS 2 typestore) as a GpsSample."""
    stamp = msg.header.stamp
    return GpsSample(
        sensor, stamp.sec + stamp.nanosec * 1e-9, float(msg.latitude), float(msg.longitude), float(msg.altitude),
        int(msg.status.status), tuple(msg.position_covariance.tolist()), int(msg.position_covariance_type),
    )


# NavSatFix after its Header: status.status, status.service, latitude, longitude, altitude, the covariance,
# its type
NAVSATFIX_TAIL: Final = ("int8", "uint16", *("float64",) * 12, "uint8")


def gps_from_tail(values: tuple[Any, ...], stamp: float, sensor: str) -> GpsSample:
    """A NavSatFix's fields after its Header (``NAVSATFIX_TAIL``), read by struct from a bag, as the
    GpsSample ``gps_from_ros`` makes of the same message."""
    return GpsSample(sensor, stamp, values[2], values[3], values[4], values[0], values[5:14], values[14])


def gps_from_message(m: GpsMessage, sensor: str) -> GpsSample:
    """A decoded ``GpsMessage`` as a GpsSample."""
    return GpsSample(sensor, m.stamp, m.latitude, m.longitude, m.altitude, m.status, m.position_covariance,
                     m.position_covariance_type)


def encode_gps_sample(sample: GpsSample, encoding: str, msgtype: str = NAVSATFIX) -> bytes:
    """What a GPS driver puts on the key (CDR: sensor_msgs/msg/NavSatFix, frame gps)."""
    if encoding == "ros2-cdr":
        T = ros_types()
        msg = T[NAVSATFIX](
            header=ros_header(sample.stamp, "gps"),
            status=T["sensor_msgs/msg/NavSatStatus"](status=int(sample.status), service=1),
            latitude=float(sample.latitude), longitude=float(sample.longitude), altitude=float(sample.altitude),
            position_covariance=float_array(sample.position_covariance, 9),
            position_covariance_type=int(sample.covariance_type),
        )
        return serialize(msg, NAVSATFIX)
    return encode_structured(
        GpsMessage(stamp=sample.stamp, latitude=sample.latitude, longitude=sample.longitude,
                   altitude=sample.altitude, status=sample.status, position_covariance=sample.position_covariance,
                   position_covariance_type=sample.covariance_type),
        encoding,
    )


CODEC = KindCodec("gps", GpsSample, (NAVSATFIX,), gps_from_ros, encode_gps_sample, GpsMessage, gps_from_message,
                  None, GpsSample("", 0.0, 0.0, 0.0, 0.0), (NAVSATFIX_TAIL, gps_from_tail))

__all__ = ["CODEC", "NAVSATFIX_TAIL", "GpsMessage", "encode_gps_sample", "gps_from_message", "gps_from_ros",
           "gps_from_tail"]
