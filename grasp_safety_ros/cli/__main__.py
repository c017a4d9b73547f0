"""``python -m grasp_safety_ros.cli``: the ``grasp-safety`` command."""

import sys

from .main import main

sys.exit(main())
