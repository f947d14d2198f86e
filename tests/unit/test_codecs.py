"""Codecs against rosbags itself: roundtrips, rounding of stamps, and hostile payloads."""

from __future__ import annotations

import math
import struct

import msgspec
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fusiond.core.sensors import ImuSample, OdomSample, encode_sample, make_decoder
from fusiond.codecs import (
    IMU,
    MAX_PAYLOAD,
    ODOMETRY,
    POSE_COV_STAMPED,
    REASONS,
    TYPESTORE,
    DecodeError,
    decode_odometry_cdr,
    decode_pose_cdr,
    encode_odometry_cdr,
    encode_pose_cdr,
    stamp_to_ros,
)
from fusiond.core.sensors.imu.codec import imu_from_ros
from fusiond.core.sensors.odom.codec import odom_from_ros

KINDS = ("odom", "imu")
ENCODINGS = ("ros2-cdr", "json", "msgpack")
FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
stamps = st.floats(min_value=0.0, max_value=2.0e9, allow_nan=False)


def _vec(n: int) -> st.SearchStrategy[tuple[float, ...]]:
    return st.tuples(*[finite] * n)


odom_samples = st.builds(
    OdomSample, sensor=st.just("wheel"), stamp=stamps, linear=_vec(3), angular=_vec(3),
    twist_covariance=_vec(36), position=_vec(3), orientation=_vec(4),
)
imu_samples = st.builds(
    ImuSample, sensor=st.just("imu"), stamp=stamps, orientation=_vec(4), orientation_covariance=_vec(9),
    angular_velocity=_vec(3), angular_velocity_covariance=_vec(9), linear_acceleration=_vec(3),
    linear_acceleration_covariance=_vec(9),
)


def _odom(stamp: float = 12.5) -> OdomSample:
    return OdomSample("wheel", stamp, (0.4, 0.0, 0.0), (0.0, 0.0, 0.1), tuple(float(i) for i in range(36)),
                      (1.0, 2.0, 0.5), (0.0, 0.0, 0.6, 0.8))


def _imu(stamp: float = 12.5) -> ImuSample:
    return ImuSample("imu", stamp, (0.0, 0.0, 0.6, 0.8), tuple(0.01 * i for i in range(9)), (0.1, -0.2, 0.3),
                     (2.5e-5,) * 9, (0.0, 0.1, 9.8), (0.1,) * 9)


def _same(a: object, b: object) -> bool:
    """Bit-exact equality, NaN included (msgpack keeps float64 bits)."""
    return msgspec.msgpack.encode(a) == msgspec.msgpack.encode(b)


def _assert_roundtrip(decoded: OdomSample | ImuSample, sample: OdomSample | ImuSample, cdr: bool) -> None:
    if cdr:  # CDR carries whole nanoseconds
        assert abs(decoded.stamp - sample.stamp) <= 5e-10 + 2 * math.ulp(sample.stamp)
        decoded = msgspec.structs.replace(decoded, stamp=sample.stamp)
    assert decoded == sample
    for field in decoded.__struct_fields__:
        value = getattr(decoded, field)
        assert type(value) in (str, float, tuple), field
        if isinstance(value, tuple):
            assert all(type(v) is float for v in value), field


# --------------------------------------------------------------------------- roundtrips


@pytest.mark.parametrize("encoding", ENCODINGS)
@given(sample=odom_samples)
@FUZZ
def test_odom_roundtrip(encoding: str, sample: OdomSample) -> None:
    decoded = make_decoder("odom", encoding, "wheel")(encode_sample(sample, encoding))
    _assert_roundtrip(decoded, sample, encoding == "ros2-cdr")


@pytest.mark.parametrize("encoding", ENCODINGS)
@given(sample=imu_samples)
@FUZZ
def test_imu_roundtrip(encoding: str, sample: ImuSample) -> None:
    decoded = make_decoder("imu", encoding, "imu")(encode_sample(sample, encoding))
    _assert_roundtrip(decoded, sample, encoding == "ros2-cdr")


def test_cdr_is_what_rosbags_reads() -> None:
    msg = TYPESTORE.deserialize_cdr(encode_sample(_odom(), "ros2-cdr"), ODOMETRY)
    assert (msg.header.frame_id, msg.child_frame_id) == ("odom", "base_link")
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (12, 500_000_000)
    assert odom_from_ros(msg, "wheel") == _odom()
    imu = TYPESTORE.deserialize_cdr(encode_sample(_imu(), "ros2-cdr"), IMU)
    assert imu.header.frame_id == "base_link"
    assert imu_from_ros(imu, "imu") == _imu()


