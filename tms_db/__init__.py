"""tms_db: the document store at the centre of the platform.

Holds task data (one behavior tree per ``task_id``), parameter data (static records set before a run
and dynamic records updated live by sensing) and the global blackboard, in the original ROS2-TMS
schema (database ``rostmsdb``, collections ``task`` and ``parameter``). The backend is chosen by URI:
``mongodb://...`` goes through pymongo to a real MongoDB; the default is an embedded on-disk store
with the same API. The reader/writer nodes expose it to other processes over ROS 2 services/topics.

The public API, the one thing other packages import of tms_db: :func:`open_store`, :func:`declare_and_open` (a
node's ``db_uri`` / ``db_path`` parameters and the store they name) with :class:`StoreOwner` (closes it with the
node), :class:`Store`, the errors, and
:func:`normalise_task_xml` (the one-line form a task's tree is stored in), :func:`find_heightmap` (the newest stored
terrain heightmap of a type, as the original's heightmap reader picks it), :func:`put_design` / :func:`get_design` /
:func:`list_designs` (design surfaces in the collection ``design`` of ours, :mod:`tms_db.design`).
"""

from tms_db.backend import open_store
from tms_db.design import DESIGN_COLLECTION, get_design, list_designs, put_design
from tms_db.errors import BlobTooLarge, RecordNotFound, StoreError, ValidationError
from tms_db.heightmap import find_heightmap, find_heightmap_doc
from tms_db.nodes.common import StoreOwner, declare_and_open
from tms_db.schema import normalise_task_xml
from tms_db.store import DATABASE, Store, default_path

__all__ = ["open_store", "declare_and_open", "StoreOwner", "Store", "StoreError", "RecordNotFound", "ValidationError",
           "BlobTooLarge", "normalise_task_xml", "DATABASE", "default_path", "find_heightmap", "find_heightmap_doc",
           "put_design", "get_design", "list_designs", "DESIGN_COLLECTION"]
