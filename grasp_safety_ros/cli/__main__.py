"""``python -m grasp_safety_ros.cli``: the ``grasp-safety`` command."""

from .main import run

run()
