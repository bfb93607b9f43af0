"""sim_ros: vessel and sea simulator with ground truth, and a DP controller.

`sim_ros.physics` and `sim_ros.control` are ROS-free pure step functions (numpy, scipy);
`sim_ros.nodes` are the thin ROS 2 adapters.
"""
