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
    "ROLL_PITCH_OFFSET_RAD", "GATED_FRACTION", "MOST_GATED", "JUMP_NOTE_SHARE", "JUMP_NOISE_SHARE",
    "UNALIGNED_MIN_FIXES", "UNALIGNED_LARGE",
    "LEAN_RAD",
    "CLOCK_DROP_SHARE",
    "MIN_COAST_BINS", "DECEL_TOLERANCE", "MIN_COAST_DECEL", "COAST_Z_SIGMAS", "LEVEL_SHARE",
    "DROPOUT_LONGEST_S", "DROPOUT_FRACTION",
    "MIN_GAP_S", "GAP_TURN_RAD", "GAP_DRIFT_RATE", "GAP_EDGE_S",
    "PERSISTING_SHARE", "WANDER_MIN_FIXES", "MAX_LAG_FRACTION",
    "MOUNT_PITCH_RAD",
    "MIN_REJECTED_FRACTION", "OVERSTATED_RATIO", "NOISE_RATIO", "DISAGREE_RAD_S", "MIN_DRIFT_EPISODES",
    "DRIFT_WALK_MARGIN",
    "WINDOW_S", "WANDER_RAD", "TRACK_OFFSET_RAD", "DRIFT_RAD_S", "MIN_SPAN_S",
    "WHEEL_SCALE_TOLERANCE", "MIN_TURN_RAD", "WHEEL_OFFSET_RAD_S", "ZERO_TURNING_RAD_S", "MISSED_INTERVAL_S",
    "MISSED_TURN_RAD",
    "LATE_DRIFT_RAD", "RELATIVE_MARGIN", "REACQUIRE_AFTER_GAP_S",
    "LEVER_TOL", "MAX_SE", "MAX_SE_NAMED", "LATENCY_ALONG", "LEVER_Z_SIGMAS", "OUTLIER_SIGMAS", "MIN_PAIRS", "PAIR_S",
    "MAX_INTERVAL",
    "MOUNT_YAW_RAD", "MOUNT_MIN_SPEED", "SMOOTH_BINS", "MOUNT_MIN_SAMPLES", "GAIN_BAND", "MAX_ALIGN_S",
    "MOUNT_Z_SIGMAS",
    "SCALE_TOLERANCE", "CHORD_M", "CHORD_MAX_S", "MIN_CHORDS", "ASSUMED_TAU_S", "SCALE_Z_SIGMAS",
    "TURNING_RAD_S", "UNMEASURED_FRACTION", "ALL_ZEROS_FRACTION", "MIN_TURNED_RAD", "SLIP_FRACTION", "TURNED_RAD",
    "ALONG_SIN", "MOVING_M_S",
]

# -- how much a run must show (diagnose) ----------------------------------------------------------------------
MIN_UPDATES = 50  # twist-frame and lean checks need this many samples (not NIS: that uses what there is)

# -- innovation statistics (nis.py) ------------------------------------------------------------------------------
NIS_HIGH = 2.0  # mean NIS per dof above this (and above the chi-square bound): noise understated
NIS_LOW = 0.3  # ... below this (and below the bound): noise overstated

# -- one channel's own records (channels.py) ---------------------------------------------------------------------
ROLL_PITCH_OFFSET_RAD = 0.01  # a mean roll/pitch innovation this large is a mounting error, not noise
GATED_FRACTION = 0.1  # gated beyond this: the sensor jumps (or its noise is understated) ...
MOST_GATED = 0.5  # ... and beyond this: its noise is understated (jumps are the exception, not the rule)
JUMP_NOTE_SHARE = 0.01  # yaw jumps in more than this share of the orientation samples are worth a warning
JUMP_NOISE_SHARE = 0.2  # ... in more than this, the stated yaw noise is what is wrong (or the yaw is unusable)
UNALIGNED_MIN_FIXES = 50  # fixes before a heading never found is worth a verdict
UNALIGNED_LARGE = 2.0  # predicted innovation rms this many times the measured one: the stated noise hides the heading

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
# "Strongly autocorrelated": at least 15 % of the innovations' variance persists to the next fix. A
# consistent filter's innovations are white: their lag-1 autocorrelation is ~N(0, 1/n) (0.04 over 750
# fixes); with the noise misstated the filter's own response adds a little: measured 0.00-0.04 on white
# fixes at 2 and 10 Hz, 1 to 25 m/s, stated honestly to 3.7x overstated; it must also be beyond
# 4 / sqrt(n) of zero for short runs. A Gauss-Markov error of 1.2 m (tau 60 s) under 0.6 m of white noise
# leaves 0.38 (stated honestly) to 0.54 (stated 2.2 m) at 2 Hz, where the filter follows the wander less
# the more the fixes are distrusted; at 10 Hz on a car at 25 m/s it follows more of it and leaves 0.18-0.25
# (a highway car: 0.18; a threshold of 0.3 misses it, and the advice would be "lower position_noise").
PERSISTING_SHARE = 0.15
WANDER_MIN_FIXES = 50  # fixes for an autocorrelation: at lag 1 its standard error is ~1/sqrt(50) = 0.14
MAX_LAG_FRACTION = 0.25  # autocorrelation lags up to this share of the run (beyond, too few pairs)

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
WINDOW_S = 60.0  # detrending window: a gyro bias is constant over a minute
WANDER_RAD = 0.05  # rms yaw wander (after bias and scale are removed) that is a disturbance, not noise
TRACK_OFFSET_RAD = 0.05  # a mean IMU-vs-track offset this large is worth a yaw_offset
DRIFT_RAD_S = 0.002  # the IMU yaw's own drift (against the gyro, its bias at rest removed) that is no heading:
# 7 deg a minute, far beyond a magnetometer's (no secular drift) and a learned gyro bias's (~1e-4 rad/s)
MIN_SPAN_S = 10.0  # s: a detrending window whose samples span less than this is too short to fit a bias and is skipped
WHEEL_SCALE_TOLERANCE = 0.1  # wheel yaw within 10 % of the gyro's is fine for a prediction
MIN_TURN_RAD = 0.5  # total turn needed to measure a yaw scale
WHEEL_OFFSET_RAD_S = 0.02  # a wheel yaw-rate offset that turns the heading by a radian a minute
ZERO_TURNING_RAD_S = 0.05  # the gyro turning this fast while the wheels read exactly zero: not at rest
MISSED_INTERVAL_S = 0.5  # s: an odometry interval counts for at most this much turn time (gaps count nothing)
MISSED_TURN_RAD = 0.2  # rad (11 deg) of turn the wheels missed in all: worth fusing the gyro for

