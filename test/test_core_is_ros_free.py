"""The core imports with rclpy (and mujoco) made unimportable."""

from __future__ import annotations

import subprocess
import sys

CODE = """
import sys
for name in ("rclpy", "mujoco", "yaml", "matplotlib"):
    sys.modules[name] = None  # any import of these now raises ImportError
import grasp_safety_ros.core as core
import grasp_safety_ros.core.method.effective_mass, grasp_safety_ros.core.method.ik
loaded = [m for m, v in sys.modules.items() if v is not None]
print(sorted(m for m in loaded if m.split(".")[0] in ("rclpy", "mujoco")))
"""


def test_core_imports_without_ros_or_mujoco() -> None:
    completed = subprocess.run(
        [sys.executable, "-c", CODE], capture_output=True, text=True, check=False
    )
    assert completed.returncode == 0, completed.stderr
    assert completed.stdout.strip() == "[]"
