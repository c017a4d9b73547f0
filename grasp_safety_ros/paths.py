"""Where the package's bundled files (config/) are, in a checkout, a venv or a ROS install."""

from __future__ import annotations

import sys
from pathlib import Path

from .core.exceptions import GraspSafetyError

PACKAGE = "grasp_safety_ros"


def config_dirs() -> list[Path]:
    """Candidate config folders: the source tree, the venv's share/, the ament index."""
    dirs = [
        Path(__file__).resolve().parents[1] / "config",
        Path(sys.prefix) / "share" / PACKAGE / "config",
    ]
    try:
        from ament_index_python.packages import get_package_share_directory

        dirs.append(Path(get_package_share_directory(PACKAGE)) / "config")
    except (ImportError, LookupError, OSError, ValueError):
        pass  # no ROS environment: the first two places are all there is
    return dirs


def config_file(name: str) -> Path:
    """Path of a bundled config file."""
    dirs = config_dirs()
    for folder in dirs:
        if (folder / name).is_file():
            return folder / name
    raise GraspSafetyError(f"bundled config file '{name}' not found in {[str(d) for d in dirs]}")
