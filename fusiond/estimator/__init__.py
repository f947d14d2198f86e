"""Pure maths: state blocks, error-state EKF, motion and measurement models. No I/O, no clocks."""

from .backend import COMPILED as COMPILED_BACKEND
from .backend import DEFAULT as DEFAULT_BACKEND
from .backend import PYTHON as PYTHON_BACKEND
from .backend import Backend, CompiledBackend, PythonBackend
from .ekf import ErrorStateEKF, UpdateResult
from .planar import planar_mask
from .gps_error import GpsErrorBlock
from .motion import MotionInput, PredictWorkspace, corrected_inputs, predict
from .scale import GyroScaleBlock, WheelScaleBlock
from .smoother import Smoothed, SmoothingRecorder, smooth
from .state import (ATTITUDE, POSE, POSE_ERR, POSITION, POSITION_ERR, POSITION_ROWS, YAW_ROW, GyroBiasBlock, InputBlock, PoseBlock, StateBlock,
                    StateLayout, YawOffsetBlock, add_motion_noise, attitude_of, position_of)
from .twist_pitch import TwistPitchBlock

__all__ = [
    "Backend", "PythonBackend", "CompiledBackend", "PYTHON_BACKEND", "COMPILED_BACKEND", "DEFAULT_BACKEND",
    "ErrorStateEKF", "UpdateResult", "planar_mask", "Smoothed", "SmoothingRecorder", "smooth",
    "MotionInput", "PredictWorkspace", "corrected_inputs", "predict",
    "GpsErrorBlock", "GyroBiasBlock", "GyroScaleBlock", "TwistPitchBlock", "WheelScaleBlock", "InputBlock",
    "PoseBlock", "StateBlock", "StateLayout", "YawOffsetBlock",
    "POSITION", "ATTITUDE", "POSE", "POSITION_ROWS", "POSITION_ERR", "POSE_ERR", "YAW_ROW", "position_of", "attitude_of", "add_motion_noise",
]
