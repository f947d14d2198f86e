"""Configuration: the TOML contract (config.toml documents every key) as msgspec Structs.

Every table forbids unknown fields and every sensor kind is a tagged Struct, so a
typo, a wrong type or an unknown kind/mode is one clear line naming the key,
raised before anything starts.

The loader: it decodes a document as the shared tables (``config_tables``, re-exported here)
and the registered kinds' tables (``core/sensors/``), and validates what the kinds mean to each
other. It stands above the kinds it assembles; they and the fusion core read ``config_tables``.
"""

from __future__ import annotations

import math
import re
import tomllib
import typing
from pathlib import Path
from typing import Final, Literal

import msgspec

from .config_tables import (Config, FilterConfig, MetricsConfig, OutputConfig, RosConfig, SensorTable, StateConfig,
                            Vec2, Vec3, Vec6, ZenohConfig)
from .core.sensors import POSE_MSGTYPES, GpsSensor, ImuSensor, OdomSensor, PoseSensor
from .core.sensors.registry import config_types, kind_of, require
from .errors import ConfigError  # defined with the other layers' errors; importable from here

__all__ = [
    # the loader
    "load", "loads", "convert", "validate", "check_endpoint", "sensor_key", "ConfigError", "metrics_address",
    # the shared tables (config_tables) and the built-in kinds' tables (core/sensors), as the contract names them
    "Config", "ZenohConfig", "OutputConfig", "RosConfig", "StateConfig", "FilterConfig", "MetricsConfig", "SensorTable",
    "Vec2", "Vec3", "Vec6", "OdomSensor", "ImuSensor", "GpsSensor", "PoseSensor", "POSE_MSGTYPES", "SensorConfig",
]

# The built-in kinds' [[sensors]] tables (type hints, the documented defaults of config.toml); a
# config's sensors decode as whatever kinds are registered (``registry.config_types``), which a new
# kind extends.
SensorConfig = OdomSensor | ImuSensor | GpsSensor | PoseSensor


def sensor_key(names: typing.Sequence[object], i: int, field: str = "") -> str:
    """How an error names key ``field`` of the i-th [[sensors]] table: by the sensor's name
    (`sensor "imu": orientation`), which is what a user finds in the file, when the table has a
    name no other table shares; else by its index (`sensors[2].orientation`)."""
    name = names[i] if 0 <= i < len(names) else None
    if isinstance(name, str) and name and list(names).count(name) == 1:
        return f'sensor "{name}": {field}' if field else f'sensor "{name}"'
    return f"sensors[{i}].{field}" if field else f"sensors[{i}]"


def _check_struct(obj: msgspec.Struct, at: typing.Callable[[str], str]) -> None:
    for field in obj.__struct_fields__:
        value = getattr(obj, field)
        path = at(field)
        numbers = value if isinstance(value, tuple) else [value]
        for v in numbers:
            if isinstance(v, float) and math.isnan(v):
                raise ConfigError(f"{path}: NaN is not a valid value")
        signed = field == "stamp_offset_s"  # an offset: either way
        if field.endswith(("_s", "_sigma", "_noise", "_window", "_max", "_confirm")) and value is not None and not signed:
            if any(isinstance(v, (int, float)) and v < 0 for v in numbers):
                raise ConfigError(f"{path}: must not be negative")


ZENOH_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws", "unixsock-stream", "unixpipe", "serial", "vsock")
_IP_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws")  # their address is HOST:PORT


def check_endpoint(endpoint: str, where: str) -> None:
    """A Zenoh locator `<protocol>/<address>`: refused here, naming the key, rather than by the session."""
    proto, sep, address = endpoint.partition("/")
    if not sep or not address:
        raise ConfigError(f"{where}: Endpoints must be of the form <protocol>/<address> (e.g. tcp/10.0.0.2:7447), "
                          f"got {endpoint!r}")
    if proto not in ZENOH_PROTOCOLS:
        raise ConfigError(f"{where}: unknown protocol {proto!r} in {endpoint!r}; valid: {', '.join(ZENOH_PROTOCOLS)}")
    if proto in _IP_PROTOCOLS:  # the address before Zenoh's ?metadata and #config parts
        host, colon, port = address.split("?", 1)[0].split("#", 1)[0].rpartition(":")
        if not colon or not host or not port.isdigit() or int(port) > 65535:
            raise ConfigError(f"{where}: a {proto} endpoint is {proto}/HOST:PORT with a port in 0-65535 "
                              f"(e.g. {proto}/10.0.0.2:7447; port 0: any free port), got {endpoint!r}")