def test_big_endian_cdr_decodes_too() -> None:
    for kind, sample, msgtype in (("odom", _odom(), ODOMETRY), ("imu", _imu(), IMU)):
        msg = TYPESTORE.deserialize_cdr(encode_sample(sample, "ros2-cdr"), msgtype)
        big = bytes(TYPESTORE.serialize_cdr(msg, msgtype, little_endian=False))
        assert make_decoder(kind, "ros2-cdr", sample.sensor)(big) == sample


def test_pose_output_roundtrip() -> None:
    cov = np.arange(36, dtype=float).reshape(6, 6)
    raw = encode_pose_cdr(101.25, "odom", (1.0, -2.0, 0.25), (0.0, 0.0, 0.6, 0.8), cov)
    assert raw[:4] == b"\x00\x01\x00\x00"
    for msg in (TYPESTORE.deserialize_cdr(raw, POSE_COV_STAMPED), decode_pose_cdr(raw)):
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id) == (101, 250_000_000, "odom")
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        assert (p.x, p.y, p.z) == (1.0, -2.0, 0.25)
        assert (q.x, q.y, q.z, q.w) == (0.0, 0.0, 0.6, 0.8)
        assert msg.pose.covariance.tolist() == cov.reshape(-1).tolist()


def test_odometry_output_roundtrip() -> None:
    pose_cov = [float(i) for i in range(36)]
    twist_cov = np.eye(6) * 0.5
    raw = encode_odometry_cdr(7.000000001, "odom", "base_link", np.array([1.0, 2.0, 3.0]), (0.0, 0.0, 0.0, 1.0),
                              pose_cov, (0.5, 0.0, 0.0), (0.0, 0.0, -0.25), twist_cov)
    for msg in (TYPESTORE.deserialize_cdr(raw, ODOMETRY), decode_odometry_cdr(raw)):
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (7, 1)
        assert (msg.header.frame_id, msg.child_frame_id) == ("odom", "base_link")
        assert msg.pose.covariance.tolist() == pose_cov
        assert msg.twist.covariance.tolist() == twist_cov.reshape(-1).tolist()
        t = msg.twist.twist
        assert (t.linear.x, t.angular.z) == (0.5, -0.25)
    with pytest.raises(ValueError, match="36"):
        encode_pose_cdr(1.0, "odom", (0, 0, 0), (0, 0, 0, 1), [0.0] * 35)


def test_output_decoders_reject_garbage() -> None:
    pose = encode_pose_cdr(1.0, "odom", (0, 0, 0), (0, 0, 0, 1), [0.0] * 36)
    with pytest.raises(DecodeError) as err:
        decode_odometry_cdr(pose)
    assert err.value.reason == "wrong_type"
    with pytest.raises(DecodeError):
        decode_pose_cdr(b"\x00\x01\x00\x00garbage")


# --------------------------------------------------------------------------- stamps


@pytest.mark.parametrize(("stamp", "expected"), [
    (0.0, (0, 0)),
    (1.9999999999, (2, 0)),  # rounds up across the second
    (1.9999999994, (1, 999_999_999)),
    (1.0000000004, (1, 0)),
    (1.0000000006, (1, 1)),
    (47.584, (47, 584_000_000)),
    (-0.5, (-1, 500_000_000)),
    (-1e-10, (0, 0)),
    (1_700_000_000.123456, (1_700_000_000, 123_456_001)),  # nearest ns of the float actually stored
])
def test_stamp_to_ros(stamp: float, expected: tuple[int, int]) -> None:
    assert stamp_to_ros(stamp) == expected


@given(stamp=st.floats(min_value=-2.0**31, max_value=2.0**31 - 1, allow_nan=False))
def test_stamp_to_ros_is_nearest_ns(stamp: float) -> None:
    sec, nanosec = stamp_to_ros(stamp)
    assert 0 <= nanosec < 1_000_000_000
    assert abs((sec - stamp) + nanosec * 1e-9) <= 5e-10 + 2 * math.ulp(stamp)


