"""The platform's DDS middleware profile (``config/dds/fastdds_profiles.xml``).

:func:`use_platform_profiles` points Fast DDS at that file through ``FASTRTPS_DEFAULT_PROFILES_FILE``
before rclpy initialises; child processes inherit it. A value you set yourself is kept (then give your
file the ``service`` publisher profile too, or service replies may be dropped at start-up: see the XML).
"""

from __future__ import annotations

import os

from tms_common.config import config_path

__all__ = ["PROFILES_ENV", "use_platform_profiles"]

#: the variable Fast DDS 2.x (ROS 2 Jazzy) reads its XML profiles from
PROFILES_ENV = "FASTRTPS_DEFAULT_PROFILES_FILE"


def use_platform_profiles() -> str:
    """Set ``FASTRTPS_DEFAULT_PROFILES_FILE`` to the platform's profiles unless already set; return the file used."""
    path = config_path("dds", "fastdds_profiles.xml")
    if not path.is_file():
        raise FileNotFoundError(f"DDS profiles {path} are missing from the checkout")
    return os.environ.setdefault(PROFILES_ENV, str(path))
