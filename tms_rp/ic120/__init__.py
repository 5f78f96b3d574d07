"""IC120 crawler dump planning: localisation, costmap, global planner, local controller, goal checking.

Pure-Python cores (no rclpy import; GNSS -> map is :mod:`tms_model.site`): :mod:`ekf` (filterpy EKF
fusing track odometry, GNSS and azimuth with Mahalanobis gating), :mod:`costmap` (Nav2 map_server PGM+YAML,
inflation with the IC120 footprint), :mod:`planner` (coarse-to-fine Dijkstra on scipy.sparse graphs),
:mod:`controller` (regulated pure pursuit for a tracked vehicle, forward and reverse), :mod:`goal_checker`
and :mod:`navigator` (the Nav2 navigate_* semantics as a step function). Nodes live in :mod:`tms_rp.nodes`.
"""
