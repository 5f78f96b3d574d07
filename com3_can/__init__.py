"""com3_can: the COM3 CAN layer.

DBC-driven codecs (cantools) for the published COM3 excavator frames and our crawler-carrier
extension, CAN bus construction by configuration (socketcan, udp_multicast, virtual), and the
per-machine ROS 2 <-> CAN converter node with its emergency-stop latch and command watchdog.
"""
