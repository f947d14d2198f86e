"""Every threshold the doctor's checks decide by, in one place, each with where it comes from.

A verdict is only as good as the line it is drawn at: kept together, the lines can be read,
compared and argued about without reading the checks. Each constant says what it is derived
from (a stated error model, a statistical quantile, a config key's meaning) or, where it is a
judgement, what it trades. The series' own resolution and ordering (``bins.BIN_S``,
``series.REORDER_S``, ``streams.MAX_STEP_S``) and memory batch sizes are not thresholds: they stay
with the code that builds the series.
"""

from __future__ import annotations

from .bins import BIN_S

__all__ = [
    "MIN_UPDATES",
    "NIS_HIGH", "NIS_LOW",
    "LEAN_RAD",
    "CLOCK_DROP_SHARE",
    "MIN_COAST_BINS", "DECEL_TOLERANCE", "MIN_COAST_DECEL", "COAST_Z_SIGMAS", "LEVEL_SHARE",
    "DROPOUT_LONGEST_S", "DROPOUT_FRACTION",
    "MIN_GAP_S", "GAP_TURN_RAD", "GAP_DRIFT_RATE", "GAP_EDGE_S",
    "MOUNT_PITCH_RAD",
    "MIN_REJECTED_FRACTION", "OVERSTATED_RATIO", "NOISE_RATIO", "DISAGREE_RAD_S", "MIN_DRIFT_EPISODES",
    "DRIFT_WALK_MARGIN",
    "LATE_DRIFT_RAD", "RELATIVE_MARGIN",
    "MOUNT_YAW_RAD", "MOUNT_MIN_SPEED", "SMOOTH_BINS", "MOUNT_MIN_SAMPLES", "GAIN_BAND", "MAX_ALIGN_S",
    "MOUNT_Z_SIGMAS",
    "SCALE_TOLERANCE", "TURNED_RAD",
    "ALONG_SIN", "MOVING_M_S",
]

# -- how much a run must show (diagnose) ----------------------------------------------------------------------
MIN_UPDATES = 50  # twist-frame and lean checks need this many samples (not NIS: that uses what there is)

# -- innovation statistics (nis.py) ------------------------------------------------------------------------------
NIS_HIGH = 2.0  # mean NIS per dof above this (and above the chi-square bound): noise understated
NIS_LOW = 0.3  # ... below this (and below the bound): noise overstated

# -- one channel's own records (channels.py) ---------------------------------------------------------------------

# -- the estimate's lean (attitude.py) ---------------------------------------------------------------------------
LEAN_RAD = 0.03  # a mean lean of ~1.7 degrees that barely varies

# -- sensor clocks (clock.py) --------------------------------------------------------------------------------------
CLOCK_DROP_SHARE = 0.5  # this share of a sensor's samples dropped as far from filter time: its clock, not a glitch

# -- the mounting yaw the accelerometer measures (mounting.py) ---------------------------------------------------
# A yaw error delta in the mounting puts sin(delta) of the IMU's roll on base pitch (and of the
# centripetal tilt correction on the wrong axis): at 0.05 rad (3 degrees) a 0.1 rad side slope
# becomes a 0.005 rad pitch error, a sixth of the lean check's LEAN_RAD (0.03), i.e. 0.5 % of the
# distance driven in height. Smaller errors are not worth a verdict.
MOUNT_YAW_RAD = 0.05
MOUNT_MIN_SPEED = 0.2  # m/s: slower, dv/dt and v w are too small and the wheels too coarse to compare
SMOOTH_BINS = 5  # 1 s at 5 Hz: vibration averaged, manoeuvres (seconds long) kept
MOUNT_MIN_SAMPLES = 20  # decimated driving samples: 20 s of driving
# |(c, s)| is 1 for an accelerometer that sees the motion turned; at half or twice that it is not a turn
# (a mirrored axis, e.g. one sign flipped in the driver, fits with |(c, s)| near 0; wrong units near 10):
# the angle then means nothing and is not named
GAIN_BAND = (0.5, 2.0)
MAX_ALIGN_S = 1.5 * BIN_S  # an accelerometer bin with no wheel bin this close is not compared
MOUNT_Z_SIGMAS = 3.0  # a mounting yaw is named beyond 3 standard errors (0.27 % two-sided)

