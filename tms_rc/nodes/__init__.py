"""ROS 2 nodes of tms_rc (console scripts): ``zx200_arm_controller`` and ``ic120_vessel``."""
