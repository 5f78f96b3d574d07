"""ZX200 arm planning: pinocchio kinematics, analytic IK, goal validation and motion segments.

* :mod:`tms_rp.zx200.kinematics` builds the arm model from ``config/machines/zx200.yaml`` (FK,
  bucket-tip Jacobians, theta_w) and solves position + theta_w IK in closed form.
* :mod:`tms_rp.zx200.planner` turns change_pose / excavate_simple / release_simple goals into
  validated motion segments for the arm controller (``tms_rc.zx200``), rejecting bad goals first.

Pure Python (no rclpy); the action servers live in :mod:`tms_if_opera.nodes.zx200_planner`.
"""
