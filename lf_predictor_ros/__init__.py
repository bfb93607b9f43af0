"""lf_predictor_ros: a learned low-frequency (LF) pose predictor — a wave filter — for ship DP.

`lf_predictor_ros.core` is ROS-free (numpy, scipy, torch); `nodes`, `bag` and `demo` are the
ROS 2 adapters and tools around it.
"""
__version__ = '0.1.0'
