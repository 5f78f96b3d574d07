"""rclpy nodes of tms_sp (thin wrappers around :mod:`tms_sp.processor`)."""
