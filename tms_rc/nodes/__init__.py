"""ROS 2 nodes of tms_rc (console scripts): ``excavator_arm_controller``, ``vessel_controller`` (any crawler
carrier) and its former name ``ic120_vessel`` (the paper launch's)."""
