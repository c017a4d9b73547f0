"""The middleware settings of the node's process, made before rclpy starts: Fast DDS's
shared-memory segment sized for large responses (``data/fastdds_large_responses.xml``).

Fast DDS's default segment (512 KiB) is smaller than a large response (1.4 MB at 100 grasps x
201 samples): the response then reached the client 10-20 ms after the node sent it beyond its
deserialisation, against none with a segment that holds it (docs/performance_pipeline.md,
"Service"). Only the writer's segment counts, so the node's process alone needs it; Fast DDS
reserves all of it in /dev/shm at start-up (4.4 MB). A process that configures Fast DDS itself
(a profile file, its built-in transports, another middleware) keeps its own settings.
"""

from __future__ import annotations

import os
from collections.abc import MutableMapping
from importlib import resources
from pathlib import Path

PROFILE_FILE = "fastdds_large_responses.xml"
"""The profile, in the package's ``data`` folder."""
PROFILE_VARIABLE = "FASTRTPS_DEFAULT_PROFILES_FILE"
"""Where Fast DDS 2 reads its profile file's path (Jazzy's rmw_fastrtps_cpp)."""
OWN_SETTINGS = (PROFILE_VARIABLE, "FASTDDS_DEFAULT_PROFILES_FILE", "FASTDDS_BUILTIN_TRANSPORTS")
"""Variables by which a process configures Fast DDS itself."""
FAST_DDS = ("", "rmw_fastrtps_cpp", "rmw_fastrtps_dynamic_cpp")
"""RMW_IMPLEMENTATION values that mean Fast DDS (empty: the default, in Jazzy)."""
DEFAULT_PROFILE_FILE = "DEFAULT_FASTRTPS_PROFILES.xml"
"""The profile Fast DDS reads from the working directory (unless SKIP_DEFAULT_FILE is set)."""
SKIP_DEFAULT_FILE = "SKIP_DEFAULT_XML_FILE"
"""Fast DDS 2's variable that makes it ignore DEFAULT_PROFILE_FILE."""


def size_shared_memory_for_large_responses(
    environ: MutableMapping[str, str] = os.environ, working_directory: Path | None = None
) -> str | None:
    """Point Fast DDS at the profile with the large shared-memory segment, when this process
    uses Fast DDS and configures it in no other way (OWN_SETTINGS, a DEFAULT_PROFILE_FILE in
    the working directory that SKIP_DEFAULT_FILE does not skip). Call before rclpy.init.
    Returns the profile's path, or None when left alone."""
    if environ.get("RMW_IMPLEMENTATION", "") not in FAST_DDS:
        return None
    if any(environ.get(name) for name in OWN_SETTINGS):
        return None
    in_directory = (working_directory or Path.cwd()) / DEFAULT_PROFILE_FILE
    if not environ.get(SKIP_DEFAULT_FILE) and in_directory.exists():
        return None
    path = Path(str(resources.files("grasp_safety_ros").joinpath("data", PROFILE_FILE)))
    if not path.is_file():  # not installed with the package: Fast DDS's defaults
        return None
    environ[PROFILE_VARIABLE] = str(path)
    return str(path)
