"""`fusiond init BAG --out FILE`: a starting config written from what the recording holds, every choice commented.

A new user's first question is the one robot_localization's tracker is full of: which topic goes where,
which mode for the IMU, which frame is the twist in, where is the IMU mounted. The bag answers most
of it (``bag_info.inspect_bags``): the odometry, IMU and NavSatFix topics and their types; whether the
IMU publishes an orientation at all (covariance[0] = -1 says it does not); the IMU's and the GPS
antenna's mounts from `/tf_static` (base frame -> sensor frame, composed along a chain); whether the
odometry's twist is stated in the body (its lateral speed is ~0 while driving) or in the odometry
frame (it is ~0 only once turned by the message's own heading); a driver that lost its yaw rate
(exactly 0 while driving). Each choice goes into the file with the reason it was made, so the user
can see what to change. Topics named as a reference (``/ground_truth``) are never fused. The config
is checked by the same loader `replay` uses before it is written.

What the bag cannot say is left at the README's recommendation and said so: the IMU's yaw is not
fused (``roll_pitch``): a magnetometer's yaw is disturbed near motors and steel, and the gyro, with
its bias learned at standstills, drives heading instead.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

from .bag_info import IMU, NAVSATFIX, ODOMETRY, POSES, BagInfo, StaticTransform, TopicInfo, inspect_bags, is_reference
from .config import ImuSensor, loads
from .core.sensors.registry import kind_reading
from .estimator import rotation as rot

__all__ = ["generate_config", "mount", "pick", "write_init"]

LATERAL_BODY = 0.3  # median |vy| / speed above this while driving: not a body-frame twist ...
LATERAL_TURNED = 0.1  # ... when turned by the message's heading it falls below this: an odometry-frame twist


def _key(topic: str) -> str:
    return topic.lstrip("/")


def pick(info: BagInfo, msgtype: str) -> tuple[TopicInfo | None, list[TopicInfo]]:
    """(the topic of this type to fuse, the others of it): references never; then the most messages
    (a filtered or republished copy is usually the rarer)."""
    candidates = [t for t in info.topics if t.msgtype == msgtype and not is_reference(t.topic) and t.count > 0]
    candidates.sort(key=lambda t: ("filtered" in t.topic, -t.count, t.topic))
    return (candidates[0] if candidates else None), candidates[1:]


def mount(static: Sequence[StaticTransform], base: str, frame: str) -> tuple[tuple[float, float, float],
                                                                           rot.Quat] | None:
    """The transform base -> frame composed along `/tf_static` (either direction of each link), or None."""
    base, frame = base.lstrip("/"), frame.lstrip("/")
    if not frame or frame == base:
        return (0.0, 0.0, 0.0), rot.IDENTITY
    links: dict[str, list[tuple[str, tuple, rot.Quat]]] = {}
    for s in static:
        fwd = (s.translation, rot.normalize(s.rotation))
        links.setdefault(s.parent, []).append((s.child, *fwd))
        qi = rot.conj(fwd[1])
        back = _rotate(qi, tuple(-v for v in s.translation))
        links.setdefault(s.child, []).append((s.parent, back, qi))
    seen = {base}
    todo = [(base, (0.0, 0.0, 0.0), rot.IDENTITY)]
    while todo:
        node, p, q = todo.pop()
        for child, t, r in links.get(node, []):
            if child in seen:
                continue
            d = _rotate(q, t)
            nxt = ((p[0] + d[0], p[1] + d[1], p[2] + d[2]), rot.normalize(rot.mul(q, r)))
            if child == frame:
                return nxt
            seen.add(child)
            todo.append((child, *nxt))
    return None


def _rotate(q: rot.Quat, v: Sequence[float]) -> tuple[float, float, float]:
    m = rot.matrix(q)
    return (float(m[0, 0] * v[0] + m[0, 1] * v[1] + m[0, 2] * v[2]),
            float(m[1, 0] * v[0] + m[1, 1] * v[1] + m[1, 2] * v[2]),
            float(m[2, 0] * v[0] + m[2, 1] * v[1] + m[2, 2] * v[2]))


def _num(v: float) -> str:
    """A float as TOML: six decimals at most, at least one (-0 as 0)."""
    text = f"{0.0 if abs(v) < 5e-7 else v:.6f}".rstrip("0")
    return text + "0" if text.endswith(".") else text


def _vec(v: Sequence[float]) -> str:
    return "[" + ", ".join(_num(float(x)) for x in v) + "]"


def _odometry_lines(t: TopicInfo) -> list[str]:
    lines = ["[[sensors]]", 'name = "wheel"',
             f'kind = "odom"                 # {t.topic}: {t.msgtype}, {t.rate_hz:.1f} Hz; its twist drives the '
             "prediction",
             f'key = "{_key(t.topic)}"']
    if t.pose_only:
        lines.append("twist_from_pose = true        # its pose travels while every twist reads 0: the driver fills the "
                     "pose only (as robot_pose_ekf read it); the twist is taken from consecutive poses")
        return lines
    if (t.lateral_body is not None and t.lateral_rotated is not None and t.lateral_body > LATERAL_BODY
            and t.lateral_rotated < LATERAL_TURNED):
        lines.append(f'twist_frame = "world"         # its lateral speed is {t.lateral_body:.0%} of the speed while '
                     f"driving, {t.lateral_rotated:.0%} once turned by the message's heading: stated in "
                     f"{t.frame_id or 'the odometry frame'}, not in {t.child_frame_id or 'the body'}")
    else:
        why = (f"its lateral speed is {t.lateral_body:.0%} of the speed while driving"
               if t.lateral_body is not None else "the robot never drove faster than 0.2 m/s here: not checked")
        lines.append(f'twist_frame = "body"          # in {t.child_frame_id or "base_link"}: {why}')
    if t.yaw_rate_zero:
        lines.append("twist_measured = [true, true, true, false, false, false]  # the yaw rate reads exactly 0 while "
                     "driving: the driver does not measure it (the gyro turns the robot)")
    if t.twist_zero_covariance:
        lines.append("# every twist covariance is 0: floored at twist_min_sigma (this table); state twist_noise (m/s, "
                     "rad/s) once measured (`fusiond tune` fits it)")
    return lines


def _imu_lines(t: TopicInfo, info: BagInfo, base: str, notes: list[str]) -> list[str]:
    lines = ["[[sensors]]", 'name = "imu"',
             f'kind = "imu"                  # {t.topic}: {t.msgtype}, {t.rate_hz:.1f} Hz, frame '
             f'{t.frame_id or "(none)"}',
             f'key = "{_key(t.topic)}"']
    if t.orientation_valid:
        lines.append('orientation = "roll_pitch"    # it publishes an orientation: roll and pitch are fused, its yaw '
                     'is not (magnetometers lie near motors and steel); "absolute" if its yaw is a calibrated '
                     'compass (examples/jackal_rl.toml), "relative" for a gyro-integrating AHRS')
    else:
        lines.append('orientation = "off"           # covariance[0] = -1: the driver publishes no orientation; '
                     "roll/pitch come from the accelerometer's gravity at low dynamics")
    if t.gyro_measured:
        lines.append("angular_velocity = true       # fuse the gyro: it drives heading, its bias learned at "
                     "standstills")
    else:
        lines.append("angular_velocity = false      # covariance[0] = -1: no gyro")
    floors = ImuSensor(name="imu", key=_key(t.topic))  # the floors' defaults, which this table keeps
    if t.gyro_zero_covariance:
        lines.append(f"# every gyro covariance is 0: floored at gyro_min_sigma ({floors.gyro_min_sigma:g} rad/s), "
                     "trusted beyond most gyros; state gyro_noise (rad/s) once measured at rest (`fusiond "
                     "calibrate-imu`; the doctor says what it measures at standstills)")
    if t.orientation_zero_covariance:
        lines.append(f"# every orientation covariance is 0: floored at orientation_min_sigma "
                     f"({floors.orientation_min_sigma:g} rad); state orientation_noise (rad) once measured (`fusiond "
                     "tune` fits it)")
    found = mount(info.static, base, t.frame_id) if t.frame_id else None
    if found is not None:
        rpy = rot.to_rpy(found[1])
        where = ("the IMU's frame is the base frame" if t.frame_id.lstrip("/") == base
                 else f"/tf_static {base} -> {t.frame_id}")
        lines.append(f"extrinsic_rpy = {_vec(rpy)}  # {where} (fixed-axis roll, pitch, yaw, rad, as URDF)")
    else:
        lines.append("extrinsic_rpy = [0.0, 0.0, 0.0]  # no /tf_static from " + base + f" to {t.frame_id!r}: taken as "
                     "mounted level and forward; state the mount if it is not (`fusiond doctor` measures it)")
        notes.append(f"the IMU frame {t.frame_id!r} has no static transform from {base!r}: mount assumed identity")
    return lines


def _gps_lines(t: TopicInfo, info: BagInfo, base: str) -> list[str]:
    lines = ["[[sensors]]", 'name = "gps"',
             f'kind = "gps"                  # {t.topic}: {t.msgtype}, {t.rate_hz:.1f} Hz; the output frame becomes '
             "ENU at the first fix (map -> odom -> base_link)",
             f'key = "{_key(t.topic)}"']
    found = mount(info.static, base, t.frame_id) if t.frame_id else None
    if found is not None and any(abs(v) > 1e-9 for v in found[0]):
        lines.append(f"extrinsic_xyz = {_vec(found[0])}  # the antenna in {base}, from /tf_static")
    else:
        lines.append(f"extrinsic_xyz = [0.0, 0.0, 0.0]  # no /tf_static from {base} to {t.frame_id!r}: the antenna "
                     "taken at the base origin (the doctor measures a lever arm from turns)")
    if t.covariance_type == 0:
        lines.append("# covariance type UNKNOWN: fixes get unknown_position_sigma and their horizontal noise is "
                     "measured from the wheels (estimate_unknown_noise)")
    return lines


def generate_config(info: BagInfo, bags: Sequence[str]) -> str:
    """The commented TOML of a starting config for this recording (ValueError when it has no odometry).
    Checked by the config loader before it is returned."""
    odom, other_odom = pick(info, ODOMETRY)
    if odom is None:
        have = ", ".join(f"{t.topic} [{t.msgtype}]" for t in info.topics) or "none"
        raise ValueError(f"no nav_msgs/msg/Odometry topic to drive the prediction (references left out); the bag "
                         f"has: {have}")
    imu, other_imu = pick(info, IMU)
    gps, other_gps = pick(info, NAVSATFIX)
    base = (odom.child_frame_id or "base_link").lstrip("/")
    notes: list[str] = []
    out = [f"# fusiond config written by `fusiond init` from {', '.join(bags)}",
           f"# ({'ROS 2' if info.ros2 else 'ROS 1'}, {info.duration_s:.1f} s). Every choice below says why; every "
           "key not written is at its default (config.toml documents them).",
           "# Check it: `fusiond doctor BAG --config THIS_FILE` (init ran it once already).", ""]
    out += _odometry_lines(odom) + [""]
    if imu is not None:
        out += _imu_lines(imu, info, base, notes) + [""]
    if gps is not None:
        out += _gps_lines(gps, info, base) + [""]
    skipped = []
    for t in info.topics:
        if t in (odom, imu, gps):
            continue
        if is_reference(t.topic):
            skipped.append(f"# {t.topic} ({t.msgtype}): a reference by its name, never fused; score against it with "
                           f"`fusiond replay BAG --config THIS_FILE --reference {t.topic}`")
        elif t in other_odom or t in other_imu or t in other_gps:
            chosen = odom if t in other_odom else imu if t in other_imu else gps
            also = (": if it is another source of this robot's motion (visual odometry, a localizer), a kind = "
                    "\"pose\" sensor fuses it (README step 3; differential = true for odometry that drifts)"
                    if t in other_odom else "")
            skipped.append(f"# {t.topic} ({t.msgtype}): a second one of its kind, not fused ({chosen.topic} is, "
                           f"having more messages){also}")
        elif t.msgtype in POSES:
            skipped.append(f"# {t.topic} ({t.msgtype}): not fused; if it measures this robot add a kind = \"pose\" "
                           "sensor (README step 3)")
        elif t.msgtype.endswith("TFMessage"):
            skipped.append(f"# {t.topic}: read for the sensors' mounts above" if t.topic.endswith("tf_static")
                           else f"# {t.topic}: not read (fusiond publishes its own TF)")
        elif (kind := kind_reading(t.msgtype)) is not None:  # a kind an installed package adds: its keys are its own
            skipped.append(f"# {t.topic} ({t.msgtype}): the installed kind \"{kind.name}\" reads it: add a [[sensors]] "
                           f"table with kind = \"{kind.name}\" and key = \"{_key(t.topic)}\" (its keys: that "
                           "package's documentation)")
        else:
            skipped.append(f"# {t.topic} ({t.msgtype}): not a sensor kind fusiond fuses")
    if skipped:
        out += ["# Topics not fused:", *skipped, ""]
    if notes:
        out += ["# To check:", *(f"# - {n}" for n in notes), ""]
    out += ["# On the robot, `fusiond run` is a Zenoh peer found by UDP multicast: a monitor on the same host, or on a",
            "# network that passes multicast, finds it. Where none passes, listen on an endpoint an operator can dial",
            "# (`fusiond monitor --connect tcp/ROBOT:7447`; docs/FLEET.md):",
            "# [zenoh]",
            '# listen = ["tcp/0.0.0.0:7447"]', ""]
    text = "\n".join(out)
    loads(text)  # what replay would refuse is refused here, naming the key
    return text


def write_init(bags: Sequence[str], out: str, force: bool = False) -> int:
    """`fusiond init`'s work before its replay: read the bags, write the config to ``out``. 0 when written;
    2 with one line on stderr for a bag that cannot be read, one without odometry, or an ``out`` that
    exists (without ``force``) or cannot be written."""
    from .errors import BagError

    path = Path(out)
    if path.exists() and not force:
        print(f"fusiond: --out {out}: exists; pass --force to overwrite it", file=sys.stderr)
        return 2
    try:
        info = inspect_bags(bags)
        text = generate_config(info, [Path(b).name for b in bags])
    except (BagError, ValueError) as err:
        print(f"fusiond: {err}", file=sys.stderr)
        return 2
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    except OSError as err:
        print(f"fusiond: --out {out}: cannot write it ({err.strerror})", file=sys.stderr)
        return 2
    print(f"config      {out} (written from the bag; each choice commented)")
    return 0