@pytest.mark.parametrize("stamp", [math.nan, math.inf, -math.inf, 2.0**31, -(2.0**31) - 1])
def test_stamp_to_ros_rejects(stamp: float) -> None:
    with pytest.raises(ValueError):
        stamp_to_ros(stamp)


# --------------------------------------------------------------------------- JSON / msgpack


@pytest.mark.parametrize("encoding", ["json", "msgpack"])
def test_structured_wrong_lengths(encoding: str) -> None:
    enc = msgspec.json.encode if encoding == "json" else msgspec.msgpack.encode
    odom = make_decoder("odom", encoding, "wheel")
    imu = make_decoder("imu", encoding, "imu")
    good_odom = msgspec.to_builtins(msgspec.json.decode(encode_sample(_odom(), "json")))
    good_imu = msgspec.to_builtins(msgspec.json.decode(encode_sample(_imu(), "json")))
    assert odom(enc(good_odom)) == _odom()
    assert imu(enc(good_imu)) == _imu()
    bad = [
        (odom, {**good_odom, "twist_covariance": [0.0] * 35}),
        (odom, {**good_odom, "twist_covariance": [0.0] * 37}),
        (odom, {**good_odom, "linear": [0.0, 0.0]}),
        (odom, {**good_odom, "orientation": [0.0, 0.0, 1.0]}),
        (odom, {k: v for k, v in good_odom.items() if k != "stamp"}),
        (odom, {**good_odom, "stamp": "now"}),
        (imu, {**good_imu, "orientation_covariance": [0.0] * 8}),
        (imu, {**good_imu, "angular_velocity_covariance": [0.0] * 10}),
        (imu, {**good_imu, "linear_acceleration_covariance": []}),
        (imu, {**good_imu, "angular_velocity": [0.0] * 4}),
        (imu, good_odom),
    ]
    for decode, payload in bad:
        with pytest.raises(DecodeError) as err:
            decode(enc(payload))
        assert err.value.reason == "schema_invalid", payload


def test_structured_defaults_and_unknown_fields() -> None:
    raw = b'{"stamp": 3, "linear": [1, 0, 0], "angular": [0, 0, 0], "twist_covariance": [' + b"0," * 35 + b'0], "x": 1}'
    s = make_decoder("odom", "json", "wheel")(raw)
    assert s.stamp == 3.0 and type(s.stamp) is float
    assert (s.position, s.orientation) == ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))


def test_structured_syntax_and_stamp_errors() -> None:
    with pytest.raises(DecodeError) as err:
        make_decoder("odom", "json", "wheel")(b'{"stamp": 1.0,')
    assert err.value.reason == "json_invalid"
    with pytest.raises(DecodeError) as err:
        make_decoder("imu", "msgpack", "imu")(b"\xc1")
    assert err.value.reason == "msgpack_invalid"
    nan_stamp = msgspec.msgpack.encode(msgspec.structs.replace(_odom(), stamp=math.nan))
    with pytest.raises(DecodeError) as err:
        make_decoder("odom", "msgpack", "wheel")(nan_stamp)
    assert err.value.reason == "schema_invalid"


# --------------------------------------------------------------------------- hostile payloads


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("encoding", ENCODINGS)
def test_size_limits(kind: str, encoding: str) -> None:
    decode = make_decoder(kind, encoding, "s")
    for payload, reason in ((b"", "empty_payload"), (b"\x00\x01\x00\x00" + bytes(MAX_PAYLOAD), "oversized")):
        with pytest.raises(DecodeError) as err:
            decode(payload)
        assert err.value.reason == reason


def test_unknown_kind_or_encoding_is_a_config_error() -> None:
    with pytest.raises(ValueError, match="kind"):
        make_decoder("lidar", "json", "s")  # not a registered kind
    with pytest.raises(ValueError, match="encoding"):
        make_decoder("odom", "cbor", "s")


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("encoding", ENCODINGS)
@given(payload=st.binary(max_size=800))
@FUZZ
def test_random_bytes_raise_only_decode_error(kind: str, encoding: str, payload: bytes) -> None:
    decode = make_decoder(kind, encoding, "s")
    try:
        decode(payload)
    except DecodeError as err:
        assert err.reason in REASONS


