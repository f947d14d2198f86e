"""Pure maths: state blocks, error-state EKF, motion and measurement models. No I/O, no clocks."""

from .ekf import ErrorStateEKF, UpdateResult
from .gps_error import GpsErrorBlock
from .motion import MotionInput, PredictWorkspace, corrected_inputs, predict
from .scale import GyroScaleBlock, WheelScaleBlock
from .state import GyroBiasBlock, InputBlock, PoseBlock, StateBlock, StateLayout, YawOffsetBlock
from .twist_pitch import TwistPitchBlock

__all__ = [
    "ErrorStateEKF", "UpdateResult", "MotionInput", "PredictWorkspace", "corrected_inputs", "predict",
    "GpsErrorBlock", "GyroBiasBlock", "GyroScaleBlock", "TwistPitchBlock", "WheelScaleBlock", "InputBlock",
    "PoseBlock", "StateBlock", "StateLayout", "YawOffsetBlock",
]
