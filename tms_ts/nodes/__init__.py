"""rclpy nodes of tms_ts: the task scheduler manager (``tms_ts_manager``) and the subtask action servers
(``tms_ts_subtasks``), one module per executable."""
