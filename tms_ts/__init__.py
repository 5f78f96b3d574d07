"""tms_ts: the task scheduler.

Loads a task's behavior tree (BehaviorTree.CPP / Groot XML) from tms_db, builds it with py_trees and
ticks it. Leaf nodes are asynchronous action clients of subtask servers (``/<model_name>/<subtask>``);
subtask servers read their DB record when a goal arrives and hand it to planning. One task drives one
machine; tasks synchronise through global-blackboard flags in the DB; cancel and the emergency signal
halt trees root to leaf and wait until every subtask confirms its machine is at rest.
"""
