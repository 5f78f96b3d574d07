"""Excavator arm control (every excavator kind): the HEAP-style hierarchical QP controller and its node.

* :mod:`tms_rc.excavator.hqp`: strict-priority hierarchical QP over joint velocities (OSQP per level).
* :mod:`tms_rc.excavator.controller`: the 100 Hz arm controller (pump flow, joint velocity, position
  limits, ground/self collision, theta_w, tip position, least motion), trapezoidal-profile references
  with PID feedback and dead-time compensation.
* :mod:`tms_rc.excavator.segments`: an ``arm_controller/move`` goal's segments -> controller targets, validated.
* :mod:`tms_rc.excavator.plant`: a first-order-lag + dead-time joint model for tests and benchmarks.
* :mod:`tms_rc.nodes.excavator_arm_controller`: ``excavator_arm_controller`` (joint_states -> front_cmd, action
  ``arm_controller/move``).
"""
