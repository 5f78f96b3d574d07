"""ROS 2 nodes of the document store: ``tms_db_reader`` and ``tms_db_writer`` (thin wrappers over :mod:`tms_db`)."""
