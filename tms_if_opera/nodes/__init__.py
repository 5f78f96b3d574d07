"""rclpy nodes of tms_if_opera: the ZX200 planning action servers (``zx200_planner``)."""
