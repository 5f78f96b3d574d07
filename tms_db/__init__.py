"""tms_db: the document store at the centre of the platform.

Holds task data (one behavior tree per ``task_id``), parameter data (static records set before a run
and dynamic records updated live by sensing) and the global blackboard, in the original ROS2-TMS
schema (database ``rostmsdb``, collections ``task`` and ``parameter``). The backend is chosen by URI:
``mongodb://...`` goes through pymongo to a real MongoDB; the default is an embedded on-disk store
with the same API. The reader/writer nodes expose it to other processes over ROS 2 services/topics.
"""

from tms_db.errors import RecordNotFound, StoreError, ValidationError
from tms_db.store import DATABASE, Store, default_path, open_store

__all__ = ["open_store", "Store", "StoreError", "RecordNotFound", "ValidationError", "DATABASE", "default_path"]
