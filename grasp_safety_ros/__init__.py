"""grasp_safety_ros: minimum impact-force grasp selection (Mavrakis et al., IROS 2017)."""

__version__ = "0.1.0"
