"""Every reason code a sample can be dropped or rejected for, in one place.

These strings are stable counter names: they key `SensorStats.dropped`, health's
`dropped_by_reason`, the `sample_dropped` log event and the doctor's advice, so an
operator's dashboards and alerts depend on them. Code raises and counts them through
these constants, never as literals; ``MEANINGS`` says what each one means.
"""

from __future__ import annotations

from typing import Final

# -- the fusion core: a decoded sample it will not apply ------------------------------------------
UNKNOWN_SENSOR: Final = "unknown_sensor"
INVALID_STAMP: Final = "invalid_stamp"
STALE_STAMP: Final = "stale_stamp"
FUTURE_STAMP: Final = "future_stamp"
DUPLICATE_STAMP: Final = "duplicate_stamp"
TOO_OLD: Final = "too_old"
HELD_TIME_JUMP: Final = "held_time_jump"  # not a drop: held until its timeline is confirmed or left
WRONG_TYPE: Final = "wrong_type"  # also a payload of another ROS type (codec)

# -- the sensor policies: a sample whose values cannot be fused ------------------------------------
NON_FINITE: Final = "non_finite"
IMPLAUSIBLE_VALUE: Final = "implausible_value"
BAD_COVARIANCE: Final = "bad_covariance"
NEGATIVE_COVARIANCE: Final = "negative_covariance"
ZERO_QUATERNION: Final = "zero_quaternion"
NON_UNIT_QUATERNION: Final = "non_unit_quaternion"
NOTHING_TO_FUSE: Final = "nothing_to_fuse"
NO_FIX: Final = "no_fix"

# -- the daemon and the codecs: a payload that never became a sample --------------------------------
QUEUE_FULL: Final = "queue_full"
EMPTY_PAYLOAD: Final = "empty_payload"
OVERSIZED: Final = "oversized"
CDR_INVALID: Final = "cdr_invalid"
JSON_INVALID: Final = "json_invalid"
MSGPACK_INVALID: Final = "msgpack_invalid"
SCHEMA_INVALID: Final = "schema_invalid"

MEANINGS: Final[dict[str, str]] = {
    UNKNOWN_SENSOR: "the sample names no configured sensor",
    INVALID_STAMP: "the header stamp is zero, negative or not finite",
    STALE_STAMP: "more than jump_s behind filter time, held, then left by the stream (a clock glitch)",
    FUTURE_STAMP: "more than jump_s ahead of filter time, held, then left by the stream (a clock glitch)",
    HELD_TIME_JUMP: "not a drop (yet): far from filter time, held until jump_confirm samples over jump_persist_s "
                    "confirm a new timeline (then applied) or the stream goes on along the old one (then dropped)",
    DUPLICATE_STAMP: "this sensor already had a sample with this exact stamp",
    TOO_OLD: "older than the late-data history (history_s / history_max): cannot be placed",
    WRONG_TYPE: "the message is not of the sensor's configured type",
    NON_FINITE: "a NaN or infinite value in what would be fused",
    IMPLAUSIBLE_VALUE: "a value beyond any real robot (speed, rate, position or geodetic range)",
    BAD_COVARIANCE: "a covariance array of the wrong length or with non-finite entries",
    NEGATIVE_COVARIANCE: "a negative variance on the diagonal",
    ZERO_QUATERNION: "an orientation quaternion of zero norm",
    NON_UNIT_QUATERNION: "an orientation quaternion whose norm is far from 1",
    NOTHING_TO_FUSE: "every component of the message is marked not measured or is disabled",
    NO_FIX: "a GPS message without a fix (NavSatStatus below STATUS_FIX)",
    QUEUE_FULL: "the daemon's input queue was full: the newest sample was dropped (overload)",
    EMPTY_PAYLOAD: "a Zenoh sample with no bytes",
    OVERSIZED: "a payload above the codec's size limit, rejected before parsing",
    CDR_INVALID: "bytes that do not deserialize as the expected ROS 2 CDR message",
    JSON_INVALID: "bytes that are not valid JSON",
    MSGPACK_INVALID: "bytes that are not valid MessagePack",
    SCHEMA_INVALID: "JSON/MessagePack that does not have the sample's fields and types",
}
"""Reason code -> one-line meaning (README and the monitor may show it)."""

ALL: Final = tuple(MEANINGS)
