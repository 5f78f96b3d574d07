"""tms_launch: the launcher and the node-registration conventions.

``tms-launch <file.yaml>`` starts the nodes of a launch file, the nodes of one ``container`` in one process
(``tms_launch.container``) or each in its own (``--layout per-node``), with their parameters and namespaces,
prefixes their output, waits until each node is visible on the ROS graph,
and stops them all cleanly. ``register_ament`` makes every console-script node findable by
``ros2 run <package> <executable>``. ``tms_launch.nodes`` holds small demonstration nodes used by the foundation tests.
"""