# -- a gyro bias learned late (late_bias.py) -----------------------------------------------------------------------
LATE_DRIFT_RAD = 0.05  # heading drift before the first standstill worth a verdict (3 deg)
RELATIVE_MARGIN = 0.5  # the relative yaw's mean heading error must stay below this share of the late bias's
REACQUIRE_AFTER_GAP_S = 30.0  # a GPS reacquired this soon after a logging gap ended is blamed on the gap

# -- the GPS lever arm (lever.py) ------------------------------------------------------------------------------------
LEVER_TOL = 0.2  # m: a lever this close to the stated one is not worth a change
MAX_SE = 0.1  # m: "as stated" needs the fit this precise (half LEVER_TOL)
MAX_SE_NAMED = 0.3  # m: a lever is named only from a fit this precise (a fifth of a 1.5 m mast's offset)
LATENCY_ALONG = 2.0  # a misfit behind base_link this many times longer than it is wide: also says latency
# named when the lever's chi-square (2 dof) exceeds LEVER_Z_SIGMAS^2 = 25 (p ~ 4e-6, lever's docstring)
LEVER_Z_SIGMAS = 5.0
OUTLIER_SIGMAS = 4.0  # a pair beyond 4 sigma of the scatter is multipath (a normal pair: 6e-5 chance)
MIN_PAIRS = 30  # fix pairs in turns before a fit: its scatter estimate then good to ~13 %
PAIR_S = 3.0  # s between the two fixes of a pair (lever's docstring)
MAX_INTERVAL = 1.5  # a pair further apart than this many PAIR_S (fixes missing) is not used

# -- the wheel speed scale against the GPS (speed.py) --------------------------------------------------------------
SCALE_TOLERANCE = 0.02  # a wheel scale within 2 % is not worth a state
CHORD_M = 10.0  # chords at least this long (or 20 sigma_w): short and consecutive (speed's docstring)
CHORD_MAX_S = 60.0  # a chord spans at most this long (slower: the robot is standing or creeping)
MIN_CHORDS = 3  # the fewest for a residual standard error (2 dof) next to the model's
ASSUMED_TAU_S = 100.0  # the fast end of receivers' wander times (speed's docstring)
SCALE_Z_SIGMAS = 3.0  # a scale is named beyond this many standard errors (as a normal quantile: 0.27 % two-sided)

# -- the odometry twist (twist.py) ------------------------------------------------------------------------------------
TURNING_RAD_S = 0.05  # the gyro says the robot turns (well above any gyro's noise and bias)
UNMEASURED_FRACTION = 0.5  # in turns, this share of exact zeros is a component the driver does not measure
ALL_ZEROS_FRACTION = 0.99  # ... and in gentle turns only: (nearly) every moving sample an exact zero
MIN_TURNED_RAD = 1.0  # ... over a run whose heading the gyro turned by at least this much
SLIP_FRACTION = 0.2  # samples flagged as slip beyond a fifth: the wheels' yaw rate is not just noisy
TURNED_RAD = 0.3  # the message's own pose yaw this far from the odom frame's x: a world twist must follow it
ALONG_SIN = 0.05  # |sin| of the angle between the twist and an axis below this: the twist points along it
MOVING_M_S = 0.1  # speed above which a twist has a direction
