"""ROS 2 nodes of tms_rp (console scripts): ``ic120_localization`` and ``ic120_navigator``."""
