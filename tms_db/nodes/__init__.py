"""ROS 2 nodes of the document store, thin wrappers over :mod:`tms_db`: ``tms_db_reader`` and ``tms_db_writer``, and the
rest of the original's DB boundary (``tms_db_writer_param``, ``tms_db_reader_param``, ``tms_db_writer_gridfs``,
``tms_db_reader_gridfs``, ``tms_db_writer_collision``: :mod:`tms_db.boundary`; ``tms_db_reader_heightmap``:
:mod:`tms_db.heightmap`)."""
