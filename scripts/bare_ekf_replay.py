"""A bare numpy EKF over a bag, as the yardstick for `fusiond replay`'s whole-process time.

Same model as fusiond's recommended setup (body twist drives position, gyro minus
bias drives attitude, IMU roll/pitch observed), written the short way: no history,
no policies, no diagnostics, messages applied in bag order. Usage:
    python scripts/bare_ekf_replay.py BAG ODOM_TOPIC IMU_TOPIC
"""

import math
import sys
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader


def quat_mul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz])


def rotmat(q):
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def main() -> None:
    bag, odom_topic, imu_topic = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
    p, q, b = np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3)
    P = np.diag([0.0] * 3 + [0.01] * 3 + [1e-4] * 3)
    v, w, t = np.zeros(3), np.zeros(3), None
    Qd = np.diag([1e-3] * 3 + [1e-6] * 3 + [4e-10] * 3)
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic in (odom_topic, imu_topic)]
        for conn, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
            if t is not None and stamp > t:
                dt = stamp - t
                R = rotmat(q)
                F = np.eye(9)
                dp = R @ v * dt
                F[0:3, 3:6] = -np.array([[0, -dp[2], dp[1]], [dp[2], 0, -dp[0]], [-dp[1], dp[0], 0]])
                F[3:6, 6:9] = -R * dt
                p = p + dp
                a = (w - b) * dt
                n = np.linalg.norm(a)
                dq = np.append(a / n * math.sin(n / 2), math.cos(n / 2)) if n > 1e-12 else np.array([0, 0, 0, 1.0])
                q = quat_mul(q, dq)
                q /= np.linalg.norm(q)
                P = F @ P @ F.T + Qd * dt
            t = stamp if t is None else max(t, stamp)
            if conn.topic == odom_topic:
                v = np.array([msg.twist.twist.linear.x, msg.twist.twist.linear.y, msg.twist.twist.linear.z])
                continue
            w = np.array([msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z])
            o = msg.orientation
            roll = math.atan2(2 * (o.w * o.x + o.y * o.z), 1 - 2 * (o.x * o.x + o.y * o.y))
            pitch = math.asin(max(-1.0, min(1.0, 2 * (o.w * o.y - o.z * o.x))))
            x, y, z, ww = q
            h = np.array([math.atan2(2 * (ww * x + y * z), 1 - 2 * (x * x + y * y)),
                          math.asin(max(-1.0, min(1.0, 2 * (ww * y - z * x))))])
            yaw = math.atan2(2 * (ww * z + x * y), 1 - 2 * (y * y + z * z))
            H = np.zeros((2, 9))  # small-tilt approximation: global x/y errors seen through the heading
            H[0, 3], H[0, 4] = math.cos(yaw), math.sin(yaw)
            H[1, 3], H[1, 4] = -math.sin(yaw), math.cos(yaw)
            S = H @ P @ H.T + np.eye(2) * 1e-6
            K = P @ H.T @ np.linalg.inv(S)
            K[[0, 1, 2, 5, 8], :] = 0.0  # roll/pitch must not move position, heading, z bias
            dx = K @ (np.array([roll, pitch]) - h)
            p += dx[0:3]
            n = np.linalg.norm(dx[3:6])
            if n > 0:
                q = quat_mul(np.append(dx[3:6] / n * math.sin(n / 2), math.cos(n / 2)), q)
            b += dx[6:9]
            IKH = np.eye(9) - K @ H
            P = IKH @ P @ IKH.T + K @ (np.eye(2) * 1e-6) @ K.T
    print(f"final {p[0]:.4f} {p[1]:.4f} {p[2]:.4f}")


if __name__ == "__main__":
    main()