# -- coasting (coast.py) ---------------------------------------------------------------------------------------------
MIN_COAST_BINS = 2 * SMOOTH_BINS  # 2 s of coasting measured, at least
DECEL_TOLERANCE = 0.15  # m/s^2: a coast-down constant this close to the measured one is right enough
MIN_COAST_DECEL = 0.05  # m/s^2: the smallest advised (a 3 m/s coast then runs a minute); 0 turns the coast off
COAST_Z_SIGMAS = 3.0  # a coast-down is named beyond 3 standard errors (0.27 % two-sided for a normal error)
LEVEL_SHARE = 0.5  # an accelerometer bin counts when gravity was removed with the IMU's attitude in most of it

# -- the covariance cap (covariance.py) ----------------------------------------------------------------------------
# a cap reached after dropouts is blamed on them (gap_inflation) when one silence lasted 10 s or they add up
# to a tenth of the run; shorter, rarer silences leave the growth to the dead-reckoning between them
DROPOUT_LONGEST_S = 10.0
DROPOUT_FRACTION = 0.1

# -- the heading across logging gaps (gap_heading.py) --------------------------------------------------------------
MIN_GAP_S = 1.0  # shorter silences: the held inputs cover most of them
GAP_TURN_RAD = 0.2  # rad of unexplained turn across a gap: several times the yaw noise (gap_heading's docstring)
GAP_DRIFT_RATE = 0.01  # rad/s: an uncorrected consumer gyro bias, integrated by the IMU through the gap
# the estimates compared lie this close to the gap's ends (a time jump holds poses ~1 s), or it is not judged
GAP_EDGE_S = 2.0

# -- a wandering GPS receiver error (gps_wander.py) ----------------------------------------------------------------

# -- the mounting pitch against the GPS grade (grade.py) -----------------------------------------------------------
# A pitch error delta sinks or lifts the dead-reckoned z by delta per metre driven: at 0.01 rad, 1 %
# of the distance, twice the 0.5 % below which mounting.py names no yaw error. Smaller: not named.
MOUNT_PITCH_RAD = 0.01

# -- the gyro at rest (gyro.py) --------------------------------------------------------------------------------------
MIN_REJECTED_FRACTION = 0.1  # rejected standstill updates beyond a tenth: more than a gate's chance ones
OVERSTATED_RATIO = 3.0  # a stated gyro noise this many times the measured one at rest is overstated
# the gyro's noise at rest measured beyond this factor of the stated (either way) explains a NIS high or low;
# within it, the noise is as stated
NOISE_RATIO = 1.5
DISAGREE_RAD_S = 0.003  # episodes whose gyro means differ by more than this (and 5 sigma) disagree
MIN_DRIFT_EPISODES = 3  # a drift is told from one odd standstill by its trend, which takes three points
DRIFT_WALK_MARGIN = 2.0  # a drift is named when the walk it shows exceeds the configured one by this factor

# -- the heading sources against each other (heading.py) -----------------------------------------------------------

# -- a gyro bias learned late (late_bias.py) -----------------------------------------------------------------------
LATE_DRIFT_RAD = 0.05  # heading drift before the first standstill worth a verdict (3 deg)
RELATIVE_MARGIN = 0.5  # the relative yaw's mean heading error must stay below this share of the late bias's

# -- the GPS lever arm (lever.py) ------------------------------------------------------------------------------------

# -- the wheel speed scale against the GPS (speed.py) --------------------------------------------------------------
SCALE_TOLERANCE = 0.02  # a wheel scale within 2 % is not worth a state

# -- the odometry twist (twist.py) ------------------------------------------------------------------------------------
TURNED_RAD = 0.3  # the message's own pose yaw this far from the odom frame's x: a world twist must follow it
ALONG_SIN = 0.05  # |sin| of the angle between the twist and an axis below this: the twist points along it
MOVING_M_S = 0.1  # speed above which a twist has a direction
