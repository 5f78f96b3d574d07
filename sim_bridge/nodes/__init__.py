"""rclpy node wrappers of sim_bridge (thin: the physics and CAN I/O live in the pure core)."""
