"""ROS 2 nodes of tms_rc (console scripts): ``zx200_arm_controller``, ``vessel_controller`` (any crawler
carrier) and its former name ``ic120_vessel`` (default machine ``ic120``)."""