def metrics_address(listen: str, where: str = "metrics.listen") -> tuple[str, int]:
    """``"HOST:PORT"`` (``[::1]:9108`` for IPv6) as (host, port); ConfigError naming ``where`` otherwise."""
    host, sep, port = listen.rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ConfigError(f"{where}: must be \"HOST:PORT\" (e.g. \"127.0.0.1:9108\"; port 0: any free port), "
                          f"got {listen!r}")
    return host, int(port)


def _check_zenoh_retry(z: ZenohConfig) -> None:
    for name in ("connect_retry_init_s", "connect_retry_max_s"):
        value = getattr(z, name)
        if not 0.0 < value < math.inf:
            raise ConfigError(f"zenoh.{name}: must be a positive number of seconds, got {value}")
    if z.connect_retry_max_s < z.connect_retry_init_s:
        raise ConfigError(f"zenoh.connect_retry_max_s: {z.connect_retry_max_s} is below connect_retry_init_s "
                          f"({z.connect_retry_init_s})")
    if not 1.0 <= z.connect_retry_factor < math.inf:
        raise ConfigError(f"zenoh.connect_retry_factor: must be 1 or more, got {z.connect_retry_factor}")


def validate(cfg: Config) -> Config:
    """Checks msgspec cannot express: vector lengths, signs, unique names and keys."""
    for table in ("connect", "listen"):
        for ep in getattr(cfg.zenoh, table):
            check_endpoint(ep, f"zenoh.{table}")
    _check_zenoh_retry(cfg.zenoh)
    if cfg.metrics.listen:
        metrics_address(cfg.metrics.listen)
    _check_struct(cfg.filter, lambda field: f"filter.{field}")
    _check_struct(cfg.state, lambda field: f"state.{field}")
    if cfg.state.save_interval_s <= 0.0:
        raise ConfigError(f"state.save_interval_s: must be positive, got {cfg.state.save_interval_s}")
    if not 0.0 < cfg.filter.standstill_alpha < 0.5:
        raise ConfigError("filter.standstill_alpha: must be between 0 and 0.5")
    if not 0.0 < cfg.filter.nis_confidence < 1.0:
        raise ConfigError("filter.nis_confidence: must be between 0 and 1")
    if cfg.filter.nis_window < 2:
        raise ConfigError("filter.nis_window: must be at least 2")
    names: set[str] = set()
    keys: set[str] = set()
    every = [s.name for s in cfg.sensors]
    for i, s in enumerate(cfg.sensors):
        if not s.name:
            raise ConfigError(f"sensors[{i}].name: must not be empty")
        if s.name in names:
            raise ConfigError(f"sensors[{i}].name: duplicate sensor name {s.name!r}")
        _check_struct(s, lambda field: sensor_key(every, i, field))  # noqa: B023 - called at once
        if s.key in keys:
            raise ConfigError(f"{sensor_key(every, i, 'key')}: duplicate key {s.key!r}")
        if not s.key or s.key.startswith("/"):
            raise ConfigError(f"{sensor_key(every, i, 'key')}: must be a Zenoh key without leading '/', got {s.key!r}")
        if s.timeout_s <= 0:
            raise ConfigError(f"{sensor_key(every, i, 'timeout_s')}: must be positive")
        if not math.isfinite(s.stamp_offset_s):
            raise ConfigError(f"{sensor_key(every, i, 'stamp_offset_s')}: must be finite")
        names.add(s.name)
        keys.add(s.key)
    # What a sensor's kind means to the others (which one drives the prediction, defines the world
    # frame, is geodetic) its descriptor says.
    kinds = [kind_of(s) for s in cfg.sensors]
    odoms = [s for s, k in zip(cfg.sensors, kinds) if k.drives_prediction]
    if len(odoms) != 1 and cfg.sensors:
        raise ConfigError(f"sensors: exactly one odom sensor drives the prediction, found {len(odoms)}")
    frames = [i for i, (s, k) in enumerate(zip(cfg.sensors, kinds)) if k.defines_frame(s)]
    if len(frames) > 1:
        raise ConfigError(f"{sensor_key(every, frames[1])}: only one absolute sensor (gps, or pose without differential) "
                          "may define the world frame")
    if cfg.output.navsat_key and not any(k.geodetic for k in kinds):
        raise ConfigError("output.navsat_key: needs a gps sensor (the NavSatFix is the fused position in WGS84)")
    _check_ros(cfg)
    for i, (s, k) in enumerate(zip(cfg.sensors, kinds)):
        def at(field: str) -> str:
            return sensor_key(every, i, field)  # noqa: B023 - called in this iteration only

        k.validate(s, at)
        _check_radians(s, at)
        _check_metres(s, at)
    return cfg


