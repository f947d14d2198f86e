"""A consumer receiver's wandering GPS error and the noise it states (HDOP)."""

from __future__ import annotations

# A consumer receiver (the doctor's wander tests): white 0.6 m plus a Gauss-Markov wander of 1.2 m
# (tau 60 s), 2 Hz, stating 2.2 m (HDOP).
WANDER = dict(duration=400.0, gps_rate=2.0, gps_sigma=0.6)
STATED_HDOP = "position_noise = [2.2, 2.2, 4.4]"
