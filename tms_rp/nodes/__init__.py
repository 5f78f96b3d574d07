"""ROS 2 nodes of tms_rp (console scripts): ``tracked_localization``, ``tracked_navigator`` (any tracked
machine) and their former names ``ic120_localization``, ``ic120_navigator`` (the paper launch's)."""