# Angles are radians. Beyond these bounds a value is degrees typed as radians (yaw_offset = 20 meant
# 20 deg; as rad it turned the heading by 1.15 rad): never needed, since the angles wrap at 2 pi and a
# declination lies within pi.
_ANGLE_BOUNDS: Final = {"yaw_offset": 2.0 * math.pi, "magnetic_declination": math.pi, "extrinsic_rpy": 2.0 * math.pi}


def _check_radians(s: object, at: typing.Callable[[str], str]) -> None:
    for name, bound in _ANGLE_BOUNDS.items():
        value = getattr(s, name, None)
        if value is None:
            continue
        if any(not abs(v) <= bound for v in (value if isinstance(value, tuple) else (value,))):
            shown = list(value) if isinstance(value, tuple) else value
            raise ConfigError(f"{at(name)}: {shown} is beyond {bound:.2f}: angles are in radians "
                              "(degrees x pi / 180)")


# Lengths are metres. A sensor mounted farther than this from base_link is not on a wheeled robot (the largest,
# a mining haul truck, is 15 m long): it is centimetres or millimetres typed as metres (a lever arm of 150 put
# the antenna 150 m off, 158 m of world error).
MAX_MOUNT_M: Final = 20.0


def _check_metres(s: object, at: typing.Callable[[str], str]) -> None:
    xyz = getattr(s, "extrinsic_xyz", None)
    if xyz is not None and not math.hypot(*xyz) <= MAX_MOUNT_M:
        raise ConfigError(f"{at('extrinsic_xyz')}: {list(xyz)} is {math.hypot(*xyz):g} m from base_link, beyond "
                          f"{MAX_MOUNT_M:g} m: lengths are in metres (centimetres / 100)")


def _check_ros(cfg: Config) -> None:
    """[ros] and the output keys it turns into ROS topics."""
    out, ros = cfg.output, cfg.ros
    if out.ros_diagnostics_period_s <= 0.0:
        raise ConfigError("output.ros_diagnostics_period_s: must be positive")
    if not 0.0 <= out.diagnostics_batch_s <= 1.0:
        raise ConfigError(f"output.diagnostics_batch_s: must be in [0, 1] s (0: one record per put), "
                          f"got {out.diagnostics_batch_s}")
    for name in ("tf_key", "set_pose_key"):
        if not getattr(out, name):
            raise ConfigError(f"output.{name}: must not be empty")
    if not (math.isfinite(out.smooth_lag_s) and out.smooth_lag_s > 0.0):
        raise ConfigError(f"output.smooth_lag_s: must be a positive number of seconds, got {out.smooth_lag_s}")
    if not 0 <= ros.domain_id < 2**31:
        raise ConfigError(f"ros.domain_id: must be in [0, 2^31), got {ros.domain_id}")
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", ros.node_name):
        raise ConfigError(f"ros.node_name: not a valid ROS node name: {ros.node_name!r}")
    if ros.interop != "rmw_zenoh":
        return
    if cfg.zenoh.namespace:
        raise ConfigError("zenoh.namespace: not used with ros.interop = \"rmw_zenoh\" (rmw_zenoh keys start with "
                          "the domain id); put a ROS namespace into the keys instead, e.g. \"robot1/odom\"")
    every = [s.name for s in cfg.sensors]
    for i, s in enumerate(cfg.sensors):
        if s.encoding != "ros2-cdr":
            raise ConfigError(f"{sensor_key(every, i, 'encoding')}: rmw_zenoh carries ROS 2 CDR only, got {s.encoding!r}")