@pytest.mark.parametrize("kind", KINDS)
@given(payload=st.binary(max_size=800))
@FUZZ
def test_random_cdr_body_raise_only_decode_error(kind: str, payload: bytes) -> None:
    """Past the encapsulation check, so the garbage reaches the rosbags deserialiser."""
    try:
        make_decoder(kind, "ros2-cdr", "s")(b"\x00\x01\x00\x00" + payload)
    except DecodeError as err:
        assert err.reason in ("cdr_invalid", "wrong_type")


@pytest.mark.parametrize(("kind", "raw"), [
    ("odom", encode_sample(_odom(), "ros2-cdr")),
    ("imu", encode_sample(_imu(), "ros2-cdr")),
])
def test_every_truncation_and_trailing_garbage_is_rejected(kind: str, raw: bytes) -> None:
    decode = make_decoder(kind, "ros2-cdr", "s")
    for n in range(len(raw)):
        with pytest.raises(DecodeError):
            decode(raw[:n])
    for extra in (4, 8, 100):
        with pytest.raises(DecodeError) as err:
            decode(raw + b"\x00" * extra)
        assert err.value.reason == "cdr_invalid"
    # Up to 3 bytes of alignment padding are legal CDR (rosbags and DDS accept them).
    assert decode(raw + b"\x00\x00\x00").stamp == 12.5


def test_payload_of_another_type_is_wrong_type() -> None:
    odom_raw = encode_sample(_odom(), "ros2-cdr")
    imu_raw = encode_sample(_imu(), "ros2-cdr")
    for decode, raw, sent in ((make_decoder("odom", "ros2-cdr", "w"), imu_raw, IMU),
                              (make_decoder("imu", "ros2-cdr", "i"), odom_raw, ODOMETRY),
                              (make_decoder("imu", "ros2-cdr", "i"),
                               encode_pose_cdr(1.0, "odom", (0, 0, 0), (0, 0, 0, 1), [0.0] * 36), POSE_COV_STAMPED)):
        with pytest.raises(DecodeError) as err:
            decode(raw)
        assert err.value.reason == "wrong_type"
        assert sent in str(err.value)


def _reference(kind: str, payload: bytes) -> OdomSample | ImuSample | None:
    """The plain rosbags path: deserialize_cdr + *_from_ros, None where rosbags rejects."""
    msgtype, from_ros = (ODOMETRY, odom_from_ros) if kind == "odom" else (IMU, imu_from_ros)
    try:
        msg = TYPESTORE.deserialize_cdr(payload, msgtype)
    except Exception:
        return None
    return from_ros(msg, "s")


@st.composite
def mutated_cdr(draw: st.DrawFn) -> tuple[str, bytes]:
    kind = draw(st.sampled_from(KINDS))
    sample = draw(odom_samples if kind == "odom" else imu_samples)
    frame = draw(st.sampled_from(["", "base_link", "é", "a" * 7]))
    if kind == "odom":
        raw = bytearray(encode_odometry_cdr(sample.stamp, frame, frame[:3], sample.position, sample.orientation,
                                            [0.0] * 36, sample.linear, sample.angular, sample.twist_covariance))
    else:
        raw = bytearray(encode_sample(sample, "ros2-cdr"))
    for _ in range(draw(st.integers(0, 3))):
        raw[draw(st.integers(0, len(raw) - 1))] = draw(st.integers(0, 255))
    cut = draw(st.integers(-4, 4))
    raw = raw[:len(raw) + cut] if cut < 0 else raw + bytes(cut)
    return kind, bytes(raw)


@given(case=mutated_cdr())
@settings(max_examples=400, deadline=None)
def test_decoder_agrees_with_rosbags(case: tuple[str, bytes]) -> None:
    """The struct fast path accepts exactly what rosbags accepts, with identical values."""
    kind, payload = case
    expected = _reference(kind, payload)
    try:
        got = make_decoder(kind, "ros2-cdr", "s")(payload)
    except DecodeError:
        assert expected is None
    else:
        assert expected is not None and _same(got, expected)


def _cdr_of(kind: str, sample: OdomSample | ImuSample, frame: str) -> bytes:
    if kind == "odom":
        return encode_odometry_cdr(sample.stamp, frame, frame[:3], sample.position, sample.orientation,
                                   [0.0] * 36, sample.linear, sample.angular, sample.twist_covariance)
    msg = TYPESTORE.deserialize_cdr(encode_sample(sample, "ros2-cdr"), IMU)  # frame base_link: set another
    msg.header.frame_id = frame
    return bytes(TYPESTORE.serialize_cdr(msg, IMU))


