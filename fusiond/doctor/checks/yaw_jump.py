"""Absolute yaw readings the jump gate kept out, against the orientation samples: how often a disturbance
switched on."""

from __future__ import annotations

from ...core.sensors.imu import YAW_JUMP_GATE
from ..channels import PerChannel
from ..evidence import Evidence
from ..nis import ChannelStats
from ..verdict import Verdict, sensor_key

__all__ = ["YawJumps"]

JUMP_NOTE_SHARE = 0.01  # yaw jumps in more than this share of the orientation samples are worth a warning
JUMP_NOISE_SHARE = 0.2  # ... in more than this, the stated yaw noise is what is wrong (or the yaw is unusable)


class YawJumps(PerChannel):
    """Absolute yaw readings the jump gate kept out, against the orientation samples."""

    name = kind = "yaw_jump"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        """The ``yaw_jump`` channel (core/sensors/imu/model.py ``_yaw_jump``): every record is an absolute yaw reading
        that jumped against the gyro-carried heading beyond YAW_JUMP_GATE sigma and was not fused, so its NIS
        says nothing about the stated noise (all are beyond the gate by construction). What it says is how often
        the magnetometer's disturbance switched on."""
        name, orientation = key[0], ev.channels.get((key[0], "orientation"))
        total = ch.n + (orientation.n if orientation is not None else 0)
        share = ch.n / total if total else 0.0
        head = (f"{ch.n} yaw readings ({100 * share:.1f}% of the IMU's) jumped against the gyro-carried heading "
                f"beyond {YAW_JUMP_GATE:g} sigma of their stated noise and were not fused")
        evidence = {"yaw_jumps": float(ch.n), "yaw_jump_share": share}
        if share <= JUMP_NOTE_SHARE:
            return [Verdict(name, "yaw_jump", "ok", head + ": a disturbance switching on now and then (a motor, steel "
                            "nearby); one that persists is fused from the next reading and goes into the yaw offset",
                            evidence=evidence)]
        if share <= JUMP_NOISE_SHARE:
            return [Verdict(name, "yaw_jump", "warn", head + ": the magnetometer's yaw is disturbed often "
            "(motors, steel); "
                            "the heading holds on the gyro meanwhile. If the track bends near those places, take only "
                            'roll/pitch from the IMU (orientation = "roll_pitch")', evidence=evidence)]
        return [Verdict(name, "yaw_jump", "warn", head + ": too many for disturbances: "
        "the stated yaw noise is far below "
                        "the yaw's real sample-to-sample noise (state it), or the yaw is unusable (orientation = "
                        '"roll_pitch")', sensor_key(name, "orientation_noise"), evidence=evidence)]