def _resolve(raw: object, path: str) -> type | None:
    """The config Struct at a msgspec error path (`sensors[1]`, `filter`), reading a sensor's `kind`."""
    import re

    cls: type = Config
    node = raw
    for part in [p for p in re.split(r"\.|(?=\[)", path) if p]:
        if part.startswith("["):
            if not isinstance(node, list):
                return None
            i = int(part[1:-1])
            node = node[i] if i < len(node) else None
            kind = node.get("kind") if isinstance(node, dict) else None
            cls = next((c for c in _sensor_tables() if c.__struct_config__.tag == kind), None)
            if cls is None:
                return None
            continue
        hint = typing.get_type_hints(cls).get(part)
        node = node.get(part) if isinstance(node, dict) else None
        if isinstance(hint, type) and issubclass(hint, msgspec.Struct):
            cls = hint
        elif part == "sensors":
            continue
        else:
            return None
    return cls


def _hint(msg: str, path: str, raw: object) -> str:
    """What msgspec does not say: the valid values of an enum, the key a typo meant."""
    import difflib
    import re

    unknown = re.match(r"Object contains unknown field `([^`]+)`", msg)
    if unknown:
        name = unknown.group(1)
        foreign = _foreign(name)
        if foreign:
            return foreign
        cls = _resolve(raw, path)
        if cls is not None:
            close = difflib.get_close_matches(name, cls.__struct_fields__, n=1, cutoff=0.6)
            if close:
                return f"; did you mean `{close[0]}`?"
        elsewhere = [table for table, t in _TABLES.items() if name in t.__struct_fields__]
        elsewhere += [f'a [[sensors]] table with kind = "{t.__struct_config__.tag}"' for t in _sensor_tables()
                      if name in t.__struct_fields__ and t is not cls]
        if elsewhere:
            return f"; it is a key of {' or '.join(f'[{t}]' if t in _TABLES else t for t in elsewhere)}"
        return ""
    if msg.startswith("Expected `array") and msg.endswith(("got `float`", "got `int`", "got `str`")):
        table, _, field = path.rpartition(".")
        cls = _resolve(raw, table) if table else Config
        hint = typing.get_type_hints(cls).get(field) if cls is not None else None
        n = next((len(typing.get_args(t)) for t in [hint, *typing.get_args(hint)]
                  if typing.get_origin(t) is tuple and ... not in typing.get_args(t)), 0)
        return f"; write a list of {n} numbers in [ ]" if n else "; write a list in [ ]"
    if msg.startswith(("Invalid enum value", "Invalid value")):
        table, _, field = path.rpartition(".")
        cls = _resolve(raw, table) if table else Config
        if field == "kind":
            valid = [c.__struct_config__.tag for c in _sensor_tables()]
        elif cls is not None:
            hint = typing.get_type_hints(cls).get(field)
            valid = [a for t in ([hint] + list(typing.get_args(hint))) if typing.get_origin(t) is Literal
                     for a in typing.get_args(t)]
        else:
            valid = []
        if valid:
            return "; valid values: " + ", ".join(f"{v!r}" if isinstance(v, str) else str(v) for v in valid)
    return ""


# The top-level tables, by the name a document gives them: a key put in the wrong one is named with its own.
_TABLES: Final = {"filter": FilterConfig, "output": OutputConfig, "zenoh": ZenohConfig, "ros": RosConfig,
                  "state": StateConfig, "metrics": MetricsConfig}

# robot_localization's and robot_pose_ekf's parameters a migrating user may write into a fusiond table, with
# the key that says the same here (docs/MIGRATION.md maps every one): named in the error instead of a
# look-alike key that means something else (`relative` is not `adaptive`).
_FOREIGN: Final = {
    "frequency": "not needed, a pose is published per odometry message",
    "freq": "not needed, a pose is published per odometry message",
    "sensor_timeout": "`timeout_s`, per sensor",
    "world_frame": "`[output] frame_id` (odometry frame) or `map_frame` (with a GPS or absolute pose)",
    "odom_frame": "`[output] frame_id`",
    "output_frame": "`[output] frame_id`",
    "base_link_frame": "`[output] child_frame_id`",
    "base_footprint_frame": "`[output] child_frame_id`",
    "process_noise_covariance": "`[filter] process_noise` (do not carry robot_localization's values over)",
    "initial_estimate_covariance": "`[filter] initial_sigma` (standard deviations)",
    "relative": '`orientation = "relative"` (an IMU) or `differential` (a pose)',
    "zero_altitude": "`[filter] two_d_mode`, or `vertical_error_sigma` (a GPS)",
    "use_odometry_yaw": 'an IMU with `orientation = "roll_pitch"` (the heading from the gyro and wheels)',
    "odom_used": 'a [[sensors]] table with kind = "odom"',
    "imu_used": 'a [[sensors]] table with kind = "imu"',
    "vo_used": 'a [[sensors]] table with kind = "pose" and differential = true',
    "gps_used": 'a [[sensors]] table with kind = "gps"',
}
# robot_localization's per-sensor parameters (odom0_config, imu1_differential, ...)
_FOREIGN_SENSOR: Final = re.compile(r"(odom|imu|pose|twist)\d+(_[a-z_]+)?")


