"""tms_if_opera: the interface between subtasks and planning.

Turns subtask targets (ZX200 pose / excavate / release, IC120 navigation and dumping) into planning
goals for tms_rp, as the original tms_if_for_opera bridged ROS2-TMS to PWRI's OPERA stack.
"""
