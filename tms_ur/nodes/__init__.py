"""ROS 2 nodes of tms_ur (console scripts): ``tms_ur_panel`` and ``tms_ur_experiment``."""
