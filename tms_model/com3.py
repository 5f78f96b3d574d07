"""What every COM3 machine's commands share, below the converter and the controllers that speak to it.

``com3_msgs/JointCmd`` (OPERA com3_ros) carries ``control_type`` as a bare ``uint8`` without named
constants; its values are fixed by com3_ros: 0 position, 1 velocity, 2 effort. They are named once here so
the converter (which reads them) and the controllers (which write them) agree.
"""

from __future__ import annotations

__all__ = ["POSITION", "VELOCITY", "EFFORT", "CONTROL_NAMES", "CARRIER_DUMP_JOINT", "CARRIER_ROTATE_JOINT"]

POSITION, VELOCITY, EFFORT = 0, 1, 2
CONTROL_NAMES = {POSITION: "POSITION", VELOCITY: "VELOCITY", EFFORT: "EFFORT"}

# A crawler carrier's ``rot_dump_cmd`` (com3_msgs/JointCmd) names its vessel ``dump_joint`` and its rotating
# body, where it has one, ``rotate_joint`` (com3_ros's crawler-carrier names).
CARRIER_DUMP_JOINT = "dump_joint"
CARRIER_ROTATE_JOINT = "rotate_joint"