def _foreign(name: str) -> str:
    """The hint for a robot_localization / robot_pose_ekf parameter written as a fusiond key ("" if not one)."""
    said = _FOREIGN.get(name)
    if said is None and _FOREIGN_SENSOR.fullmatch(name):
        said = ('a [[sensors]] table per sensor; its config booleans are `twist_measured` (odometry) or '
                '`orientation` and `angular_velocity` (an IMU)')
    return f"; a robot_localization / robot_pose_ekf parameter (fusiond: {said}; docs/MIGRATION.md)" if said else ""


def _one_line(err: msgspec.ValidationError, raw: object = None) -> str:
    msg = str(err)
    # msgspec says "... - at `$.sensors[0].kind`"; lead with the key, as users read it.
    if " - at `$" in msg:
        text, _, path = msg.partition(" - at `$")
        path = path.lstrip(".").rstrip("`")
        hint = _hint(text, path, raw)
        return f"{_named(path, raw)}: {text}{hint}" if path else f"{text}{hint}"
    return msg + _hint(msg, "", raw)


def _named(path: str, raw: object) -> str:
    """A msgspec error path (`sensors[1].orientation`) with the sensor named as the raw TOML names it
    (`sensor "imu": orientation`); other paths as they are."""
    found = re.match(r"sensors\[(\d+)\](?:\.(.*))?$", path)
    tables = raw.get("sensors") if isinstance(raw, dict) else None
    if not found or not isinstance(tables, list):
        return path
    names = [t.get("name") if isinstance(t, dict) else None for t in tables]
    return sensor_key(names, int(found.group(1)), found.group(2) or "")


def _sensor_tables() -> tuple[type, ...]:
    """The kinds' [[sensors]] tables registered at call time (a kind registered after import counts)."""
    return config_types()


def convert(raw: object) -> Config:
    """A parsed TOML document as a Config (not yet ``validate``-d); msgspec.ValidationError as msgspec
    raises it, its path from the document's root. The [[sensors]] tables decode as the union of the
    kinds registered now."""
    cfg = msgspec.convert(raw, type=Config)
    if not cfg.sensors:
        return cfg
    require(t.get("kind") for t in cfg.sensors if isinstance(t, dict))  # an installed package's kind
    tables = _sensor_tables()
    union = typing.Union[tables] if len(tables) > 1 else tables[0]  # noqa: UP007 - built at run time
    try:
        sensors = msgspec.convert(cfg.sensors, type=list[union])  # type: ignore[valid-type]
    except msgspec.ValidationError as err:
        text, sep, path = str(err).partition(" - at `$")
        raise msgspec.ValidationError(f"{text}{sep}.sensors{path}" if sep else text) from None
    return msgspec.structs.replace(cfg, sensors=sensors)


def loads(text: str, source: str = "<config>") -> Config:
    # `[sensors]` for `[[sensors]]`: TOML reads one table (then a second one overwrites it), not a list of them
    single = re.search(r"^\s*\[\s*sensors\s*\]\s*(#.*)?$", text, re.MULTILINE) is not None
    tables = "; each sensor is a [[sensors]] table (double brackets), not [sensors]" if single else ""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{source}: invalid TOML: {err}{tables}") from None
    try:
        cfg = convert(raw)
    except msgspec.ValidationError as err:
        raise ConfigError(f"{source}: {_one_line(err, raw)}{tables}") from None
    try:
        return validate(cfg)
    except ConfigError as err:
        raise ConfigError(f"{source}: {err}") from None


def load(path: str | Path) -> Config:
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as err:
        raise ConfigError(f"{p}: cannot read config: {err.strerror}") from None
    return loads(text, str(p))
