"""tms_sp: sensing processors.

Turn simulated sensor data (height samples of the mound and the vessel, machine states) into dynamic
DB parameters and global-blackboard flags: the excavation target, the release target, and the
SENSING_* flags that synchronise the tasks.
"""
