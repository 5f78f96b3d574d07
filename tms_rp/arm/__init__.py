"""Excavator arm planning: goal validation and motion segments (the kinematics is :mod:`tms_model.excavator`).

* :mod:`tms_rp.arm.planner` turns change_pose / excavate_simple / release_simple goals into
  validated motion targets (:mod:`tms_model.excavator.targets`) for the arm controller, rejecting bad goals first.
* :mod:`tms_rp.arm.collision` (collision objects from the DB records, the padded arm) and
  :mod:`tms_rp.arm.collision_planner` (the ``_plan`` variants: dense path checks, detours over objects).

Pure Python (no rclpy); the action servers live in :mod:`tms_if_opera.nodes.zx200_planner`.
"""
