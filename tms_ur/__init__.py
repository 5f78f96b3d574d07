"""tms_ur: user requests.

Start and stop from a GUI: the ``/tms_ts/start``, ``/tms_ts/cancel`` and ``/emergency_signal`` topics,
and a web control panel with a live view of the site.
"""
