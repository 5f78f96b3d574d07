"""ZX200 arm control: the HEAP-style hierarchical QP controller and its node.

* :mod:`tms_rc.zx200.hqp`: strict-priority hierarchical QP over joint velocities (OSQP per level).
* :mod:`tms_rc.zx200.controller`: the 100 Hz arm controller (pump flow, joint velocity, position
  limits, ground/self collision, theta_w, tip position, least motion), trapezoidal-profile references
  with PID feedback and dead-time compensation.
* :mod:`tms_rc.zx200.segments`: an ``arm_controller/move`` goal's segments -> controller targets, validated.
* :mod:`tms_rc.zx200.plant`: a first-order-lag + dead-time joint model for tests and benchmarks.
* :mod:`tms_rc.nodes.zx200_arm_controller`: ``zx200_arm_controller`` (joint_states -> front_cmd, action ``arm_controller/move``).
"""
