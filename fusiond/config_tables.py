"""The config's tables that depend on no sensor kind: [zenoh], [output], [ros], [state], [filter],
the keys every [[sensors]] table shares (``SensorTable``), and the document that holds them (``Config``).

Apart from ``config`` so that the sensor kinds (``core/sensors/``), whose tables subclass
``SensorTable`` and whose models read ``FilterConfig``, import it, and ``config``, which
assembles the whole document from these and the registered kinds' tables, imports them: the
layers stand one above the other, with no import running back up. ``fusiond.config`` re-exports
every name here.
"""

from __future__ import annotations

import typing
from typing import Literal

import msgspec

__all__ = ["Vec2", "Vec3", "Vec6", "ZenohConfig", "OutputConfig", "RosConfig", "StateConfig", "FilterConfig",
           "MetricsConfig", "SensorTable", "Config"]


Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]
Vec6 = tuple[float, float, float, float, float, float]


class _Table(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    pass


class ZenohConfig(_Table):
    mode: Literal["peer", "client", "router"] = "peer"
    connect: list[str] = []
    listen: list[str] = []
    multicast_scouting: bool = True
    config_file: str = ""
    namespace: str = ""
    # Zenoh's connect/retry: how soon a lost router (or peer) is dialled again. Zenoh's own defaults
    # (1 s, doubling to 4 s) left a 3 s outage costing ~7 s of data; these retry within 0.5 s.
    connect_retry_init_s: float = 0.25  # first retry after a failed or lost connection
    connect_retry_max_s: float = 0.5  # the retry period grows up to this
    connect_retry_factor: float = 1.5  # by this factor per failed attempt


class OutputConfig(_Table):
    pose_key: str = "odom_combined"
    odometry_key: str = "odometry/filtered"
    diagnostics_key: str = "fusiond/diagnostics"
    diagnostics_batch_s: float = 0.05  # one JSON array of the records of this long per put (0: a put per record)
    health_key: str = "fusiond/health"
    frame_id: str = "odom"
    child_frame_id: str = "base_link"
    navsat_key: str = ""  # with a gps sensor: the fused position as NavSatFix here (empty: off)
    publish_tf: bool = True  # tf2_msgs/msg/TFMessage frame_id -> child_frame_id on tf_key (robot_localization's name)
    # With a GPS or absolute pose: the world frame. TF then carries map_frame -> frame_id (the corrections)
    # and frame_id -> child_frame_id (continuous), as robot_localization's dual EKF; "" or frame_id: one TF.
    map_frame: str = "map"
    tf_key: str = "tf"  # the bridge's mapping of /tf
    ros_diagnostics_key: str = "diagnostics"  # health as diagnostic_msgs/msg/DiagnosticArray (empty: off)
    ros_diagnostics_period_s: float = 1.0  # how often it is published (diagnostic_updater's default rate)
    set_pose_key: str = "fusiond/set_pose"  # queryable: re-initialise the filter (robot_localization's set_pose)
    # the pose of smooth_lag_s ago smoothed over the window since (core/fixed_lag.py), for a consumer that can
    # wait (a mapper); "": off, and nothing is recorded for it
    smoothed_key: str = ""
    smooth_lag_s: float = 1.0


class RosConfig(_Table):
    """How fusiond meets ROS 2: through zenoh-bridge-ros2dds's plain keys, or as an rmw_zenoh node."""

    interop: Literal["bridge", "rmw_zenoh"] = "bridge"
    domain_id: int = 0  # ROS_DOMAIN_ID (rmw_zenoh mode): the first chunk of every key
    node_name: str = "fusiond"  # the node rmw_zenoh tools list (ros2 node list)


class StateConfig(_Table):
    """The daemon's persisted state, so that a restart resumes where the filter was instead of at the origin
    with nothing learnt (biases, scales, the GPS frame). Off unless a path is given."""

    path: str = ""  # file the state is written to (atomically) and resumed from; relative: to the config's directory
    save_interval_s: float = 1.0  # how often it is written while samples are fused (and once at a clean stop)
    max_age_s: float = 30.0  # an older file is refused at start (the robot may have moved meanwhile)


class MetricsConfig(_Table):
    """Prometheus text on ``/metrics`` (``transport/metrics.py``), fed from the health answer. Off unless
    an address is given."""

    listen: str = ""  # "HOST:PORT", e.g. "127.0.0.1:9108" (port 0: any free port, logged); "": off


class FilterConfig(_Table):
    """Core and estimator tuning shared by all sensors."""

    history_s: float = 1.0  # late messages up to this age are applied at their own stamp
    history_max: int = 4096  # hard bound on stored events, whatever their rate
    gap_s: float = 0.5  # a prediction step longer than this inflates the covariance
    gap_inflation: Vec2 = (0.05, 0.05)  # position m/sqrt(s), attitude rad/sqrt(s) added per s of gap
    covariance_cap: Vec2 = (1.0e6, 10.0)  # max variance: position m^2 (1 km: a car after a gap), attitude rad^2
    jump_s: float = 5.0  # a stamp this far from filter time is suspect (clock reset, bag restart)
    jump_confirm: int = 3  # suspect messages that, with jump_persist_s, confirm a jump (reset if backwards)
    jump_persist_s: float = 1.0  # and the suspect stamps must span this long: a short clock glitch is dropped
    process_noise: Vec2 = (0.002, 0.002)  # model error: position m/sqrt(s), attitude rad/sqrt(s)
    initial_sigma: Vec2 = (0.0, 0.1)  # initial position m, attitude rad
    gyro_bias_sigma: float = 0.01  # initial gyro-bias uncertainty, rad/s
    gyro_bias_walk: float = 2.0e-5  # gyro-bias random walk, rad/s/sqrt(s)
    standstill_s: float = 0.3  # odometry at rest this long before the gyro bias is learned
    standstill_alpha: float = 0.01  # size of the odometry's rest test: a true standstill window refused this often
    wheel_scale_sigma: float = 0.1  # initial wheel speed scale uncertainty (scale_estimation)
    wheel_scale_walk: float = 1.0e-4  # its random walk, 1/sqrt(s)
    gyro_scale_sigma: float = 0.05  # initial gyro (yaw axis) scale uncertainty (gyro_scale_estimation)
    gyro_scale_walk: float = 1.0e-5  # its random walk, 1/sqrt(s)
    twist_pitch_sigma: float = 0.1  # initial uncertainty of the twist's pitch in the body, rad (pitch_estimation)
    twist_pitch_walk: float = 1.0e-5  # its random walk, rad/sqrt(s)
    two_d_mode: bool = False  # planar robot (robot_localization's meaning): z, roll, pitch held at 0
    # No heading reference: a bias learned at rest never turns the pose (REP-105's continuous odom frame).
    # false is for offline analysis only: the correlated correction then turns heading and position at once.
    continuous_odom: bool = True
    nis_window: int = 50  # updates per windowed NIS consistency test
    nis_confidence: float = 0.95  # two-sided chi-square confidence of that test


class SensorTable(_Table, tag_field="kind"):
    """The keys every [[sensors]] table has; each kind's table subclasses it with ``tag="<kind>"``
    and is registered with its descriptor (``core/sensors/registry.py``)."""

    name: str
    key: str
    encoding: Literal["ros2-cdr", "json", "msgpack"] = "ros2-cdr"
    timeout_s: float = 0.2
    # s added to every header stamp of this sensor before it is fused: a receiver's latency (a GPS fix
    # stamped on arrival, 0.1-0.3 s after its epoch: negative), or a clock offset (GPS time vs UTC: -18)
    stamp_offset_s: float = 0.0


class Config(_Table):
    zenoh: ZenohConfig = msgspec.field(default_factory=ZenohConfig)
    output: OutputConfig = msgspec.field(default_factory=OutputConfig)
    ros: RosConfig = msgspec.field(default_factory=RosConfig)
    filter: FilterConfig = msgspec.field(default_factory=FilterConfig)
    state: StateConfig = msgspec.field(default_factory=StateConfig)
    metrics: MetricsConfig = msgspec.field(default_factory=MetricsConfig)
    # Decoded by ``config.loads`` against the registered kinds' tables (``config.convert``), not by this
    # annotation, so that a kind registered after import is a valid [[sensors]] table.
    sensors: list[typing.Any] = []

    def sensor(self, name: str) -> SensorTable:
        for s in self.sensors:
            if s.name == name:
                return s
        raise KeyError(name)
