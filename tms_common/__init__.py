"""tms_common: what every package shares, and nothing more.

The exception base (:class:`TmsError`), YAML configuration loading with file-and-line errors, and the
node runner that every console-script node uses (rclpy init, executor choice, clean shutdown). No
module here imports another tms package.
"""
