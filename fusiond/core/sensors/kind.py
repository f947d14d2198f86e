"""What the rest of fusiond may ask about a sensor kind: one ``SensorKind`` descriptor per kind.

Config loading, the state layout, the fusion core, the decoder choice, the bag reader, the
daemon, replay's evaluation and resume need to know what a sensor's kind means to them (does it
define the world frame, which state blocks does it need, which ROS type does it read); each such
question is a method or flag here, answered by the kind's own package (``odom/``, ``imu/``,
``gps/``, ``pose/``) and looked up through ``registry.py``, so that none of them names a kind.
The defaults describe a plain aiding sensor (no world frame, no yaw, no state block of its own,
no publish prompt), so a new kind overrides only what it is.

Decoding is the one place a descriptor reaches below the core: ``codec``, ``from_ros`` and
``decoder`` import ``fusiond.codecs`` (and the kind's own ``codec`` module) when called (they pull
rosbags in), never at import, so the filter core stays importable without them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from importlib import import_module
from typing import TYPE_CHECKING, Any, ClassVar

from ...errors import ConfigError

if TYPE_CHECKING:
    from ...config_tables import FilterConfig
    from ...codecs.kind_codec import KindCodec
    from ...estimator import StateBlock
    from .base import SensorModel
    from .tunable import Param


class ModelIn:
    """A kind's ``model_type`` named by the module that defines it, imported when first read (when a
    filter is built). A model needs numpy and the estimator; a config is loaded without them, so that the
    process imports them after a replay's reading child is forked and while it opens the bags (such a child
    imports numpy only for a doctor of its own: ``replay.read_ahead``). A kind may as well set ``model_type``
    to the class itself."""

    __slots__ = ("module", "name")

    def __init__(self, module: str, name: str) -> None:
        self.module, self.name = module, name

    def __get__(self, kind: object, owner: type | None = None) -> type["SensorModel"]:
        return getattr(import_module(self.module), self.name)  # type: ignore[no-any-return]


class LayoutView:
    """What a kind may know of the whole configuration when it says which state blocks it needs:
    the filter table, and whether some sensor defines the world frame / fuses an absolute height
    (a wheel scale and a twist pitch are observable only then) / tells the heading (a gyro's scale
    is observable only then) / tests a height wander state it fuses (``SensorKind.height_wander``)."""

    __slots__ = ("filter", "absolute", "absolute_height", "heading", "height_wander")

    def __init__(self, filter_cfg: "FilterConfig", absolute: bool, absolute_height: bool,
                 heading: bool = True, height_wander: bool = False) -> None:
        self.filter = filter_cfg
        self.absolute = absolute
        self.absolute_height = absolute_height
        self.heading = heading
        self.height_wander = height_wander


class SensorKind:
    """One sensor kind: its config table, sample, model, decoders and what it means to the core.

    Subclasses set the class attributes and override the hooks their kind answers differently
    from the defaults. ``cfg`` arguments are instances of ``config_type``.
    """

    name: ClassVar[str]  # the config's `kind` tag
    config_type: ClassVar[type]  # the [[sensors]] table (a tagged ``SensorTable``)
    sample_type: ClassVar[type]  # what its decoders make and its model converts
    model_type: ClassVar[type["SensorModel"]]  # built once per configured sensor
    ros_types: ClassVar[tuple[str, ...]] = ()  # the ROS 2 message types its decoders read
    # exactly one sensor of this kind drives the prediction (the odometry): config loading requires it
    drives_prediction: ClassVar[bool] = False
    # an applied sample of this kind is a moment to publish the estimate (the odometry's rate)
    prompts_publish: ClassVar[bool] = False
    # the world frame it defines is geodetic (ENU at a WGS84 datum): NavSatFix output, heading from travel
    geodetic: ClassVar[bool] = False
    # what "waiting for the first ... to define the world frame" names
    frame_message: ClassVar[str] = "message"
    # it measures the body's own rotation in its axes (an IMU: orientation, gyro, gravity): the one the
    # doctor's cross-source checks hold against the wheels, and `calibrate-imu` measures at rest
    inertial: ClassVar[bool] = False
    # it measures where the robot is, or how far it moved (a GPS fix, a pose): after a gap of the other
    # sensors it finds the robot, and its heading, again
    measures_position: ClassVar[bool] = False

    # -- config -------------------------------------------------------------------------------------
    def validate(self, cfg: Any, at: Callable[[str], str]) -> None:
        """Checks of one table msgspec cannot express; raise ConfigError naming ``at(field)``."""

    # -- the world frame and the state ----------------------------------------------------------------
    def defines_frame(self, cfg: Any) -> bool:
        """Does this sensor define the world frame (nothing is published before its first message)?"""
        return False

    def fuses_height(self, cfg: Any, filter_cfg: "FilterConfig") -> bool:
        """Does its absolute height reach the filter (outside two_d_mode, which the caller checks)?"""
        return False

    def height_wander(self, cfg: Any) -> bool:
        """Does its height carry a modelled wander state whose estimate it tests against that model (a GPS
        altitude's: a refuted wander releases what ``pitch_estimation = "auto"`` holds)?"""
        return False

    def fuses_yaw(self, cfg: Any) -> bool:
        """Does it observe the heading itself (an absolute or relative IMU yaw)?"""
        return False

    def absolute_yaw(self, cfg: Any) -> bool:
        """Is its yaw absolute (REP-103 ENU), a heading reference beside a GPS?"""
        return False

    def heading_reference(self, cfg: Any) -> bool:
        """Does it tell the filter where it heads (from the positions it measures, or a yaw it observes),
        so that a gyro bias and a wheel yaw error do not accumulate into heading unchecked?"""
        return self.measures_position or self.fuses_yaw(cfg)

    def fuses_gyro(self, cfg: Any) -> bool:
        """Does it give the prediction a measured yaw rate (a gyro, whose bias the filter learns)?"""
        return False

    def tracks_acceleration(self, cfg: Any) -> bool:
        """Does its model need the odometry's forward acceleration (tilt from gravity)?"""
        return False

    def state_blocks(self, cfg: Any, view: LayoutView) -> Sequence["StateBlock"]:
        """The error-state blocks this sensor needs; the layout keeps one block per name (the first
        sensor asking wins) in its fixed order (``layout.BLOCK_ORDER``), unknown names after."""
        return ()

    def noise_key(self, cfg: Any, channel: str) -> str | None:
        """The key of its table that states the noise of its updates on ``channel`` (the key a NIS high or low
        there is about), for the doctor's verdict on a channel no check of its own judges; None by default (the
        built-in kinds' channels have checks of their own)."""
        return None

    def idle_keys(self, cfg: Any, view: LayoutView) -> list[tuple[str, str]]:
        """(key, why) for each key set in this sensor's table that the rest of the configuration leaves
        without effect (an estimate asked for with nothing to observe it): the core says so at start
        rather than let the key look as if it worked. None by default."""
        return []

    def datum(self, cfg: Any) -> tuple[float, float, float] | None:
        """A configured geodetic origin (lat deg, lon deg, alt m) of the world frame, if any."""
        return None

    # -- tuning -------------------------------------------------------------------------------------------
    def slow_errors(self, cfg: Any, span: float) -> dict[str, float]:
        """The parts of its error ("horizontal", "vertical") modelled as slower than a recording of ``span``
        seconds can identify, with their time constants: held-back positions score none of them (they
        share that error with their fused neighbours). None by default."""
        return {}

    def difference_variance(self, cfg: Any, dt: float) -> list[float]:
        """What its configured slow error (a Gauss-Markov state) adds to the variance of the difference of two
        of its readings ``dt`` seconds apart, per component of its reading (for the GPS: east, north, up);
        the floors `fusiond tune` measures at rest take it off. None by default: ``[]``."""
        return []

    def tunables(self, cfg: Any, samples: Sequence[object]) -> list["Param"]:
        """The keys of its table `fusiond tune` may fit on ``samples``, and where each starts
        (``tunable.py``); those that cannot be fitted carry the reason. None by default."""
        return []

    # -- decoding ---------------------------------------------------------------------------------------
    def ros_type(self, cfg: Any) -> str:
        """The ROS 2 message type this sensor's topic carries (the first of ``ros_types`` by default)."""
        return self.ros_types[0]

    def codec(self) -> "KindCodec | None":
        """Its wire formats (a ``fusiond.codecs.KindCodec``: ROS converter, JSON / msgpack Struct, encoder,
        struct fast path), imported from its package when first asked for, never when the kind loads.
        None by default: a kind that offers only ``from_ros`` is read as ROS 2 CDR through rosbags."""
        return None

    def from_ros(self) -> Callable[[Any, str], Any]:
        """(rosbags message, sensor name) -> sample: what a bag replay reads with (its codec's by default)."""
        codec = self.codec()
        if codec is None:
            raise NotImplementedError(f"sensor kind {self.name!r} has no ROS message converter")
        return codec.from_ros

    def decoder(self, cfg: Any) -> Callable[[Any], Any]:
        """bytes -> sample of this sensor's key; raises only ``DecodeError``. Through its ``codec`` (any
        encoding it offers, ``ros_type`` of a kind reading several), else ROS 2 CDR of ``ros_type`` through
        rosbags and ``from_ros``."""
        codec = self.codec()
        if codec is not None:
            from ...codecs.decoders import decoder_for

            msgtype = self.ros_type(cfg) if len(codec.ros_types) > 1 else None
            return decoder_for(codec, cfg.encoding, cfg.name, msgtype=msgtype)
        from ...codecs.decoders import cdr_decoder

        if cfg.encoding != "ros2-cdr":
            raise ConfigError(f"sensor {cfg.name!r}: kind {self.name!r} reads ros2-cdr only, got {cfg.encoding!r}")
        return cdr_decoder(self.ros_type(cfg), self.from_ros(), cfg.name)

    def zero_covariance(self, cfg: Any) -> Callable[[Any], bool] | None:
        """For health's ``zero_covariance_floored``: does an accepted sample carry a zero variance the
        sensor's floor replaces? None when the covariances are not read (overridden, or none)."""
        return None

    def __repr__(self) -> str:
        return f"<sensor kind {self.name!r}>"


__all__ = ["LayoutView", "ModelIn", "SensorKind"]
