"""rclpy node wrappers of com3_can (console scripts)."""
