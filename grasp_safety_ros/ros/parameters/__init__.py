"""The node's parameters: the table (table.py), the checks of each on its own (checks.py), the
settings a full set gives (settings.py), the whole arm's points (arm_points.py) and their ROS
declaration (declaration.py). The names below are what the node, tests and tools import."""

from .checks import ParameterConstraints, check_parameter, parameter_constraints
from .settings import (
    NodeSettings,
    analysis_from_parameters,
    points_from_parameters,
    settings_from_parameters,
)
from .table import (
    INFEASIBLE_CHOICES,
    PARAMETERS,
    PUBLISHED_PARAMETER,
    ROBOT_PARAMETERS,
    ParameterSpec,
)

__all__ = [
    "INFEASIBLE_CHOICES",
    "PARAMETERS",
    "PUBLISHED_PARAMETER",
    "ROBOT_PARAMETERS",
    "NodeSettings",
    "ParameterConstraints",
    "ParameterSpec",
    "analysis_from_parameters",
    "check_parameter",
    "parameter_constraints",
    "points_from_parameters",
    "settings_from_parameters",
]