@st.composite
def sensor_stream(draw: st.DrawFn) -> tuple[str, list[bytes]]:
    """What one sensor key carries: mostly payloads of one layout (same frame ids, new values), with
    now and then another frame id, a corrupted byte before the float block, or a cut or padded tail."""
    kind = draw(st.sampled_from(KINDS))
    samples = odom_samples if kind == "odom" else imu_samples
    frames = ["base_link", "imu_link", "é", ""]
    out = []
    for _ in range(draw(st.integers(1, 12))):
        raw = bytearray(_cdr_of(kind, draw(samples), draw(st.sampled_from(frames[:1] * 4 + frames))))
        change = draw(st.sampled_from(["none"] * 4 + ["byte", "cut", "pad"]))
        if change == "byte":  # the identifier, the stamp, a string length, a string, a terminator or padding
            raw[draw(st.integers(0, 40))] = draw(st.integers(0, 255))
        elif change == "cut":
            raw = raw[:-draw(st.integers(1, 4))]
        elif change == "pad":
            raw += bytes(draw(st.integers(1, 4)))
        out.append(bytes(raw))
    return kind, out


@given(case=sensor_stream())
@settings(max_examples=120, deadline=None)
def test_one_decoder_over_a_stream_agrees_with_rosbags(case: tuple[str, list[bytes]]) -> None:
    """A decoder remembers the layout of the last payload it accepted and skips re-checking the frame
    ids of a payload that repeats it (`_RepeatedLayout`): over a stream that mixes repeats, other
    frame ids, corrupted bytes and other lengths, every payload still decodes exactly as rosbags does."""
    kind, payloads = case
    decode = make_decoder(kind, "ros2-cdr", "s")
    for payload in payloads:
        expected = _reference(kind, payload)
        try:
            got = decode(payload)
        except DecodeError:
            assert expected is None
        else:
            assert expected is not None and _same(got, expected)


def test_cdr_header_values_pass_through() -> None:
    """Negative seconds and NaN values are the core's business, not the codec's."""
    raw = bytearray(encode_sample(_imu(), "ros2-cdr"))
    struct.pack_into("<i", raw, 4, -3)
    nan_at = len(raw) - 8
    struct.pack_into("<d", raw, nan_at, math.nan)
    s = make_decoder("imu", "ros2-cdr", "imu")(bytes(raw))
    assert s.stamp == -3 + 0.5
    assert math.isnan(s.linear_acceleration_covariance[-1])


@given(kind=st.sampled_from(KINDS), data=st.data())
@settings(max_examples=60, deadline=None)
def test_repeated_covariances_are_read_once_and_shared_only_while_their_bytes_repeat(kind: str, data) -> None:
    """A driver's covariances are constants: the decoder keeps the previous message's covariance tuples
    while their bytes repeat (``cdr_fast_path.Covariances``), and reads them anew when any changes. Over
    a stream whose covariances switch between two sets (and a value that moves in every message), each
    payload still decodes exactly as rosbags does, and a covariance tuple is the previous one's object
    exactly when its message repeated the previous covariance bytes."""
    samples = odom_samples if kind == "odom" else imu_samples
    pool = [data.draw(samples), data.draw(samples)]
    fields = ("twist_covariance",) if kind == "odom" else (
        "orientation_covariance", "angular_velocity_covariance", "linear_acceleration_covariance")
    decode = make_decoder(kind, "ros2-cdr", "s")
    previous = previous_cov = None
    for k, which in enumerate(data.draw(st.lists(st.integers(0, 1), min_size=2, max_size=10))):
        moving = "linear" if kind == "odom" else "angular_velocity"
        sample = msgspec.structs.replace(pool[which], stamp=1.0 + k, **{moving: (float(k), -0.5, 0.25)})
        payload = _cdr_of(kind, sample, "base_link")
        got = decode(payload)
        assert _same(got, _reference(kind, payload))
        covs = tuple(getattr(got, f) for f in fields)
        repeated = previous is not None and all(
            msgspec.msgpack.encode(getattr(sample, f)) == msgspec.msgpack.encode(getattr(previous, f)) for f in fields)
        if previous_cov is not None:
            assert all(a is b for a, b in zip(covs, previous_cov)) == repeated
        previous, previous_cov = sample, covs
