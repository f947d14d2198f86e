"""The GPS's [[sensors]] table (kind = "gps"): config.toml documents every key."""

from __future__ import annotations

from ....config_tables import SensorTable, Vec3


class GpsSensor(SensorTable, tag="gps"):
    """sensor_msgs/msg/NavSatFix; with one configured, the world frame is ENU at the datum."""

    timeout_s: float = 2.0
    # gate on sqrt(NIS) once the heading is known: multipath bursts and placeholder fixes, not the
    # receiver's ordinary noise (a consistent filter rejects ~1 fix in 10^5); a run of agreeing
    # rejected fixes re-acquires (core/sensors/gps/model.py), so the gate cannot lock the filter out
    mahalanobis_threshold: float = 5.0
    # a run of gated-out fixes that began with a jump of the fixes and keeps one common offset is a step
    # of the receiver's error, taken within a few fixes by a sequential test whose false alarms (steps
    # taken from outliers) stay below this probability per run; 0: no such test (model.py, module doc)
    step_false_alarm: float = 1.0e-3
    datum: Vec3 | None = None  # [lat deg, lon deg, alt m]; default: the first valid fix
    position_noise: Vec3 | None = None  # std devs east north up, m; replaces position_covariance
    position_min_sigma: float = 0.01  # floor, m
    unknown_position_sigma: Vec3 = (2.5, 2.5, 5.0)  # used when the covariance type is UNKNOWN (0)
    # a receiver that states no accuracy: its white noise measured from consecutive fixes against the
    # dead-reckoned motion between them (below unknown_position_sigma, never above); false: that default
    estimate_unknown_noise: bool = True
    extrinsic_xyz: Vec3 = (0.0, 0.0, 0.0)  # antenna position in base_link, m
    heading_init_m: float = 5.0  # travel (m) over which the initial heading is measured
    error_tau_s: float = 0.0  # > 0: estimate a Gauss-Markov GPS error with this time constant, s
    error_sigma: Vec3 | None = None  # its steady-state std devs east north up, m (needed with error_tau_s)
    # Without error_tau_s: the vertical alone as such a state (consumer receivers' altitude wanders
    # metres over minutes while they state ~1-2 m); vertical_error_sigma = 0 turns it off
    vertical_error_tau_s: float = 300.0
    vertical_error_sigma: float = 5.0  # m
    max_sigma: float = 1.0e3  # an axis stated less precise than this (m) is "not measured": not fused


__all__ = ["GpsSensor"]
