"""fusiond: wheel odometry + IMU EKF fusion at the edge, over Eclipse Zenoh."""

__version__ = "0.1.0"
