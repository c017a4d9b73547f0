"""Validation of the effective mass with the MuJoCo physics engine (issue #4).

``reproduce(out_dir, quick)`` runs the paper's simulated experiments (tensor object, book)
with impacts into a force sensor, plus free impacts that check the effective mass itself, and
writes results.json, results.md and PNG figures. Only this subpackage imports mujoco.
"""

from .experiments import FULL, QUICK
from .records import RunConfig
from .reproduce import format_summary, reproduce

__all__ = ["FULL", "QUICK", "RunConfig", "format_summary", "reproduce"]
